//! The output pixel type of frames, tiles and the wire: 8- or 16-bit gray
//! levels (`u8`, `u16`), with the largest level each holds. A leaf: the
//! algorithm and the link both use it, neither through the other.

/// An output pixel type: 8- or 16-bit gray.
pub trait Gray: Copy + Default {
    /// Largest level.
    const MAX: u16;
    /// From a level already clamped to `[0, MAX]`.
    fn from_level(v: u16) -> Self;
    /// The level.
    fn level(self) -> u16;
}

impl Gray for u8 {
    const MAX: u16 = 255;
    #[inline]
    fn from_level(v: u16) -> Self {
        v.min(255) as u8
    }
    #[inline]
    fn level(self) -> u16 {
        u16::from(self)
    }
}

impl Gray for u16 {
    const MAX: u16 = u16::MAX;
    #[inline]
    fn from_level(v: u16) -> Self {
        v
    }
    #[inline]
    fn level(self) -> u16 {
        self
    }
}
