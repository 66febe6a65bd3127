//! The per-pixel working memory of a frame, owned by the caller.
//!
//! Per pixel of a strip (the rows processed at once, margins included):
//!
//! | buffer | type | bytes/px | holds |
//! |---|---|---|---|
//! | `counts` | `u64` | 1 | the current window count c_n, bit-sliced (`crate::slices`: eight planes per 64 px) |
//! | `c_t` | `u8` | 1 | the count at the window where the pixel was decided (a region pixel: its count over n*) |
//! | `class` | `u8` | 1 | class (active, particle, background) and level index |
//! | `labels` | `u16` | 2 | region label (0: none) |
//! | `masks` | `u64` | 3/8 | region-membership bit planes (any region, one region, its ring) |
//!
//! That is 5.375 bytes per pixel (plus row padding of counts and masks to 64 px),
//! within the 8 bytes per pixel the design allows besides the spike history.
//! Fixed overhead: the tile medians (one byte per 16×16 tile), the
//! union-find table (2 bytes per provisional label) and the region table
//! ([`Region`], 28 bytes each).

use crate::error::Error;
use crate::plane::words_per_row;
use crate::region::Region;
use crate::window::check_len;

/// The per-pixel state, in thousandths of a byte per pixel: 5.375 bytes
/// (`counts` 1, `c_t` 1, `class` 1, `labels` 2, three mask bits 0.375),
/// for widths that are a multiple of 64.
pub const STATE_MILLIBYTES_PER_PIXEL: usize = 5375;

/// Most pixels a strip of a frame holds at once on the shipped paths
/// ([`strip_rows`]): the labeller's 32,766 provisional labels fill at about
/// one per 50 pixels on compensated frames of the paper's scenes (a
/// 6400×250 compensated frame in one strip lost 20,815 particle pixels to
/// the full table; 3200×250 used 18,066), so 2^19 pixels leave room twice
/// over.
pub const MAX_STRIP_PIXELS: usize = 1 << 19;

/// Rows of a strip for a `width × height` frame: the whole band when it
/// holds at most [`MAX_STRIP_PIXELS`], else as many rows as fit (at least
/// two `margin`s and 16 inner rows), so that no wide frame loses particles
/// to a full label table.
pub const fn strip_rows(width: u16, height: u16, margin: u16) -> u16 {
    let w = if width == 0 { 1 } else { width as usize };
    if w * height as usize <= MAX_STRIP_PIXELS {
        return height;
    }
    let fit = MAX_STRIP_PIXELS / w;
    let least = 2 * margin as usize + 16;
    let rows = if fit < least { least } else { fit };
    if rows > height as usize {
        height
    } else {
        rows as u16
    }
}

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
    pub const fn for_strip(width: u16, rows: u16) -> Self {
        const fn clamp(v: usize, lo: usize, hi: usize) -> usize {
            if v < lo {
                lo
            } else if v > hi {
                hi
            } else {
                v
            }
        }
        let px = width as usize * rows as usize;
        WorkspaceSizes {
            width,
            rows,
            max_regions: clamp(px / 64, 16, 65535) as u16,
            max_provisional: clamp(px / 8, 64, 32766) as u16,
        }
    }

    /// Sizes for a motion-compensated strip (`crate::reconstruct_compensated`):
    /// compensated counts make every moving particle detectable, so a frame
    /// holds several times the regions of a plain one — one region per 16
    /// px (the plain default is one per 64, sized for an MCU) and the
    /// largest union-find table.
    pub const fn for_motion(width: u16, rows: u16) -> Self {
        let plain = Self::for_strip(width, rows);
        let per16 = plain.pixels() / 16;
        WorkspaceSizes {
            max_regions: if per16 < 16 {
                16
            } else if per16 > 65535 {
                65535
            } else {
                per16 as u16
            },
            max_provisional: 32766,
            ..plain
        }
    }

    /// Pixels of the strip.
    pub const fn pixels(&self) -> usize {
        self.width as usize * self.rows as usize
    }
    /// Words of the three mask planes.
    pub const fn mask_words(&self) -> usize {
        3 * words_per_row(self.width) * self.rows as usize
    }
    /// Words of the bit-sliced counts (eight per 64 px of a row).
    pub const fn count_words(&self) -> usize {
        8 * words_per_row(self.width) * self.rows as usize
    }
    /// Bytes of the tile-median table.
    pub const fn tiles(&self) -> usize {
        (self.width as usize).div_ceil(16) * ((self.rows as usize).div_ceil(16) + 1)
    }
    /// Entries of the union-find table.
    pub const fn parents(&self) -> usize {
        self.max_provisional as usize + 1
    }
    /// Regions of the region table.
    pub const fn regions(&self) -> usize {
        self.max_regions as usize
    }
    /// Bytes of the per-pixel buffers (`counts`, `c_t`, `class`, `labels`,
    /// `masks`): [`STATE_MILLIBYTES_PER_PIXEL`] / 1000 per pixel when the
    /// width is a multiple of 64, more with the row padding of counts and masks.
    pub const fn per_pixel_bytes(&self) -> usize {
        self.pixels() * 4 + (self.count_words() + self.mask_words()) * 8
    }
    /// Total bytes of all buffers.
    pub const fn total_bytes(&self) -> usize {
        self.per_pixel_bytes()
            + self.tiles()
            + self.parents() * 2
            + self.max_regions as usize * core::mem::size_of::<Region>()
    }
}

