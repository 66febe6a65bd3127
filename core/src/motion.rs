//! Motion compensation (beyond the paper): counting a pixel's
//! spikes along a particle's predicted path instead of at a fixed place,
//! and refining the prediction from the spikes themselves.
//!
//! A velocity `v` per band row and tile column ([`Motion`]: x right, y
//! down in stored rows, Q12: 1/4096 px per tick) moves plane `t` of a
//! window centred on `k_c` by
//! `s = round(v·(t − k_c))` before its spikes are added: the compensated
//! count of pixel (r, c) over a window is the number of ticks `t` with a
//! spike at (r + s_y, c + s_x). A particle moving at `v` then piles its
//! spikes up where it was at `k_c` instead of smearing them along its path,
//! so long windows gather light without blur. Rows or columns shifted in
//! from outside the band count nothing. Shifts are whole pixels: a packed
//! row moves by a funnel shift of two words (a barrel shifter on an FPGA).
//!
//! [`refine`] corrects a predicted velocity by contrast maximisation: per
//! node (a band of rows in one tile column) it tries velocities around the
//! prediction (scaled by
//! ±[`RELATIVE_STEP`]·k and offset by ±[`ABSOLUTE_STEP`]·k in x and in y)
//! and keeps the one whose compensated counts are sharpest (largest sum of
//! squared counts; a blurred particle spreads the same spikes over more
//! pixels, which lowers it) — if it beats the prediction by more than
//! [`Refine::min_gain`]. With a PIV prediction a few per cent off, the
//! refined velocity is within about 1–4 % on the paper's scenes
//! (`host/examples/mc_probe.rs`).
//!
//! Memory: none beyond the caller's buffers; [`refine`] keeps a 2 KiB
//! table of one column's band winners, its per-tick shifts (3 KiB on a
//! 32-bit MCU, 4 KiB on a 64-bit host) and a block's counters (1.5 KiB) on
//! the stack. Cost of [`refine`]: at most (1 + 2·rel + 4·abs) windows of
//! compensated counts per pixel, summed as squares in the bit planes;
//! candidates that shift every plane of a node as an earlier one does are
//! not counted again.
//!
//! Rounding rule, the one definition both this module and the host's `f64`
//! reference use: `round(v·Δt/4096) = ⌊(v·Δt + 2048)/4096⌋` (halves up).
//!
//! Why 1/4096 and not 1/256: where frames
//! overlap in time, the compensated pair shares most of its spikes, and
//! a shared spike moves between the two frames by exactly the predicted
//! displacement; PIV of the pair reads about half way between the
//! prediction and the truth (10 % off → 5 % off on the paper's shear
//! rows). A slow row's velocity rounded to 1/256 px per tick was up to
//! 14 % off (0.0135 px/tick, the quadratic profile 26 px above the wall,
//! became 3/256), and its PIV inherited half of that. The range is
//! ±8 px per tick (i16), beyond any particle a spike camera images as
//! a particle rather than a streak; faster predictions saturate.

use crate::error::{Error, ParamError};
use crate::history::History;
use crate::slices::{self, Counter};
use crate::window::{Span, Window};

/// Velocities are in 1/`Q` px per tick (Q12).
pub const Q: i32 = 1 << Q_BITS;
/// Fraction bits of a velocity: `shift` divides by [`Q`] with an
/// arithmetic shift by this.
pub const Q_BITS: u32 = 12;

/// Relative step of [`refine`]'s scaled candidates, in 1/[`REL_DEN`]
/// (2 %).
pub const RELATIVE_STEP: i32 = 2;
/// Denominator of [`RELATIVE_STEP`].
pub const REL_DEN: i32 = 100;
/// Most bands [`refine`] handles (its winners live on the stack: 2 KiB).
pub const MAX_BANDS: usize = 512;
/// Step of [`refine`]'s offset candidates, 1/[`Q`] px per tick (48/4096
/// ≈ 0.012 px/tick).
pub const ABSOLUTE_STEP: i32 = 48;

/// Shortest path, px, over which a compensated particle test also requires
/// a pixel to stand out against its own plain count (`segment`). Where
/// the predicted motion moves nothing within a level's window (a still
/// row: 0 px) the compensated counts are the plain ones and the paper's
/// test stands alone, so zero motion gives the plain frame. Longer
/// thresholds lose the floor where it matters most, the slow rows next to
/// a wall under glare (`spiv bench paper`, 10 seeds, glare-row RMAE
/// linear / quadratic: 0.063 / 0.129 at 1 px, 0.137 / 0.335 at 2 px,
/// 0.200 / 0.423 at 4 px, 0.280 / 0.473 without the floor).
pub const MIN_TRAVEL: i32 = 1;

