//! Motion compensation (beyond the paper; issue 14): counting a pixel's
//! spikes along a particle's predicted path instead of at a fixed place,
//! and refining the prediction from the spikes themselves.
//!
//! A velocity `v` per band row (x right, y down in stored rows, Q8: 1/256 px
//! per tick) moves plane `t` of a window centred on `k_c` by
//! `s = round(v·(t − k_c))` before its spikes are added: the compensated
//! count of pixel (r, c) over a window is the number of ticks `t` with a
//! spike at (r + s_y, c + s_x). A particle moving at `v` then piles its
//! spikes up where it was at `k_c` instead of smearing them along its path,
//! so long windows gather light without blur. Rows or columns shifted in
//! from outside the band count nothing. Shifts are whole pixels: a packed
//! row moves by a funnel shift of two words (a barrel shifter on an FPGA).
//!
//! [`refine`] corrects a predicted velocity by contrast maximisation: per
//! band of rows it tries velocities around the prediction (scaled by
//! ±[`RELATIVE_STEP`]·k and offset by ±[`ABSOLUTE_STEP`]·k in x and in y)
//! and keeps the one whose compensated counts are sharpest (largest sum of
//! squared counts; a blurred particle spreads the same spikes over more
//! pixels, which lowers it) — if it beats the prediction by more than
//! [`Refine::min_gain`]. With a PIV prediction a few per cent off, the
//! refined velocity is within about 1–4 % on the paper's scenes
//! (`host/examples/mc_probe.rs`).
//!
//! Memory: none beyond the caller's scratch and a 2 KiB table of band
//! winners on the stack. Cost of [`refine`]: (1 + 2·rel + 4·abs) windows
//! of compensated counts per band row.
//!
//! Rounding rule, the one definition both this module and the host's `f64`
//! reference use: `round(v·Δt/256) = ⌊(v·Δt + 128)/256⌋` (halves up).

use crate::error::{Error, ParamError};
use crate::history::History;
use crate::window::{Span, Window};

/// Velocities are in 1/`Q` px per tick.
pub const Q: i32 = 256;

/// Relative step of [`refine`]'s scaled candidates, in 1/[`REL_DEN`]
/// (2 %).
pub const RELATIVE_STEP: i32 = 2;
/// Denominator of [`RELATIVE_STEP`].
pub const REL_DEN: i32 = 100;
/// Most bands [`refine`] handles (its winners live on the stack: 2 KiB).
pub const MAX_BANDS: usize = 512;
/// Step of [`refine`]'s offset candidates, Q8 (3/256 ≈ 0.012 px/tick).
pub const ABSOLUTE_STEP: i32 = 3;

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

/// A predicted velocity per band row.
#[derive(Debug, Clone, Copy)]
pub struct Motion<'a> {
    /// x velocity of each band row, 1/256 px per tick (missing rows: 0).
    pub vx: &'a [i16],
    /// y velocity of each band row (stored rows, down), 1/256 px per tick.
    pub vy: &'a [i16],
}

impl Motion<'_> {
    /// The velocity of band row `r`.
    #[inline]
    pub fn at(&self, r: u16) -> (i16, i16) {
        let r = usize::from(r);
        (
            self.vx.get(r).copied().unwrap_or(0),
            self.vy.get(r).copied().unwrap_or(0),
        )
    }
}

/// The shift of a plane `dt` ticks from the centre for velocity `v` (Q8),
/// px: `⌊(v·dt + 128)/256⌋`.
#[inline]
pub fn shift(v: i16, dt: i32) -> i32 {
    (i32::from(v) * dt + Q / 2).div_euclid(Q)
}

/// Farthest a particle at velocity `v` (Q8) travels from where it is at
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

/// Distinct pixels a particle at velocity `v` (Q8) visits within the ticks
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
/// (0 outside the band).
#[inline]
pub fn shifted_word(
    plane: &[u64],
    wpr: usize,
    rows: u16,
    r: u16,
    j: usize,
    sx: i32,
    sy: i32,
) -> u64 {
    let rs = i32::from(r) + sy;
    if rs < 0 || rs >= i32::from(rows) {
        return 0;
    }
    let base = rs as usize * wpr;
    let word = |q: i64| -> u64 {
        if q < 0 || q >= wpr as i64 {
            0
        } else {
            plane.get(base + q as usize).copied().unwrap_or(0)
        }
    };
    let o = 64 * j as i64 + i64::from(sx);
    let (q, b) = (o.div_euclid(64), o.rem_euclid(64) as u32);
    if b == 0 {
        word(q)
    } else {
        (word(q) >> b) | (word(q + 1) << (64 - b))
    }
}

