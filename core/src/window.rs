//! Centred windows over the spike history, bit-parallel window counts, and
//! the two classic reconstructions TFP and TFI (docs/spec.md §5).
//!
//! `c_n(x, y, k)` counts the spikes of a pixel over the `n` ticks
//! `[k − ⌊n/2⌋, k − ⌊n/2⌋ + n)`. Windows are nested as `n` grows. Near the ends
//! of the history a window is clipped to the ticks held, and rates use its
//! real length ([`Window::len`]).
//!
//! Counting is bit-sliced ([`crate::slices`]): 64 pixels' counters as eight
//! bit planes, read back into bytes once; counts are bytes, so a window is
//! at most 255 ticks.

use crate::error::{Error, ParamError};
use crate::history::History;
use crate::slices::{self, SPREAD};

/// A window of ticks after clipping to the history.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Window {
    /// First tick.
    pub start: u32,
    /// Ticks actually held (≤ `nominal`; 0 when nothing is held).
    pub len: u16,
    /// The requested length n, ticks.
    pub nominal: u16,
}

impl Window {
    /// The window of `n` ticks centred on `k`, clipped to `[oldest, newest]`.
    pub fn centred(k: u32, n: u16, oldest: u32, newest: u32) -> Window {
        let a = i64::from(k) - i64::from(n / 2);
        let e = a + i64::from(n);
        let a2 = a.max(i64::from(oldest));
        let e2 = e.min(i64::from(newest) + 1);
        let len = (e2 - a2).clamp(0, i64::from(n)) as u16;
        let start = a2.clamp(0, i64::from(u32::MAX)) as u32;
        Window {
            start,
            len,
            nominal: n,
        }
    }

    /// The window of `n` ticks centred on `k` in `hist` (empty if it holds nothing).
    pub fn in_history(hist: &History<'_>, k: u32, n: u16) -> Window {
        match (hist.oldest(), hist.newest()) {
            (Some(o), Some(w)) => Window::centred(k, n, o, w),
            _ => Window {
                start: k,
                len: 0,
                nominal: n,
            },
        }
    }

    /// One past the last tick.
    pub fn end(&self) -> u32 {
        self.start.saturating_add(u32::from(self.len))
    }
}

/// The planes of a window, gathered once: slice `i` is the band at tick
/// `start + i` (an empty slice for a tick not held). At most 256 planes.
#[derive(Debug)]
pub struct Span<'h> {
    /// First tick.
    pub start: u32,
    planes: heapless::Vec<&'h [u64], 256>,
    runs: Runs<'h>,
}