/// The most tile columns (`cols`) a [`Motion`] may have: a 65 535 px row
/// holds 1024 words of 64 px.
pub const MAX_COLS: u16 = 1024;

/// The tile a per-row motion states on the wire (one column covers the
/// row whatever its tile).
pub const ROW_TILE: u16 = 64;

/// A predicted velocity per band row and tile column: a 2-D grid that is
/// fine in y (every band row; the host interpolates its coarser nodes) and
/// piecewise constant in x over tiles of `tile` px, a whole number of
/// 64-px words, so every packed word of a row moves by one shift (one
/// funnel shift of two words per tick, as a per-row motion; a tile that
/// split a word would cost a shift and a mask per part).
///
/// Entry `r·cols + c` is band row `r`'s velocity in tile column `c`
/// (columns `c·tile ..`); the last column also covers whatever of the row
/// lies beyond `cols·tile`. A per-row motion ([`Motion::rows`]) is the
/// case `cols = 1`.
#[derive(Debug, Clone, Copy)]
pub struct Motion<'a> {
    /// x velocities, 1/4096 px per tick, `rows × cols` row-major (missing
    /// entries: 0).
    pub vx: &'a [i16],
    /// y velocities (stored rows, down), 1/4096 px per tick, laid out as
    /// `vx`.
    pub vy: &'a [i16],
    /// Tile columns per row, 1..=[`MAX_COLS`].
    pub cols: u16,
    /// Width of a tile column, 64-px words (≥ 1).
    pub tile_words: u16,
}

impl<'a> Motion<'a> {
    /// One velocity per band row (`vx[r]`, `vy[r]`).
    pub fn rows(vx: &'a [i16], vy: &'a [i16]) -> Motion<'a> {
        Motion {
            vx,
            vy,
            cols: 1,
            tile_words: 1,
        }
    }

    /// A grid of `cols` tile columns of `tile` px per band row; `cols`
    /// must be in 1..=[`MAX_COLS`] and, with more than one column, `tile`
    /// a positive multiple of 64 (one column covers the row whatever its
    /// tile: [`Motion::rows`]).
    pub fn grid(vx: &'a [i16], vy: &'a [i16], cols: u16, tile: u16) -> Result<Motion<'a>, Error> {
        if cols == 1 {
            return Ok(Motion::rows(vx, vy));
        }
        if cols == 0 || cols > MAX_COLS || tile == 0 || !tile.is_multiple_of(64) {
            return Err(Error::BadParam(ParamError::Motion));
        }
        Ok(Motion {
            vx,
            vy,
            cols,
            tile_words: tile / 64,
        })
    }

    /// Entries a motion of `rows` band rows and `cols` columns needs.
    pub const fn entries(rows: u16, cols: u16) -> usize {
        rows as usize * cols as usize
    }

    /// The tile column of word `j` of a row.
    #[inline]
    pub fn col_of_word(&self, j: usize) -> u16 {
        let c = j / usize::from(self.tile_words.max(1));
        c.min(usize::from(self.cols.max(1)) - 1) as u16
    }

    /// The velocity of band row `r` in tile column `c`.
    #[inline]
    pub fn at(&self, r: u16, c: u16) -> (i16, i16) {
        let i = usize::from(r) * usize::from(self.cols.max(1)) + usize::from(c);
        (
            self.vx.get(i).copied().unwrap_or(0),
            self.vy.get(i).copied().unwrap_or(0),
        )
    }

    /// The velocity of band row `r` at word `j` (its 64 pixels share one).
    #[inline]
    pub fn at_word(&self, r: u16, j: usize) -> (i16, i16) {
        self.at(r, self.col_of_word(j))
    }

    /// Words `j` of a `wpr`-word row in tile column `c`.
    pub fn words_of(&self, c: u16, wpr: usize) -> core::ops::Range<usize> {
        let tw = usize::from(self.tile_words.max(1));
        let j0 = (usize::from(c) * tw).min(wpr);
        let j1 = if c + 1 >= self.cols.max(1) {
            wpr
        } else {
            (j0 + tw).min(wpr)
        };
        j0..j1
    }

    /// Whether the motion holds every entry of `rows` band rows.
    pub fn covers(&self, rows: u16) -> bool {
        let n = Motion::entries(rows, self.cols);
        self.vx.len() >= n && self.vy.len() >= n
    }
}

/// The shift of a plane `dt` ticks from the centre for velocity `v` (Q12),
/// px: `⌊(v·dt + 2048)/4096⌋`.
#[inline]
pub fn shift(v: i16, dt: i32) -> i32 {
    // An arithmetic right shift by Q_BITS is the floor division by Q;
    // |v·dt| ≤ 32768·65535 + Q/2 fits in an i32 (callers clamp dt).
    (i32::from(v) * dt + Q / 2) >> Q_BITS
}

