//! The per-pixel working memory of a frame, owned by the caller.
//!
//! Per pixel of a strip (the rows processed at once, margins included):
//!
//! | buffer | type | bytes/px | holds |
//! |---|---|---|---|
//! | `counts` | `u8` | 1 | the current window count c_n |
//! | `c_t` | `u8` | 1 | the count at the window where the pixel was decided |
//! | `class` | `u8` | 1 | class (active, particle, background) and level index |
//! | `labels` | `u16` | 2 | region label (0: none) |
//! | `masks` | `u64` | 3/8 | region-membership bit planes (any region, one region, its ring) |
//!
//! That is 5.375 bytes per pixel (plus row padding of the masks to 64 px),
//! within the 8 bytes per pixel the design allows besides the spike history.
//! Fixed overhead: the tile medians (one byte per 16×16 tile), the
//! union-find table (2 bytes per provisional label) and the region table
//! ([`Region`], 28 bytes each).

use crate::error::Error;
use crate::label::Region;
use crate::plane::words_per_row;
use crate::window::check_len;

/// Sizes of the buffers a [`Workspace`] needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WorkspaceSizes {
    /// Camera width, pixels.
    pub width: u16,
    /// Rows processed at once (a strip plus its two margins, or the whole band).
    pub rows: u16,
    /// Regions the table holds; more are left as background and counted.
    pub max_regions: u16,
    /// Provisional labels of the labelling pass (union-find entries), at most 32766.
    pub max_provisional: u16,
}

impl WorkspaceSizes {
    /// A workspace for `rows × width` pixels with room for one region per
    /// 64 pixels and one provisional label per 8 pixels (capped at 32766,
    /// the labeller's limit).
    pub fn for_strip(width: u16, rows: u16) -> Self {
        let px = usize::from(width) * usize::from(rows);
        WorkspaceSizes {
            width,
            rows,
            max_regions: (px / 64).clamp(16, 65535) as u16,
            max_provisional: (px / 8).clamp(64, 32766) as u16,
        }
    }
    /// Pixels of the strip.
    pub fn pixels(&self) -> usize {
        usize::from(self.width) * usize::from(self.rows)
    }
    /// Words of the three mask planes.
    pub fn mask_words(&self) -> usize {
        3 * words_per_row(self.width) * usize::from(self.rows)
    }
    /// Bytes of the tile-median table.
    pub fn tiles(&self) -> usize {
        usize::from(self.width).div_ceil(16) * (usize::from(self.rows).div_ceil(16) + 1)
    }
    /// Entries of the union-find table.
    pub fn parents(&self) -> usize {
        usize::from(self.max_provisional) + 1
    }
    /// Total bytes of all buffers.
    pub fn total_bytes(&self) -> usize {
        self.pixels() * 5
            + self.mask_words() * 8
            + self.tiles()
            + self.parents() * 2
            + usize::from(self.max_regions) * core::mem::size_of::<Region>()
    }
}

/// Caller-owned buffers for one strip. Build it once, reuse it for every frame.
#[derive(Debug)]
pub struct Workspace<'a> {
    pub(crate) sizes: WorkspaceSizes,
    pub(crate) counts: &'a mut [u8],
    pub(crate) c_t: &'a mut [u8],
    pub(crate) class: &'a mut [u8],
    pub(crate) labels: &'a mut [u16],
    pub(crate) masks: &'a mut [u64],
    pub(crate) tiles: &'a mut [u8],
    pub(crate) parents: &'a mut [u16],
    pub(crate) regions: &'a mut [Region],
}

/// The buffers of a [`Workspace`], each at least as long as [`WorkspaceSizes`] says.
#[derive(Debug)]
pub struct Buffers<'a> {
    /// `pixels()` bytes.
    pub counts: &'a mut [u8],
    /// `pixels()` bytes.
    pub c_t: &'a mut [u8],
    /// `pixels()` bytes.
    pub class: &'a mut [u8],
    /// `pixels()` entries.
    pub labels: &'a mut [u16],
    /// `mask_words()` words.
    pub masks: &'a mut [u64],
    /// `tiles()` bytes.
    pub tiles: &'a mut [u8],
    /// `parents()` entries.
    pub parents: &'a mut [u16],
    /// `max_regions` entries.
    pub regions: &'a mut [Region],
}

impl<'a> Workspace<'a> {
    /// Checks every buffer against `sizes`.
    pub fn new(sizes: WorkspaceSizes, b: Buffers<'a>) -> Result<Self, Error> {
        if sizes.width == 0 || sizes.rows == 0 {
            return Err(Error::BadDimensions);
        }
        let px = sizes.pixels();
        check_len(b.counts.len(), px)?;
        check_len(b.c_t.len(), px)?;
        check_len(b.class.len(), px)?;
        check_len(b.labels.len(), px)?;
        check_len(b.masks.len(), sizes.mask_words())?;
        check_len(b.tiles.len(), sizes.tiles())?;
        check_len(b.parents.len(), sizes.parents())?;
        check_len(b.regions.len(), usize::from(sizes.max_regions))?;
        Ok(Workspace {
            sizes,
            counts: b.counts,
            c_t: b.c_t,
            class: b.class,
            labels: b.labels,
            masks: b.masks,
            tiles: b.tiles,
            parents: b.parents,
            regions: b.regions,
        })
    }

    /// The sizes it was built for.
    pub fn sizes(&self) -> WorkspaceSizes {
        self.sizes
    }

    /// Class byte of strip pixel `i` (see [`crate::segment::Class`]); for
    /// tests and the firmware's checksums.
    pub fn class(&self) -> &[u8] {
        self.class
    }

    /// Region label per strip pixel (0: none).
    pub fn labels(&self) -> &[u16] {
        self.labels
    }

    /// The regions of the last strip processed.
    pub fn regions(&self, n: usize) -> &[Region] {
        self.regions.get(..n).unwrap_or(self.regions)
    }
}
