//! The ingest: a ring of the last `depth` spike planes of a band of rows,
//! stored as words of 64 pixels (docs/spec.md §5: "a history ring of planes").
//!
//! Ingesting a plane copies its band into the ring slot of its tick — a word
//! copy, 64 pixels at a time, and the only per-tick work: window counts, TFI
//! and segmentation read the ring lazily when a frame is due.
//!
//! Memory: `depth × rows × ceil(width/64)` words of 8 bytes, i.e. `depth/8`
//! bytes per pixel plus row padding (16 bytes per pixel at the default depth
//! of 128 planes), in a caller-supplied slice.

use crate::error::Error;
use crate::plane::{le_words, words_per_row, PlaneView};

/// Ring of spike planes over stored rows `row0..row0+rows`. Ticks count
/// planes from 0 at the first push.
#[derive(Debug)]
pub struct History<'a> {
    buf: &'a mut [u64],
    width: u16,
    height: u16,
    row0: u16,
    rows: u16,
    wpr: usize,
    depth: u16,
    next_tick: u32,
}

impl<'a> History<'a> {
    /// Words of storage a history needs, or `None` on overflow.
    pub const fn words_needed(width: u16, rows: u16, depth: u16) -> Option<usize> {
        match words_per_row(width).checked_mul(rows as usize) {
            Some(n) => n.checked_mul(depth as usize),
            None => None,
        }
    }

    /// A history of `depth` planes (1..=256) for the band of stored rows
    /// `row0..row0+rows` of a `width × height` camera.
    pub fn new(
        buf: &'a mut [u64],
        width: u16,
        height: u16,
        row0: u16,
        rows: u16,
        depth: u16,
    ) -> Result<Self, Error> {
        crate::plane::plane_bytes(width, height).ok_or(Error::BadDimensions)?;
        if rows == 0 || u32::from(row0) + u32::from(rows) > u32::from(height) {
            return Err(Error::BadBand);
        }
        if depth == 0 || depth > 256 {
            return Err(Error::BadParam(crate::error::ParamError::Window));
        }
        let needed = Self::words_needed(width, rows, depth).ok_or(Error::BadDimensions)?;
        if buf.len() < needed {
            return Err(Error::BufferTooSmall {
                needed,
                got: buf.len(),
            });
        }
        Ok(History {
            buf,
            width,
            height,
            row0,
            rows,
            wpr: words_per_row(width),
            depth,
            next_tick: 0,
        })
    }

    /// Appends one plane; returns its tick.
    #[inline]
    pub fn push(&mut self, plane: &PlaneView<'_>) -> Result<u32, Error> {
        if plane.width() != self.width || plane.height() != self.height {
            return Err(Error::PlaneMismatch);
        }
        let tick = self.next_tick;
        let next = tick.checked_add(1).ok_or(Error::TickOverflow)?;
        let (wpr, row0, width) = (self.wpr, self.row0, usize::from(self.width));
        let slot = self.slot_mut(tick);
        if width % 64 == 0 {
            // Rows of whole words: the band's bytes are its words, little-
            // endian, back to back — one pass with no per-row work.
            let start = usize::from(row0) * width / 8;
            let src = plane.bytes().get(start..start + 8 * slot.len());
            for (w, c) in slot.iter_mut().zip(src.unwrap_or(&[]).chunks_exact(8)) {
                *w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
            }
        } else if width % 8 == 0 {
            // Byte-aligned rows (the host's 400-px sensor) in this loop,
            // not through `PlaneView::row_words`, whose call per row, checks
            // and `memcpy` of the tail would cost several times the copy.
            let row_bytes = width / 8;
            let start = usize::from(row0) * row_bytes;
            let src = plane
                .bytes()
                .get(start..start + row_bytes * (slot.len() / wpr.max(1)));
            let rows = slot.chunks_exact_mut(wpr);
            for (out, bytes) in rows.zip(src.unwrap_or(&[]).chunks_exact(row_bytes)) {
                le_words(bytes, out);
            }
        } else {
            for (i, row_words) in slot.chunks_exact_mut(wpr).enumerate() {
                // `i < rows <= height - row0`, so the row exists.
                plane.row_words(row0 + i as u16, row_words);
            }
        }
        self.next_tick = next;
        Ok(tick)
    }