/// Farthest a particle at velocity `v` (Q12) travels from where it is at
/// `kc` within the ticks `start..end`, px: the larger of |x| and |y| of
/// [`shift`] at the window's two ends (0 for an empty window).
pub fn travel(v: (i16, i16), start: u32, end: u32, kc: u32) -> i32 {
    if end <= start {
        return 0;
    }
    let dt = |t: u32| (i64::from(t) - i64::from(kc)).clamp(-65_535, 65_535) as i32;
    [dt(start), dt(end - 1)]
        .iter()
        .map(|&d| shift(v.0, d).abs().max(shift(v.1, d).abs()))
        .max()
        .unwrap_or(0)
}

/// Distinct pixels a particle at velocity `v` (Q12) visits within the ticks
/// `start..end` of a window centred on `kc`: 1 plus the ticks at which its
/// [`shift`] changes (the spikes of that many pixels make one compensated
/// count; 1 for a still row or an empty window). At most 255 ticks are
/// looked at, the longest window a count holds.
pub fn positions(v: (i16, i16), start: u32, end: u32, kc: u32) -> u32 {
    let dt = |t: u32| (i64::from(t) - i64::from(kc)).clamp(-65_535, 65_535) as i32;
    let at = |t: u32| (shift(v.0, dt(t)), shift(v.1, dt(t)));
    let end = end.min(start.saturating_add(255));
    let mut n = 1;
    let mut prev = at(start);
    for t in start.saturating_add(1)..end {
        let p = at(t);
        if p != prev {
            n += 1;
            prev = p;
        }
    }
    n
}

/// Word `j` of band row `r` of a plane (`rows × wpr` words) moved by
/// `(sx, sy)`: bit `i` is the spike at row `r + sy`, column `64j + i + sx`
/// (0 outside the band). Hot in the compensated region sums, hence
/// always inlined.
#[inline(always)]
pub fn shifted_word(
    plane: &[u64],
    wpr: usize,
    rows: u16,
    r: u16,
    j: usize,
    sx: i32,
    sy: i32,
) -> u64 {
    Source::new(plane, wpr, rows, r, sx, sy).word(j)
}

/// Adds the motion-compensated counts of band rows `rows.0..rows.1` over
/// `planes` (consecutive ticks from `start`, each the band's
/// `band_rows × words` words) for a frame centred on `kc` to `counts`
/// (row-major, `width` per row, first row = `rows.0`), each word with
/// `motion`'s velocity at its row and tile column. The caller keeps every
/// count ≤ 255 (at most 255 ticks in all); bytes wrap otherwise.
#[allow(clippy::too_many_arguments)]
pub fn add_compensated(
    planes: &[&[u64]],
    start: u32,
    kc: u32,
    width: u16,
    band_rows: u16,
    rows: (u16, u16),
    motion: &Motion<'_>,
    counts: &mut [u8],
) {
    let w = usize::from(width);
    let wpr = crate::plane::words_per_row(width);
    for (r, crow) in (rows.0..rows.1).zip(counts.chunks_exact_mut(w)) {
        for c in 0..motion.cols.max(1) {
            let words = motion.words_of(c, wpr);
            let Some(cw) = crow.get_mut(64 * words.start..(64 * words.end).min(w)) else {
                continue;
            };
            let at = (planes, start, kc, wpr, band_rows);
            add_words_of(at, r, motion.at(r, c), words.start, cw);
        }
    }
}
/// Settings of [`refine`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Refine {
    /// Rows per band that get one velocity (≥ 1).
    pub band: u16,
    /// Window of the compensated counts, ticks (1..=255).
    pub window: u16,
    /// Scaled candidates `v·(1 + k·2 %)` for `k` in `−rel..=rel`.
    pub rel: u8,
    /// Offset candidates `v + k·3/256 px/tick`, in x and in y, for `k` in
    /// `−abs..=abs`.
    pub abs: u8,
    /// A candidate replaces the prediction only when its sum of squares
    /// beats the prediction's by more than this, in 1/1000 (where noise
    /// swamps the particles, as in glare, the contrast is flat and the
    /// prediction is kept).
    pub min_gain: u16,
}

impl Default for Refine {
    /// 16-row bands, 64 ticks, ±40 % and ±0.06 px/tick, a 2 % gain.
    fn default() -> Self {
        Refine {
            band: 16,
            window: 64,
            rel: 20,
            abs: 5,
            min_gain: 20,
        }
    }
}