/// Caller-owned buffers for one strip. Build it once, reuse it for every frame.
#[derive(Debug)]
pub struct Workspace<'a> {
    pub(crate) sizes: WorkspaceSizes,
    pub(crate) counts: &'a mut [u64],
    pub(crate) c_t: &'a mut [u8],
    pub(crate) class: &'a mut [u8],
    pub(crate) labels: &'a mut [u16],
    pub(crate) masks: &'a mut [u64],
    pub(crate) tiles: &'a mut [u8],
    pub(crate) parents: &'a mut [u16],
    pub(crate) regions: &'a mut [Region],
    /// Motion-compensated counts (one byte per pixel; empty unless
    /// [`Workspace::with_motion_counts`] gave them).
    pub(crate) mc: &'a mut [u8],
}

/// The buffers of a [`Workspace`], each at least as long as [`WorkspaceSizes`] says.
#[derive(Debug)]
pub struct Buffers<'a> {
    /// `count_words()` words.
    pub counts: &'a mut [u64],
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
        check_len(b.counts.len(), sizes.count_words())?;
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
            mc: &mut [],
        })
    }

    /// Adds the one extra byte per pixel that motion-compensated frames
    /// need (`crate::frame::reconstruct_compensated`): their particle test
    /// runs on compensated counts while saturation keeps the plain ones.
    pub fn with_motion_counts(mut self, mc: &'a mut [u8]) -> Result<Self, Error> {
        check_len(mc.len(), self.sizes.pixels())?;
        self.mc = mc;
        Ok(self)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The documented 5.375 bytes per pixel is what the buffers take.
    #[test]
    fn per_pixel_bytes_match_the_documented_figure() {
        for (w, h) in [(64u16, 1u16), (128, 32), (448, 250), (1024, 1000)] {
            let s = WorkspaceSizes::for_strip(w, h);
            assert_eq!(
                s.per_pixel_bytes() * 1000,
                STATE_MILLIBYTES_PER_PIXEL * s.pixels(),
                "{w}x{h}"
            );
        }
        // Row padding of counts and masks only adds.
        let s = WorkspaceSizes::for_strip(400, 250);
        assert!(s.per_pixel_bytes() * 1000 >= STATE_MILLIBYTES_PER_PIXEL * s.pixels());
        const SIZES: WorkspaceSizes = WorkspaceSizes::for_strip(128, 32);
        assert_eq!(SIZES.regions(), 64);
    }
}