    fn slot_len(&self) -> usize {
        self.wpr * usize::from(self.rows)
    }

    fn slot_mut(&mut self, tick: u32) -> &mut [u64] {
        let len = self.slot_len();
        let start = (tick % u32::from(self.depth)) as usize * len;
        self.buf.get_mut(start..start + len).unwrap_or(&mut [])
    }

    /// Reattaches a ring whose storage the caller kept between calls (a
    /// firmware loop holding its buffer in a static): the ticks before
    /// `next_tick` (at most `depth` of them) are taken as held, exactly as
    /// they were pushed.
    pub fn resumed(mut self, next_tick: u32) -> Self {
        self.next_tick = next_tick;
        self
    }

    /// The tick the next push gets.
    pub fn next_tick(&self) -> u32 {
        self.next_tick
    }

    /// Oldest tick still held, `None` before the first push.
    pub fn oldest(&self) -> Option<u32> {
        self.newest()
            .map(|n| n.saturating_sub(u32::from(self.depth) - 1))
    }

    /// Newest tick held, `None` before the first push.
    pub fn newest(&self) -> Option<u32> {
        self.next_tick.checked_sub(1)
    }

    /// Whether `tick` is held.
    pub fn holds(&self, tick: u32) -> bool {
        matches!((self.oldest(), self.newest()), (Some(o), Some(n)) if tick >= o && tick <= n)
    }

    /// The planes of ticks `t0..t0 + n` as they lie in the ring: at most
    /// two runs of consecutive slots, each its planes side by side (plane
    /// `i` at words `i·len..(i + 1)·len`, `len` a plane's words), the first
    /// holding the ticks up to the ring's end and the second, empty unless
    /// the ticks wrap, the rest. `None` unless every tick is held.
    pub(crate) fn runs(&self, t0: u32, n: u32) -> Option<[&[u64]; 2]> {
        let last = t0.checked_add(n.checked_sub(1)?)?;
        if !self.holds(t0) || !self.holds(last) {
            return None;
        }
        let depth = u32::from(self.depth);
        if depth == 0 {
            return None;
        }
        let s = t0 % depth;
        let first = n.min(depth - s);
        let len = self.slot_len();
        let slots = |a: u32, k: u32| self.buf.get(a as usize * len..(a + k) as usize * len);
        Some([slots(s, first)?, slots(0, n - first)?])
    }

    /// Words of band row `row` (0-based in the band) at `tick`; an empty
    /// slice when the tick is not held or the row is outside the band.
    #[inline]
    pub fn row(&self, tick: u32, row: u16) -> &[u64] {
        if !self.holds(tick) || row >= self.rows {
            return &[];
        }
        let start =
            (tick % u32::from(self.depth)) as usize * self.slot_len() + usize::from(row) * self.wpr;
        self.buf.get(start..start + self.wpr).unwrap_or(&[])
    }

    /// The whole band at `tick` (`rows × words_per_row` words, row-major);
    /// empty when the tick is not held.
    #[inline]
    pub fn plane(&self, tick: u32) -> &[u64] {
        if !self.holds(tick) {
            return &[];
        }
        let len = self.slot_len();
        let start = (tick % u32::from(self.depth)) as usize * len;
        self.buf.get(start..start + len).unwrap_or(&[])
    }

    /// Spike of band row `row`, column `col` at `tick` (`false` if not held).
    #[inline]
    pub fn bit(&self, tick: u32, row: u16, col: u16) -> bool {
        self.row(tick, row)
            .get(usize::from(col) / 64)
            .is_some_and(|w| (w >> (col % 64)) & 1 == 1)
    }

