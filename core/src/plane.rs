//! Zero-copy view of one bit-packed spike plane in the Vidar layout
//! (docs/formats.md): `width*height/8` bytes, pixel `p = row*width + col` over the
//! **stored** rows, least significant bit first. Stored rows are the image
//! upside down; this view never flips (file readers do).

use crate::error::Error;

/// One spike plane (one tick), borrowed. Memory: none beyond the borrow.
#[derive(Debug, Clone, Copy)]
pub struct PlaneView<'a> {
    bytes: &'a [u8],
    width: u16,
    height: u16,
}

/// Bytes of one plane, or `None` when `width*height` is zero or not a
/// multiple of 8.
pub fn plane_bytes(width: u16, height: u16) -> Option<usize> {
    let px = usize::from(width) * usize::from(height);
    (px != 0 && px % 8 == 0).then_some(px / 8)
}

/// Words of 64 pixels that hold one row of `width` pixels.
#[inline]
pub const fn words_per_row(width: u16) -> usize {
    (width as usize).div_ceil(64)
}

/// The little-endian words of `bytes` into `out` (as many as it holds),
/// the last from the bytes left over, zero above them: a byte-aligned
/// row's words ([`PlaneView::row_words`], and `History::push` in its own
/// loop over a band's rows, where a call per row and a `memcpy` of the
/// tail had cost most of the ingest).
#[inline]
pub(crate) fn le_words(bytes: &[u8], out: &mut [u64]) {
    let mut chunks = bytes.chunks_exact(8);
    let mut dst = out.iter_mut();
    // Chunks first: `zip` must not take an output word it cannot fill.
    for (c, w) in (&mut chunks).zip(&mut dst) {
        *w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
    }
    let rest = chunks.remainder();
    if let Some(w) = dst.next().filter(|_| !rest.is_empty()) {
        *w = rest.iter().rev().fold(0, |a, &b| a << 8 | u64::from(b));
    }
}

impl<'a> PlaneView<'a> {
    /// Views `bytes` as one plane of `width × height` pixels.
    ///
    /// ```
    /// use spiv_core::plane::PlaneView;
    /// // 16 × 1 pixels, bit `c % 8` of byte `c / 8`: columns 0 and 9 fire.
    /// # fn main() -> Result<(), spiv_core::Error> {
    /// let p = PlaneView::new(&[0b0000_0001, 0b0000_0010], 16, 1)?;
    /// assert!(p.get(0, 0) && p.get(0, 9) && !p.get(0, 1));
    /// assert!(PlaneView::new(&[0], 16, 1).is_err());
    /// # Ok(())
    /// # }
    /// ```
    pub fn new(bytes: &'a [u8], width: u16, height: u16) -> Result<Self, Error> {
        let expected = plane_bytes(width, height).ok_or(Error::BadDimensions)?;
        if bytes.len() != expected {
            return Err(Error::PlaneSize {
                expected,
                got: bytes.len(),
            });
        }
        Ok(PlaneView {
            bytes,
            width,
            height,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> u16 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u16 {
        self.height
    }

    /// The packed bytes.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Spike of stored row `row`, column `col`; `false` outside the plane.
    pub fn get(&self, row: u16, col: u16) -> bool {
        if row >= self.height || col >= self.width {
            return false;
        }
        let p = usize::from(row) * usize::from(self.width) + usize::from(col);
        self.bytes
            .get(p / 8)
            .is_some_and(|b| (b >> (p % 8)) & 1 == 1)
    }

    /// Spikes in the whole plane.
    pub fn count_ones(&self) -> u32 {
        self.bytes.iter().map(|b| b.count_ones()).sum()
    }

    /// Unpacks stored row `row` into `out` as words of 64 pixels (bit `i` of
    /// word `j` is column `64*j + i`); bits past the width are zero. Returns
    /// `false` (and writes nothing) if `row` is outside the plane or `out`
    /// is shorter than [`words_per_row`].
    pub fn row_words(&self, row: u16, out: &mut [u64]) -> bool {
        let wpr = words_per_row(self.width);
        if row >= self.height || out.len() < wpr {
            return false;
        }
        let width = usize::from(self.width);
        let bit0 = usize::from(row) * width;
        let byte0 = bit0 / 8;
        let shift = bit0 % 8;
        let row_bytes = (shift + width).div_ceil(8);
        let src = self.bytes.get(byte0..byte0 + row_bytes).unwrap_or(&[]);
        if shift == 0 {
            // Byte-aligned rows (any width that is a multiple of 8): whole
            // words straight from the bytes, the tail word padded with zeros.
            le_words(src, out);
            if width % 64 != 0 {
                if let Some(w) = out.get_mut(wpr - 1) {
                    *w &= (1u64 << (width % 64)) - 1;
                }
            }
            return true;
        }
        for (j, w) in out.iter_mut().take(wpr).enumerate() {
            let start = 8 * j;
            let mut buf = [0u8; 9];
            let avail = src.len().saturating_sub(start).min(9);
            if let (Some(dst), Some(s)) = (buf.get_mut(..avail), src.get(start..start + avail)) {
                dst.copy_from_slice(s);
            }
            let lo = u64::from_le_bytes([
                buf[0], buf[1], buf[2], buf[3], buf[4], buf[5], buf[6], buf[7],
            ]);
            let mut v = (lo >> shift) | (u64::from(buf[8]) << (64 - shift));
            let remaining = width - 64 * j;
            if remaining < 64 {
                v &= (1u64 << remaining) - 1;
            }
            *w = v;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_sizes() {
        assert_eq!(
            PlaneView::new(&[0; 2], 3, 5).unwrap_err(),
            Error::BadDimensions
        );
        assert_eq!(
            PlaneView::new(&[0; 2], 0, 8).unwrap_err(),
            Error::BadDimensions
        );
        assert_eq!(
            PlaneView::new(&[0; 3], 4, 4).unwrap_err(),
            Error::PlaneSize {
                expected: 2,
                got: 3
            }
        );
    }

    #[test]
    fn lsb_first_and_unaligned_rows() {
        // 12 x 2 plane: row 1 starts at bit 12 (not byte aligned).
        let mut bytes = [0u8; 3];
        let set = |b: &mut [u8; 3], p: usize| b[p / 8] |= 1 << (p % 8);
        set(&mut bytes, 0);
        set(&mut bytes, 11);
        set(&mut bytes, 12);
        set(&mut bytes, 23);
        let v = PlaneView::new(&bytes, 12, 2).unwrap();
        assert!(v.get(0, 0) && v.get(0, 11) && v.get(1, 0) && v.get(1, 11));
        assert!(!v.get(0, 1) && !v.get(2, 0) && !v.get(0, 12));
        let mut w = [0u64; 1];
        assert!(v.row_words(0, &mut w));
        assert_eq!(w[0], 1 | 1 << 11);
        assert!(v.row_words(1, &mut w));
        assert_eq!(w[0], 1 | 1 << 11);
        assert_eq!(v.count_ones(), 4);
    }

    #[test]
    fn wide_rows_match_get() {
        let (w, h) = (200u16, 4u16);
        let bytes: [u8; 100] = core::array::from_fn(|i| (i as u8).wrapping_mul(37) ^ 0x5a);
        let v = PlaneView::new(&bytes, w, h).unwrap();
        let mut words = [0u64; 4];
        for r in 0..h {
            assert!(v.row_words(r, &mut words));
            for c in 0..w {
                let bit = (words[usize::from(c) / 64] >> (c % 64)) & 1 == 1;
                assert_eq!(bit, v.get(r, c));
            }
        }
    }
}