/// The `n`-th candidate of [`refine`] around `(vx, vy)`, in the order they
/// are tried (the prediction first), or `None` past the last.
pub fn candidate(cfg: &Refine, vx: i16, vy: i16, n: usize) -> Option<(i16, i16)> {
    let (rel, abs) = (usize::from(cfg.rel), usize::from(cfg.abs));
    let clamp = |v: i32| v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
    let signed = |m: usize| -> i32 {
        // 1, −1, 2, −2, …
        let k = (m / 2 + 1) as i32;
        if m.is_multiple_of(2) {
            k
        } else {
            -k
        }
    };
    if n == 0 {
        return Some((vx, vy));
    }
    let n = n - 1;
    if n < 2 * rel {
        let s = REL_DEN + RELATIVE_STEP * signed(n);
        let scale = |v: i16| clamp((i32::from(v) * s).div_euclid(REL_DEN));
        return Some((scale(vx), scale(vy)));
    }
    let n = n - 2 * rel;
    if n < 2 * abs {
        return Some((clamp(i32::from(vx) + ABSOLUTE_STEP * signed(n)), vy));
    }
    let n = n - 2 * abs;
    if n < 2 * abs {
        return Some((vx, clamp(i32::from(vy) + ABSOLUTE_STEP * signed(n))));
    }
    None
}

/// Refines `motion` at the frame centred on `kc` by contrast maximisation:
/// for each node — a band of `cfg.band` rows in one tile column — every
/// [`candidate`] around the velocity of the band's middle row there is
/// tried over a window of `cfg.window` ticks, and the one with the largest
/// sum of squared compensated counts over the node's pixels wins (the
/// earliest on a tie, so the prediction when nothing is sharper). The
/// winners are written to `out_vx`, `out_vy` (laid out as `motion`'s:
/// `rows × cols`), per column piecewise linear in y between band centres
/// (rounded down) and constant beyond the outer ones; the refined motion
/// is `motion` with these velocities. Kept out of line (one call per
/// frame) so instruction counters can attribute its cost
/// (`firmware-sim/cost.sh`).
#[inline(never)]
pub fn refine(
    hist: &History<'_>,
    kc: u32,
    motion: &Motion<'_>,
    cfg: &Refine,
    out_vx: &mut [i16],
    out_vy: &mut [i16],
) -> Result<(), Error> {
    if cfg.band == 0 || cfg.window == 0 || cfg.window > 255 {
        return Err(Error::BadParam(ParamError::Window));
    }
    if motion.cols == 0 || motion.cols > MAX_COLS || motion.tile_words == 0 {
        return Err(Error::BadParam(ParamError::Motion));
    }
    if !hist.holds(kc) {
        return Err(Error::TickUnavailable);
    }
    let (width, rows) = (hist.width(), hist.rows());
    let cols = usize::from(motion.cols);
    let entries = Motion::entries(rows, motion.cols);
    crate::window::check_len(out_vx.len(), entries)?;
    crate::window::check_len(out_vy.len(), entries)?;
    let bands = rows.div_ceil(cfg.band);
    if usize::from(bands) > MAX_BANDS {
        return Err(Error::BufferTooSmall {
            needed: usize::from(bands),
            got: MAX_BANDS,
        });
    }
    let wpr = crate::plane::words_per_row(width);
    let span = Span::new(hist, Window::in_history(hist, kc, cfg.window));
    let mut win = [(0i16, 0i16); MAX_BANDS];
    let mut sharp = SharpScratch {
        shifts: [Shift::default(); 256],
    };
    // The window's ticks relative to the centre.
    let dts = (
        i64::from(span.start) - i64::from(kc),
        i64::from(span.start) + span.planes().len() as i64 - 1 - i64::from(kc),
    );
    for c in 0..motion.cols {
        let words = motion.words_of(c, wpr);
        for (b, slot) in (0..bands).zip(win.iter_mut()) {
            let r0 = b * cfg.band;
            let r1 = r0.saturating_add(cfg.band).min(rows);
            let (px, py) = motion.at(r0 + (r1 - r0) / 2, c);
            let mut best: Option<(u64, i16, i16)> = None;
            let mut first = 0u64;
            let mut n = 0;
            // Candidates measured so far in this node. One whose shifts
            // equal a measured one's at every tick of the window has its
            // counts, so its sum, and cannot beat it (a later one wins only
            // when larger): it is skipped. Slow rows have many such.
            let mut seen: heapless::Vec<(i16, i16), 64> = heapless::Vec::new();
            while let Some((cx, cy)) = candidate(cfg, px, py, n) {
                n += 1;
                if seen.iter().any(|&o| same_path(o, (cx, cy), dts)) {
                    continue;
                }
                // A full table only stops the skipping.
                let _ = seen.push((cx, cy));
                let node = Node {
                    width,
                    band_rows: rows,
                    rows: (r0, r1),
                    words: (words.start, words.end),
                };
                let e = sharpness(&mut sharp, &span, kc, &node, (cx, cy));
                if n == 1 {
                    first = e;
                }
                if best.is_none_or(|(be, _, _)| e > be) {
                    best = Some((e, cx, cy));
                }
            }
            // The prediction (candidate 0) stays unless beaten by min_gain.
            let gain = u128::from(first) * (1000 + u128::from(cfg.min_gain));
            *slot = match best {
                Some((e, x, y)) if u128::from(e) * 1000 > gain => (x, y),
                _ => (px, py),
            };
        }
        let column = (usize::from(c), cols);
        spread_bands(
            &win[..usize::from(bands)],
            (cfg.band, rows),
            column,
            out_vx,
            out_vy,
        );
    }
    Ok(())
}

