//! One particle region of a strip: its size, bounding box, ring and
//! adaptive window. Made by [`crate::label`], stored in the caller-owned
//! region table of [`crate::state`], filled in by [`crate::integrate`].

/// One particle region of a strip and its adaptive window.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Region {
    /// Pixels in the region.
    pub pixels: u32,
    /// Pixels of its 2-px ring (not in any region).
    pub ring_pixels: u32,
    /// Spikes of the ring over the region's window n*.
    pub ring_sum: u32,
    /// Bounding box, strip rows `row0..row1`.
    pub row0: u16,
    /// One past the last row.
    pub row1: u16,
    /// Bounding box, columns `col0..col1`.
    pub col0: u16,
    /// One past the last column.
    pub col1: u16,
    /// Optimal integration window n*, ticks (0 until computed).
    pub n_star: u16,
    /// Ticks of the window n* actually held.
    pub win_len: u16,
    /// Largest count of a region pixel over n*.
    pub max_count: u8,
    /// The union-find root it came from (labelling's bookkeeping).
    pub root: u16,
}