/// The held planes of a [`Span`] as they lie in the history's ring: at
/// most two runs of consecutive slots, each `(offset of its first plane
/// in the span, its planes side by side)`, every plane `stride` words.
/// A loop over a run's planes steps a pointer by `stride` instead of
/// reading each plane's slice (the regions' per-tick sums run on this).
/// Empty when the runs would not be exactly the held planes.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Runs<'h> {
    pub(crate) runs: [(usize, &'h [u64]); 2],
    /// Words per plane (at least 1 where there is a run).
    pub(crate) stride: usize,
}

impl<'h> Runs<'h> {
    /// The runs of `planes` (ticks from `start`), or none.
    fn new(hist: &'h History<'_>, start: u32, planes: &[&'h [u64]]) -> Runs<'h> {
        let Some(a) = planes.iter().position(|p| !p.is_empty()) else {
            return Runs::default();
        };
        let e = planes.len() - planes.iter().rev().position(|p| !p.is_empty()).unwrap_or(0);
        let stride = planes[a].len();
        let Some(t0) = start.checked_add(a as u32) else {
            return Runs::default();
        };
        let Some([r0, r1]) = hist.runs(t0, (e - a) as u32) else {
            return Runs::default();
        };
        let runs = [(a, r0), (a + r0.len() / stride.max(1), r1)];
        // Exactly the held planes, each `stride` words (a hole or a plane
        // of another length would be summed wrongly).
        let held = planes[a..e].iter().all(|p| p.len() == stride);
        if !held || runs[0].1.len() + runs[1].1.len() != (e - a) * stride {
            return Runs::default();
        }
        Runs { runs, stride }
    }
}

impl<'h> Span<'h> {
    /// The planes of `win` (clipped to 256 ticks).
    pub fn new(hist: &'h History<'_>, win: Window) -> Span<'h> {
        let mut planes = heapless::Vec::new();
        for t in win.start..win.end() {
            if planes.push(hist.plane(t)).is_err() {
                break;
            }
        }
        let runs = Runs::new(hist, win.start, &planes);
        Span {
            start: win.start,
            planes,
            runs,
        }
    }

    /// A span of `planes` from tick `start`, without runs (its sums read
    /// plane by plane).
    #[cfg(test)]
    pub(crate) fn from_planes(start: u32, planes: &[&'h [u64]]) -> Span<'h> {
        Span {
            start,
            planes: planes.iter().copied().take(256).collect(),
            runs: Runs::default(),
        }
    }

    /// The held planes as runs of ring slots ([`Runs`]).
    pub(crate) fn runs(&self) -> &Runs<'h> {
        &self.runs
    }

    /// The planes of ticks `a..e` (clipped to the span).
    #[inline]
    pub fn range(&self, a: u32, e: u32) -> &[&'h [u64]] {
        let lo = (a.saturating_sub(self.start) as usize).min(self.planes.len());
        let hi = (e.saturating_sub(self.start) as usize).clamp(lo, self.planes.len());
        &self.planes[lo..hi]
    }

    /// All planes.
    pub fn planes(&self) -> &[&'h [u64]] {
        &self.planes
    }
}

/// Where each centred window of one frame lies in its span: for every
/// `n` up to n_max the planes `a..e` of [`Window::in_history`]`(n)` as
/// offsets from the span's first tick (at most 255), so a prefix-sum
/// table over the span gives any window's sum in two reads. Built once
/// per frame (the adaptive search asks for up to 70 windows per region).
#[derive(Debug, Clone)]
pub(crate) struct Offsets {
    at: [(u8, u8); 256],
}

impl Offsets {
    /// The offsets of windows `1..=n_max` centred on `k` in `span`.
    pub(crate) fn new(hist: &History<'_>, k: u32, span: &Span<'_>, n_max: u16) -> Offsets {
        let mut at = [(0u8, 0u8); 256];
        for (n, o) in at.iter_mut().enumerate().take(usize::from(n_max) + 1) {
            let w = Window::in_history(hist, k, n as u16);
            let a = (w.start.saturating_sub(span.start) as usize).min(255);
            let e = (a + usize::from(w.len)).min(255);
            *o = (a.min(e) as u8, e as u8);
        }
        Offsets { at }
    }

    /// Window `n`'s planes `a..e` in the span (`0..0` past n_max).
    #[inline]
    pub(crate) fn of(&self, n: u16) -> (usize, usize) {
        let (a, e) = self.at.get(usize::from(n)).copied().unwrap_or((0, 0));
        (usize::from(a), usize::from(e))
    }
}

/// Adds, for every pixel of band rows `rows.0..rows.1`, its spikes over
/// ticks `ticks.0..ticks.1` to `counts` (row-major, `width` per row, first
/// row = `rows.0`). Ticks not held count nothing. The caller keeps every
/// count ≤ 255 (at most 255 ticks in all); bytes wrap otherwise.
pub fn add_counts(hist: &History<'_>, rows: (u16, u16), ticks: (u32, u32), counts: &mut [u8]) {
    if ticks.1 <= ticks.0 {
        return;
    }
    let len = (ticks.1 - ticks.0).min(256) as u16;
    let span = Span::new(
        hist,
        Window {
            start: ticks.0,
            len,
            nominal: len,
        },
    );
    add_plane_counts(span.planes(), hist.width(), rows, counts);
}

/// [`add_counts`] over planes already gathered (each `band rows × words`).
///
/// Bit-sliced ([`add_words`]).
pub fn add_plane_counts(planes: &[&[u64]], width: u16, rows: (u16, u16), counts: &mut [u8]) {
    let width = usize::from(width);
    let wpr = crate::plane::words_per_row(width as u16);
    if planes.is_empty() || width == 0 {
        return;
    }
    for (r, crow) in (rows.0..rows.1).zip(counts.chunks_exact_mut(width)) {
        let row_off = usize::from(r) * wpr;
        for (j, cw) in crow.chunks_mut(64).enumerate() {
            let idx = row_off + j;
            add_words(planes, |p| p.get(idx).copied().unwrap_or(0), cw);
        }
    }
}

/// Adds the words of spikes `word(item)` of every item (bit `b` of a word
/// the pixel `b`) to the byte counters `out` (at most 64 pixels).
/// Bit-sliced: 15 words at a time are summed into 4-bit carry-save
/// counters ([`slices::csa`]), then flushed into the byte counters through
/// the `SPREAD` table. Hand-written because this is the hot loop of every
/// TFP and compensated frame.
#[inline(always)]
pub(crate) fn add_words<T: Copy>(items: &[T], word: impl Fn(T) -> u64, out: &mut [u8]) {
    let mut acc = [0u64; 8];
    for chunk in items.chunks(15) {
        let mut s = [0u64; 4];
        for &item in chunk {
            slices::csa(&mut s, word(item));
        }
        if s[0] | s[1] | s[2] | s[3] == 0 {
            continue;
        }
        for (g, a) in acc.iter_mut().enumerate() {
            let sh = 8 * g;
            let b = |s: u64| SPREAD[((s >> sh) & 0xff) as usize];
            *a = a.wrapping_add(b(s[0]) + (b(s[1]) << 1) + (b(s[2]) << 2) + (b(s[3]) << 3));
        }
    }
    for (g, c8) in out.chunks_mut(8).enumerate() {
        let lanes = acc.get(g).copied().unwrap_or(0).to_le_bytes();
        for (c, l) in c8.iter_mut().zip(lanes) {
            *c = c.wrapping_add(l);
        }
    }
}

/// Rounded `full_scale · num / den` (0 when `den` is 0), clamped to full scale.
#[inline]
pub(crate) fn scale(full_scale: u16, num: u64, den: u64) -> u16 {
    if den == 0 {
        return 0;
    }
    let v = (u64::from(full_scale) * num + den / 2) / den;
    v.min(u64::from(full_scale)) as u16
}

/// TFP: gray = FS·c_n/len for every pixel of the band, window `n` (1..=255
/// ticks, at most the history depth) centred on `k`. `counts` is scratch of
/// `rows × width` bytes; `out` receives `rows × width` gray levels (stored
/// row order). Returns the window actually used.
pub fn tfp<G: crate::gray::Gray>(
    hist: &History<'_>,
    k: u32,
    n: u16,
    full_scale: u16,
    counts: &mut [u8],
    out: &mut [G],
) -> Result<Window, Error> {
    if n == 0 || n > 255 || n > hist.depth() {
        return Err(Error::BadParam(ParamError::Window));
    }
    let px = usize::from(hist.width()) * usize::from(hist.rows());
    check_len(counts.len(), px)?;
    check_len(out.len(), px)?;
    let win = Window::in_history(hist, k, n);
    if win.len == 0 {
        return Err(Error::TickUnavailable);
    }
    let counts = &mut counts[..px];
    counts.fill(0);
    add_counts(hist, (0, hist.rows()), (win.start, win.end()), counts);
    for (o, &c) in out.iter_mut().zip(counts.iter()) {
        *o = G::from_level(scale(
            full_scale.min(G::MAX),
            u64::from(c),
            u64::from(win.len),
        ));
    }
    Ok(win)
}

pub(crate) fn check_len(got: usize, needed: usize) -> Result<(), Error> {
    if got < needed {
        Err(Error::BufferTooSmall { needed, got })
    } else {
        Ok(())
    }
}

/// TFI: gray = FS/isi, with isi the ticks from the last spike at or before
/// `k` to the first spike after `k`, both searched within
/// `[k − ⌊n_max/2⌋, k − ⌊n_max/2⌋ + n_max)`; a pixel missing either spike gets
/// isi = n_max (never a division by zero). `out` receives `rows × width`.
pub fn tfi<G: crate::gray::Gray>(
    hist: &History<'_>,
    k: u32,
    n_max: u16,
    full_scale: u16,
    out: &mut [G],
) -> Result<(), Error> {
    if n_max < 2 || n_max > hist.depth() {
        return Err(Error::BadParam(ParamError::Window));
    }
    let width = usize::from(hist.width());
    check_len(out.len(), width * usize::from(hist.rows()))?;
    let win = Window::in_history(hist, k, n_max);
    if !hist.holds(k) || win.len == 0 {
        return Err(Error::TickUnavailable);
    }
    let fs = full_scale.min(G::MAX);
    for (r, orow) in (0..hist.rows()).zip(out.chunks_exact_mut(width)) {
        for (j, ow) in orow.chunks_mut(64).enumerate() {
            let lanes = ow.len();
            let all = if lanes == 64 {
                u64::MAX
            } else {
                (1u64 << lanes) - 1
            };
            let mut prev = [u32::MAX; 64];
            let mut next = [u32::MAX; 64];
            // Backwards from k for the last spike at or before k.
            let mut found = 0u64;
            let mut t = k;
            while found != all && t >= win.start {
                let mut new = hist.row(t, r).get(j).copied().unwrap_or(0) & all & !found;
                found |= new;
                while new != 0 {
                    prev[new.trailing_zeros() as usize] = t;
                    new &= new - 1;
                }
                if t == 0 {
                    break;
                }
                t -= 1;
            }
            let mut found = 0u64;
            let mut t = k.saturating_add(1);
            while found != all && t < win.end() {
                let mut new = hist.row(t, r).get(j).copied().unwrap_or(0) & all & !found;
                found |= new;
                while new != 0 {
                    next[new.trailing_zeros() as usize] = t;
                    new &= new - 1;
                }
                t += 1;
            }
            for ((o, &p), &nx) in ow.iter_mut().zip(prev.iter()).zip(next.iter()) {
                let isi = if p == u32::MAX || nx == u32::MAX {
                    u32::from(n_max)
                } else {
                    nx - p
                };
                *o = G::from_level(scale(fs, 1, u64::from(isi)));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::PlaneView;

    #[test]
    fn centred_windows_clip() {
        let w = Window::centred(10, 4, 0, 100);
        assert_eq!((w.start, w.len), (8, 4));
        let w = Window::centred(10, 5, 0, 100);
        assert_eq!((w.start, w.len), (8, 5));
        let w = Window::centred(1, 8, 0, 100);
        assert_eq!((w.start, w.len), (0, 5));
        let w = Window::centred(99, 8, 0, 100);
        assert_eq!((w.start, w.len), (95, 6));
        let w = Window::centred(500, 8, 0, 100);
        assert_eq!(w.len, 0);
    }

    #[test]
    fn counts_tfp_and_tfi() {
        // 70 x 8 camera so a row spans two words with a partial last word.
        let (w, h) = (72u16, 8u16);
        let mut buf = [0u64; 2 * 8 * 16];
        let mut hist = History::new(&mut buf, w, h, 0, 8, 16).unwrap();
        let nbytes = 72;
        for t in 0..16u32 {
            let mut bytes = [0u8; 72];
            // pixel (row 2, col 65) fires every 4th tick; (0,0) every tick.
            for (p, on) in [(2 * 72 + 65, t % 4 == 0), (0, true)] {
                if on {
                    bytes[p / 8] |= 1 << (p % 8);
                }
            }
            hist.push(&PlaneView::new(&bytes[..nbytes], w, h).unwrap())
                .unwrap();
        }
        let mut counts = [0u8; 72 * 8];
        let mut out = [0u8; 72 * 8];
        let win = tfp(&hist, 8, 8, 255, &mut counts, &mut out).unwrap();
        assert_eq!((win.start, win.len), (4, 8));
        assert_eq!(counts[2 * 72 + 65], 2);
        assert_eq!(counts[0], 8);
        assert_eq!(out[0], 255);
        assert_eq!(out[2 * 72 + 65], 64); // 255 * 2 / 8 = 63.75
        assert_eq!(counts.iter().map(|&c| u32::from(c)).sum::<u32>(), 10);

        let mut out = [0u8; 72 * 8];
        tfi(&hist, 9, 16, 255, &mut out).unwrap();
        assert_eq!(out[2 * 72 + 65], 64); // spikes at 8 and 12: isi 4
        assert_eq!(out[0], 255); // isi 1
        assert_eq!(out[1], 16); // no spikes: isi = n_max = 16
    }

    /// A span's runs are its held planes in order, whatever the ring's
    /// wrap and the window's clipping: every window of a history of
    /// depth 8 over 3..21 pushed planes (tick `t` has pixel `t` set).
    #[test]
    fn span_runs_are_the_held_planes() {
        let (w, h) = (64u16, 1u16);
        for pushed in 3..21u32 {
            let mut buf = [0u64; 8];
            let mut hist = History::new(&mut buf, w, h, 0, 1, 8).unwrap();
            for t in 0..pushed {
                let bytes = (1u64 << t).to_le_bytes();
                hist.push(&PlaneView::new(&bytes, w, h).unwrap()).unwrap();
            }
            for start in 0..pushed + 4 {
                for len in 0..12u16 {
                    let win = Window {
                        start,
                        len,
                        nominal: len,
                    };
                    let span = Span::new(&hist, win);
                    let runs = span.runs();
                    let mut from_runs = std::vec![None; span.planes().len()];
                    for &(o, run) in &runs.runs {
                        for (i, p) in run.chunks_exact(runs.stride.max(1)).enumerate() {
                            from_runs[o + i] = Some(p[0]);
                        }
                    }
                    let want: std::vec::Vec<_> =
                        span.planes().iter().map(|p| p.first().copied()).collect();
                    assert_eq!(from_runs, want, "pushed {pushed}, window {start}+{len}");
                    let held = want.iter().filter(|p| p.is_some()).count();
                    assert_eq!(runs.stride, usize::from(held > 0));
                }
            }
        }
    }
}