/// Writes column `c` (of `cols`) of `out_vx`, `out_vy` for `rows` rows
/// from the velocities `win` of bands of `band` rows: band centres at
/// rows b·band + (band − 1)/2, piecewise linear between them (rounded
/// down), constant beyond the outer ones.
#[inline(always)]
fn spread_bands(
    win: &[(i16, i16)],
    (band, rows): (u16, u16),
    (c, cols): (usize, usize),
    out_vx: &mut [i16],
    out_vy: &mut [i16],
) {
    // Centres in half rows: c2(b).
    let band2 = 2 * i64::from(band);
    let c2 = |b: u16| i64::from(b) * band2 + i64::from(band) - 1;
    let last = (win.len() as u16).saturating_sub(1);
    for r in 0..rows {
        let y2 = 2 * i64::from(r);
        let b = ((y2 - c2(0)).max(0) / band2).min(i64::from(last)) as u16;
        let b1 = (b + 1).min(last);
        let (a, z) = (win[usize::from(b)], win[usize::from(b1)]);
        let (c0, c1) = (c2(b), c2(b1));
        let lerp = |a: i16, z: i16| -> i16 {
            if b1 == b || y2 <= c0 {
                a
            } else if y2 >= c1 {
                z
            } else {
                let d = (i64::from(z) - i64::from(a)) * (y2 - c0);
                (i64::from(a) + d.div_euclid(c1 - c0)) as i16
            }
        };
        let i = usize::from(r) * cols + c;
        out_vx[i] = lerp(a.0, z.0);
        out_vy[i] = lerp(a.1, z.1);
    }
}

/// The pixels of one [`refine`] node: band rows `rows.0..rows.1` of a
/// band of `band_rows` rows `width` px wide, words `words.0..words.1`.
struct Node {
    width: u16,
    band_rows: u16,
    rows: (u16, u16),
    words: (usize, usize),
}

/// Adds the counts of band row `r`'s words from `j0` on compensated for
/// `(vx, vy)` to `out` (their pixels, 64 per word), bit-sliced as the
/// plain counts are (`window::add_words`); `at` is `(planes, start, kc,
/// wpr, band_rows)`.
///
/// Each tick's shift is resolved once per call: its source row (empty
/// when the shift leaves the band), the word offset and the bit offset,
/// so a shifted word is two loads and a funnel shift — the same words as
/// [`shifted_word`].
fn add_words_of(
    (planes, start, kc, wpr, band_rows): (&[&[u64]], u32, u32, usize, u16),
    r: u16,
    (vx, vy): (i16, i16),
    j0: usize,
    out: &mut [u8],
) {
    // Each tick's source row, word offset and bit offset (a vector, so
    // only the ticks there are are written: calls come per row, column
    // and level).
    let mut items: heapless::Vec<Source<'_>, 256> = heapless::Vec::new();
    for (p, i) in planes.iter().zip(0i64..) {
        let dt = (i64::from(start) + i - i64::from(kc)) as i32;
        let s = Source::new(p, wpr, band_rows, r, shift(vx, dt), shift(vy, dt));
        if items.push(s).is_err() {
            break;
        }
    }
    for (q, cw) in out.chunks_mut(64).enumerate() {
        crate::window::add_words(&items, |s| s.word(j0 + q), cw);
    }
}

/// One tick's plane as [`shifted_word`] reads it for one band row: the
/// shifted-to row's words (empty outside the band), the whole words and
/// the bits of the x shift.
#[derive(Debug, Clone, Copy)]
struct Source<'p> {
    row: &'p [u64],
    q: isize,
    b: u32,
}