    /// Camera width in pixels.
    pub fn width(&self) -> u16 {
        self.width
    }
    /// Camera height in pixels.
    pub fn height(&self) -> u16 {
        self.height
    }
    /// First stored row of the band.
    pub fn row0(&self) -> u16 {
        self.row0
    }
    /// Rows in the band.
    pub fn rows(&self) -> u16 {
        self.rows
    }
    /// Words per row (`ceil(width/64)`).
    pub fn words_per_row(&self) -> usize {
        self.wpr
    }
    /// Planes the ring holds at most.
    pub fn depth(&self) -> u16 {
        self.depth
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_keeps_last_depth_planes() {
        let mut buf = [0u64; 3 * 2];
        let mut h = History::new(&mut buf, 8, 2, 0, 2, 3).unwrap();
        assert_eq!(h.newest(), None);
        for t in 0..5u8 {
            let bytes = [t, 0xff - t];
            let p = PlaneView::new(&bytes, 8, 2).unwrap();
            assert_eq!(h.push(&p).unwrap(), u32::from(t));
        }
        assert_eq!((h.oldest(), h.newest()), (Some(2), Some(4)));
        assert!(!h.holds(1) && h.holds(2) && !h.holds(5));
        assert_eq!(h.row(3, 0), &[3]);
        assert_eq!(h.row(3, 1), &[0xfc]);
        assert_eq!(h.row(1, 0), &[] as &[u64]);
        assert!(h.bit(4, 0, 2) && !h.bit(4, 0, 0));
    }

    /// Every width's path (whole words, byte-aligned rows, any other)
    /// holds a band's pixels as the plane has them, bits past the width
    /// zero, over a ring slot that held other bits before.
    #[test]
    fn push_holds_the_planes_pixels() {
        for (width, height, row0, rows) in [
            (64u16, 5u16, 1u16, 3u16),
            (128, 4, 0, 4),
            (400, 6, 2, 3),
            (8, 5, 1, 4),
            (72, 3, 0, 3),
            (100, 4, 1, 2),
            (13, 8, 2, 5),
        ] {
            let n = crate::plane::plane_bytes(width, height).unwrap();
            let wpr = crate::plane::words_per_row(width);
            let mut buf = std::vec![u64::MAX; 2 * wpr * usize::from(rows)];
            let mut h = History::new(&mut buf, width, height, row0, rows, 2).unwrap();
            for t in 0..3u32 {
                let bytes: std::vec::Vec<u8> = (0..n)
                    .map(|i| (i as u32 * 0x9E37 + t * 0x51).wrapping_mul(0x2F) as u8)
                    .collect();
                let plane = PlaneView::new(&bytes, width, height).unwrap();
                assert_eq!(h.push(&plane).unwrap(), t);
                for r in 0..rows {
                    let words = h.row(t, r);
                    for c in 0..64 * wpr as u16 {
                        let bit = words[usize::from(c / 64)] >> (c % 64) & 1 == 1;
                        let want = c < width && plane.get(row0 + r, c);
                        assert_eq!(bit, want, "width {width} tick {t} row {r} col {c}");
                    }
                }
            }
        }
    }

    #[test]
    fn band_and_errors() {
        let mut buf = [0u64; 4];
        assert_eq!(
            History::new(&mut buf, 8, 4, 3, 2, 2).unwrap_err(),
            Error::BadBand
        );
        assert!(matches!(
            History::new(&mut buf, 8, 4, 0, 4, 2),
            Err(Error::BufferTooSmall { .. })
        ));
        let mut h = History::new(&mut buf, 8, 4, 1, 2, 2).unwrap();
        let bytes = [1, 2, 3, 4];
        assert_eq!(h.push(&PlaneView::new(&bytes, 8, 4).unwrap()).unwrap(), 0);
        assert_eq!(h.row(0, 0), &[2]);
        assert_eq!(h.row(0, 1), &[3]);
        let other = [0u8; 2];
        assert_eq!(
            h.push(&PlaneView::new(&other, 8, 2).unwrap()).unwrap_err(),
            Error::PlaneMismatch
        );
    }
}