/// Adds the motion-compensated counts of band rows `rows.0..rows.1` over
/// `planes` (consecutive ticks from `start`, each the band's
/// `band_rows × words` words) for a frame centred on `kc` to `counts`
/// (row-major, `width` per row, first row = `rows.0`), with `motion`'s
/// velocity of each row. The caller keeps every count ≤ 255 (at most 255
/// ticks in all); bytes wrap otherwise.
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
    for (r, crow) in (rows.0..rows.1).zip(counts.chunks_exact_mut(w)) {
        add_row(planes, start, kc, width, band_rows, r, motion.at(r), crow);
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
/// for each band of `cfg.band` rows, every [`candidate`] around the
/// velocity of the band's middle row is tried over a window of
/// `cfg.window` ticks, and the one with the largest sum of squared
/// compensated counts over the band wins (the earliest on a tie, so the
/// prediction when nothing is sharper). The winners are written to
/// `out_vx`, `out_vy` (one per band row), piecewise linear between band
/// centres (rounded down) and constant beyond the outer ones. `scratch`
/// holds `cfg.band × width` bytes. Kept out of line (one call per frame)
/// so instruction counters can attribute its cost (`firmware-sim/cost.sh`).
#[inline(never)]
pub fn refine(
    hist: &History<'_>,
    kc: u32,
    motion: &Motion<'_>,
    cfg: &Refine,
    scratch: &mut [u8],
    out_vx: &mut [i16],
    out_vy: &mut [i16],
) -> Result<(), Error> {
    if cfg.band == 0 || cfg.window == 0 || cfg.window > 255 {
        return Err(Error::BadParam(ParamError::Window));
    }
    if !hist.holds(kc) {
        return Err(Error::TickUnavailable);
    }
    let (width, rows) = (hist.width(), hist.rows());
    let w = usize::from(width);
    let need = usize::from(cfg.band) * w;
    crate::window::check_len(scratch.len(), need)?;
    crate::window::check_len(out_vx.len(), usize::from(rows))?;
    crate::window::check_len(out_vy.len(), usize::from(rows))?;
    let bands = rows.div_ceil(cfg.band);
    if usize::from(bands) > MAX_BANDS {
        return Err(Error::BufferTooSmall {
            needed: usize::from(bands),
            got: MAX_BANDS,
        });
    }
    let span = Span::new(hist, Window::in_history(hist, kc, cfg.window));
    let mut win = [(0i16, 0i16); MAX_BANDS];
    for (b, slot) in (0..bands).zip(win.iter_mut()) {
        let r0 = b * cfg.band;
        let r1 = r0.saturating_add(cfg.band).min(rows);
        let (px, py) = motion.at(r0 + (r1 - r0) / 2);
        let counts = &mut scratch[..usize::from(r1 - r0) * w];
        let mut best: Option<(u64, i16, i16)> = None;
        let mut first = 0u64;
        let mut n = 0;
        while let Some((cx, cy)) = candidate(cfg, px, py, n) {
            n += 1;
            counts.fill(0);
            for (i, r) in (r0..r1).enumerate() {
                let row = &mut counts[i * w..(i + 1) * w];
                add_row(span.planes(), span.start, kc, width, rows, r, (cx, cy), row);
            }
            let e: u64 = counts.iter().map(|&c| u64::from(c) * u64::from(c)).sum();
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
    // Band centres at rows b·band + (band − 1)/2 (in half rows: c2(b));
    // linear between them, constant beyond.
    let band2 = 2 * i64::from(cfg.band);
    let c2 = |b: u16| i64::from(b) * band2 + i64::from(cfg.band) - 1;
    let last = bands.saturating_sub(1);
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
        out_vx[usize::from(r)] = lerp(a.0, z.0);
        out_vy[usize::from(r)] = lerp(a.1, z.1);
    }
    Ok(())
}

/// Adds the counts of band row `r` compensated for `(vx, vy)` to `row`,
/// bit-sliced as the plain counts are (`window::add_words`).
#[allow(clippy::too_many_arguments)]
fn add_row(
    planes: &[&[u64]],
    start: u32,
    kc: u32,
    width: u16,
    band_rows: u16,
    r: u16,
    (vx, vy): (i16, i16),
    row: &mut [u8],
) {
    let wpr = crate::plane::words_per_row(width);
    // Each tick's plane with its shift.
    let mut items: [(&[u64], i32, i32); 256] = [(&[], 0, 0); 256];
    let n = planes.len().min(items.len());
    for ((it, p), i) in items.iter_mut().zip(planes).zip(0i64..) {
        let dt = (i64::from(start) + i - i64::from(kc)) as i32;
        *it = (p, shift(vx, dt), shift(vy, dt));
    }
    for (j, cw) in row.chunks_mut(64).enumerate() {
        crate::window::add_words(
            &items[..n],
            |(p, sx, sy)| shifted_word(p, wpr, band_rows, r, j, sx, sy),
            cw,
        );
    }
}