impl<'p> Source<'p> {
    const EMPTY: Source<'static> = Source {
        row: &[],
        q: 0,
        b: 0,
    };

    fn new(plane: &'p [u64], wpr: usize, rows: u16, r: u16, sx: i32, sy: i32) -> Source<'p> {
        Source::at(plane, wpr, rows, r, Shift::new(sx, sy))
    }

    fn at(plane: &'p [u64], wpr: usize, rows: u16, r: u16, s: Shift) -> Source<'p> {
        let rs = i32::from(r) + s.y;
        if rs < 0 || rs >= i32::from(rows) {
            return Source::EMPTY;
        }
        let base = rs as usize * wpr;
        let row = plane.get(base..).unwrap_or(&[]);
        Source {
            row: row.get(..wpr).unwrap_or(row),
            q: s.q,
            b: s.b,
        }
    }

    /// Word `j` of the shifted row (0 beyond the row's ends).
    #[inline(always)]
    fn word(&self, j: usize) -> u64 {
        let q = (j as isize).wrapping_add(self.q);
        // A negative q wraps to a huge index: no word, as beyond the end.
        let lo = self.row.get(q as usize).copied().unwrap_or(0);
        let hi = self
            .row
            .get(q.wrapping_add(1) as usize)
            .copied()
            .unwrap_or(0);
        // (hi << 1) << (63 − b) is hi << (64 − b) for b > 0 and 0 for b = 0.
        (lo >> self.b) | ((hi << 1) << (63 - self.b))
    }
}

/// Whether velocities `a` and `b` shift every plane `dt = dts.0..=dts.1`
/// ticks from the centre by the same whole pixels (the window's two ends
/// first: they differ most).
fn same_path(a: (i16, i16), b: (i16, i16), dts: (i64, i64)) -> bool {
    let at = |dt: i64| {
        let dt = dt.clamp(-65_535, 65_535) as i32;
        shift(a.0, dt) == shift(b.0, dt) && shift(a.1, dt) == shift(b.1, dt)
    };
    if dts.1 < dts.0 {
        return true;
    }
    at(dts.0) && at(dts.1) && (dts.0..=dts.1).all(at)
}

/// A plane's shift `(sx, sy)` split for [`Source`]: rows `y`, whole words
/// `q` and bits `b` of x.
#[derive(Debug, Clone, Copy, Default)]
struct Shift {
    y: i32,
    q: isize,
    b: u32,
}

impl Shift {
    fn new(sx: i32, sy: i32) -> Shift {
        Shift {
            y: sy,
            // Floor division and remainder by 64, as shifts.
            q: (sx >> 6) as isize,
            b: (sx & 63) as u32,
        }
    }
}

/// The per-tick shifts of [`sharpness`], on the caller's stack once per
/// [`refine`] (4 KB on a 64-bit host, 3 KB on a 32-bit MCU).
struct SharpScratch {
    shifts: [Shift; 256],
}

/// Rows of a node [`sharpness`] counts at once: each tick's shift is
/// resolved once per block of rows, not once per row.
const BLOCK_ROWS: usize = 16;

/// [`refine`]'s measure of a candidate: the sum over the node's pixels of
/// the squared counts compensated for `(vx, vy)` — the counts
/// [`add_compensated`] makes, summed as squares straight from the bit
/// planes ([`slices::sum_squares`]) without reading them back into bytes
/// (byte counts would make refine most of a compensated frame's cost).
///
/// Loops run tick by tick over blocks of [`BLOCK_ROWS`] rows of one word
/// column: a tick's source rows are consecutive, so the shift, the rows
/// the band holds and the words the row holds are worked out once per
/// tick and block, and each row's word is two loads and a funnel shift
/// into its own carry-save counter. Hand-written: refine's hot loop.
fn sharpness(
    scratch: &mut SharpScratch,
    span: &Span<'_>,
    kc: u32,
    node: &Node,
    (vx, vy): (i16, i16),
) -> u64 {
    let (planes, start) = (span.planes(), span.start);
    let wpr = crate::plane::words_per_row(node.width);
    let n = planes.len().min(256);
    let shifts = &mut scratch.shifts;
    for (s, i) in shifts.iter_mut().take(n).zip(0i64..) {
        let dt = (i64::from(start) + i - i64::from(kc)) as i32;
        *s = Shift::new(shift(vx, dt), shift(vy, dt));
    }
    let shifts = &shifts[..n];
    let planes = &planes[..n];
    let band_rows = i32::from(node.band_rows);
    let (j0, j1) = (node.words.0, node.words.1.min(wpr));
    let mut e = 0u64;
    let mut r0 = node.rows.0;
    while r0 < node.rows.1 {
        let nr = usize::from((node.rows.1 - r0).min(BLOCK_ROWS as u16));
        for j in j0..j1 {
            // Pixels past the row's end are not pixels.
            let m = slices::low_bits(usize::from(node.width) - 64 * j);
            let mut counts = [Counter::default(); BLOCK_ROWS];
            for (ps, ss) in planes.chunks(15).zip(shifts.chunks(15)) {
                #[cfg(not(target_arch = "x86_64"))]
                let mut acc = [[0u64; 4]; BLOCK_ROWS];
                #[cfg(target_arch = "x86_64")]
                let mut pairs = [[wide::u64x2::ZERO; 4]; BLOCK_ROWS / 2];
                for (plane, s) in ps.iter().zip(ss) {
                    // Block row 0's source row, and the block rows whose
                    // source row lies in the band.
                    let first = i32::from(r0) + s.y;
                    let lo = (-first).clamp(0, nr as i32) as usize;
                    let hi = (band_rows - first).clamp(0, nr as i32) as usize;
                    // The two source words of word j (in the row or not).
                    let q = (j as isize).wrapping_add(s.q);
                    let at = |k: isize| (0..wpr as isize).contains(&k).then_some(k as usize);
                    let (wl, wh) = (at(q), at(q.wrapping_add(1)));
                    let base = (first + lo as i32).max(0) as usize * wpr;
                    #[cfg(target_arch = "x86_64")]
                    row_pairs_of(plane, (wpr, m), (wl, wh), s.b, (base, lo, hi), &mut pairs);
                    #[cfg(not(target_arch = "x86_64"))]
                    {
                        let mut base = base;
                        for a in &mut acc[lo..hi] {
                            slices::csa(a, shifted(plane, base, (wl, wh), s.b, m));
                            base += wpr;
                        }
                    }
                }
                #[cfg(not(target_arch = "x86_64"))]
                for (c, a) in counts.iter_mut().zip(&acc[..nr]) {
                    slices::add_nibble(c, *a);
                }
                #[cfg(target_arch = "x86_64")]
                for (p, a) in pairs.iter().enumerate().take(nr.div_ceil(2)) {
                    let a = a.map(|v| v.to_array());
                    for (l, c) in counts.iter_mut().skip(2 * p).take(2).enumerate() {
                        slices::add_nibble(c, [a[0][l], a[1][l], a[2][l], a[3][l]]);
                    }
                }
            }
            e += counts[..nr].iter().map(slices::sum_squares).sum::<u64>();
        }
        r0 += nr as u16;
    }
    e
}

/// The row word at `base` of `plane` whose source words are `wl` and `wh`
/// (`None`: outside the row, read as 0), funnel-shifted right by `b` and
/// masked by `m`.
#[inline(always)]
fn shifted(
    plane: &[u64],
    base: usize,
    (wl, wh): (Option<usize>, Option<usize>),
    b: u32,
    m: u64,
) -> u64 {
    let word = |k: Option<usize>| k.and_then(|k| plane.get(base + k)).copied().unwrap_or(0);
    // (hi << 1) << (63 − b) is hi << (64 − b) for b > 0 and 0 for b = 0.
    ((word(wl) >> b) | ((word(wh) << 1) << (63 - b))) & m
}

/// [`sharpness`]'s block rows `lo..hi` of one plane on x86-64, from
/// block row `lo`'s first word at `base`: two rows per SSE2 operation
/// (rows 2p and 2p + 1 are pair p's lanes), a first row that is odd, or a
/// last that is even, alone in its lane; source words `wl`, `wh` of a row
/// (`None`: outside it) funnel-shifted by `b` and masked by `m`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn row_pairs_of(
    plane: &[u64],
    (wpr, m): (usize, u64),
    (wl, wh): (Option<usize>, Option<usize>),
    b: u32,
    (mut base, lo, hi): (usize, usize, usize),
    pairs: &mut [[wide::u64x2; 4]; BLOCK_ROWS / 2],
) {
    let one = |base: usize| shifted(plane, base, (wl, wh), b, m);
    let mut i = lo;
    if i % 2 == 1 && i < hi {
        slices::csa(&mut pairs[i / 2], wide::u64x2::new([0, one(base)]));
        base += wpr;
        i += 1;
    }
    let two = 2 * ((hi - i) / 2);
    if let Some(rows) = plane.get(base..base + two * wpr) {
        // Every row in the plane: one slice, no check
        // per word, and a source word outside the row
        // (`None`) is not read.
        let m = wide::u64x2::splat(m);
        let pairs = &mut pairs[i / 2..];
        match (wl, wh) {
            (Some(l), Some(r)) => row_pairs::<true, true>(rows, wpr, (l, r), b, m, pairs),
            (Some(l), None) => row_pairs::<true, false>(rows, wpr, (l, 0), b, m, pairs),
            (None, Some(r)) => row_pairs::<false, true>(rows, wpr, (0, r), b, m, pairs),
            (None, None) => {}
        }
        base += two * wpr;
        i += two;
    }
    while i + 1 < hi {
        let w = wide::u64x2::new([one(base), one(base + wpr)]);
        slices::csa(&mut pairs[i / 2], w);
        base += 2 * wpr;
        i += 2;
    }
    if i < hi {
        slices::csa(&mut pairs[i / 2], wide::u64x2::new([one(base), 0]));
    }
}

/// [`sharpness`]'s row pairs on x86: `rows` holds whole rows of `wpr`
/// words, two per entry of `pairs`; each row's word is its words `l` (when
/// `L`) and `r` (when `R`) funnel-shifted by `b`, masked by `m`, and added
/// to the pair's carry-save counter. A word not read counts as zero.
#[cfg(target_arch = "x86_64")]
fn row_pairs<const L: bool, const R: bool>(
    rows: &[u64],
    wpr: usize,
    (l, r): (usize, usize),
    b: u32,
    m: wide::u64x2,
    pairs: &mut [[wide::u64x2; 4]],
) {
    for (two, pair) in rows.chunks_exact(2 * wpr).zip(pairs) {
        let (x, y) = two.split_at(wpr);
        let at = |row: &[u64], k: usize| row.get(k).copied().unwrap_or(0);
        let mut w = wide::u64x2::ZERO;
        if L {
            w |= wide::u64x2::new([at(x, l), at(y, l)]) >> b;
        }
        if R {
            // (hi << 1) << (63 − b) is hi << (64 − b) for b > 0 and 0 for
            // b = 0.
            w |= (wide::u64x2::new([at(x, r), at(y, r)]) << 1) << (63 - b);
        }
        slices::csa(pair, w & m);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::PlaneView;

    /// `sharpness` is the sum of the squared counts `add_compensated` makes, for
    /// shifts either way, widths that end mid-word and rows that leave
    /// the band; `same_path` holds exactly when every plane's shift agrees.
    #[test]
    fn sharpness_is_the_sum_of_squared_compensated_counts() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for (w, h) in [(8u16, 9u16), (72, 12), (130, 4)] {
            let (wu, hu) = (usize::from(w), usize::from(h));
            let planes: Vec<Vec<u8>> = (0..70)
                .map(|_| (0..wu * hu / 8).map(|_| (next() & 0x2a) as u8).collect())
                .collect();
            let mut words = vec![0u64; History::words_needed(w, h, 128).unwrap()];
            let mut hist = History::new(&mut words, w, h, 0, h, 128).unwrap();
            for p in &planes {
                hist.push(&PlaneView::new(p, w, h).unwrap()).unwrap();
            }
            let kc = 33;
            let span = Span::new(&hist, Window::in_history(&hist, kc, 64));
            let mut sharp = SharpScratch {
                shifts: [Shift::default(); 256],
            };
            for v in [
                (0i16, 0i16),
                (4800, -640),
                (-11200, 1440),
                (80, 32),
                (-20800, -4800),
            ] {
                for rows in [(0u16, h), (1, 3)] {
                    let mut want = 0u64;
                    for r in rows.0..rows.1 {
                        let mut row = vec![0u8; wu];
                        let (vx, vy) = ([v.0; 16], [v.1; 16]);
                        let m = Motion::rows(&vx, &vy);
                        let (a, e) = (span.start, kc);
                        add_compensated(span.planes(), a, e, w, h, (r, r + 1), &m, &mut row);
                        want += row.iter().map(|&c| u64::from(c).pow(2)).sum::<u64>();
                    }
                    let node = Node {
                        width: w,
                        band_rows: h,
                        rows,
                        words: (0, crate::plane::words_per_row(w)),
                    };
                    let got = sharpness(&mut sharp, &span, kc, &node, v);
                    assert_eq!(got, want, "{w}x{h} v {v:?} rows {rows:?}");
                }
            }
        }
        let dts = (-32, 31);
        let shifts_of = |v: (i16, i16)| -> Vec<(i32, i32)> {
            (dts.0..=dts.1)
                .map(|dt| (shift(v.0, dt as i32), shift(v.1, dt as i32)))
                .collect()
        };
        for a in [(400i16, 0i16), (5120, 48), (-1024, -144)] {
            for d in (-192i16..=192).step_by(8) {
                for b in [(a.0 + d, a.1), (a.0, a.1 + d)] {
                    assert_eq!(
                        same_path(a, b, dts),
                        shifts_of(a) == shifts_of(b),
                        "{a:?} {b:?}"
                    );
                }
            }
        }
        assert!(same_path((400, 0), (400, 16), dts));
        assert!(!same_path((400, 0), (640, 0), dts));
    }
}
