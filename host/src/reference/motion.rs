//! The `f64` reference of the core's motion compensation
//! (`spiv_core::motion`), written from its definition: a pixel's
//! compensated count is the number of ticks of the window with a spike at
//! the place the predicted motion puts it, `round(v·Δt)` px away (halves
//! up); refinement tries the documented candidates in their documented
//! order and keeps the first with the largest sum of squared counts.
//!
//! **Tolerance**: none. Counts, energies and velocities are integers, and
//! every `f64` here is exact or rounded away from any integer it is
//! floored to, so `host/tests/reference_parity.rs` holds the core's refined
//! velocities identical to these for every row.

use super::SpikeVolume;

/// A velocity grid as `spiv_core::motion::Motion` defines it: `cols`
/// velocities per band row, 1/4096 px per tick, entry `r·cols + c` for
/// row `r` in tile column `c`; pixel column `x` is in tile column
/// `min(⌊x / tile⌋, cols − 1)`.
#[derive(Debug, Clone, Copy)]
pub struct Grid<'a> {
    /// x velocities, `rows × cols`.
    pub vx: &'a [i16],
    /// y velocities (down), `rows × cols`.
    pub vy: &'a [i16],
    /// Tile columns (≥ 1).
    pub cols: usize,
    /// Tile width, px.
    pub tile: usize,
}

impl<'a> Grid<'a> {
    /// One velocity per row.
    pub fn rows(vx: &'a [i16], vy: &'a [i16]) -> Grid<'a> {
        Grid {
            vx,
            vy,
            cols: 1,
            tile: usize::MAX,
        }
    }

    /// The tile column of pixel column `x`.
    pub fn col(&self, x: usize) -> usize {
        (x / self.tile.max(1)).min(self.cols.max(1) - 1)
    }

    /// The velocity at row `r`, pixel column `x` (0 past the arrays).
    pub fn at(&self, r: usize, x: usize) -> (i16, i16) {
        let i = r * self.cols.max(1) + self.col(x);
        let get = |a: &[i16]| a.get(i).copied().unwrap_or(0);
        (get(self.vx), get(self.vy))
    }
}

/// `round(v/Q · dt)` (Q = 4096), halves up.
fn shift(v: i16, dt: i64) -> i64 {
    (f64::from(v) / f64::from(spiv_core::motion::Q) * dt as f64 + 0.5).floor() as i64
}

/// Compensated count of pixel (r, c) over the window of `n` ticks centred
/// on `kc`, for a velocity `(vx, vy)` (1/4096 px per tick).
pub fn compensated_count(
    vol: &SpikeVolume,
    kc: u32,
    n: u16,
    (r, c): (usize, usize),
    (vx, vy): (i16, i16),
) -> u32 {
    let (start, len) = vol.window(kc, n);
    (start..start + i64::from(len))
        .filter(|&t| {
            let dt = t - i64::from(kc);
            let (rs, cs) = (r as i64 + shift(vy, dt), c as i64 + shift(vx, dt));
            rs >= 0
                && cs >= 0
                && (rs as usize) < vol.rows
                && (cs as usize) < vol.width
                && vol.spike(t, rs as usize, cs as usize) == 1
        })
        .count() as u32
}

/// Farthest the motion `(vx, vy)` moves a pixel within the window of `n`
/// ticks centred on `kc`, px (largest |x| or |y| shift over its ticks; 0
/// for an empty window).
pub fn travel(vol: &SpikeVolume, kc: u32, n: u16, (vx, vy): (i16, i16)) -> i64 {
    let (start, len) = vol.window(kc, n);
    (start..start + i64::from(len))
        .map(|t| {
            let dt = t - i64::from(kc);
            shift(vx, dt).abs().max(shift(vy, dt).abs())
        })
        .max()
        .unwrap_or(0)
}

/// How many distinct pixels the motion `(vx, vy)` visits over the window
/// of `n` ticks centred on `kc` (1 for an empty window).
pub fn positions(vol: &SpikeVolume, kc: u32, n: u16, (vx, vy): (i16, i16)) -> u32 {
    let (start, len) = vol.window(kc, n);
    let set: std::collections::BTreeSet<(i64, i64)> = (start..start + i64::from(len))
        .map(|t| {
            let dt = t - i64::from(kc);
            (shift(vx, dt), shift(vy, dt))
        })
        .collect();
    set.len().max(1) as u32
}

/// The candidates around `(vx, vy)`: the prediction; scaled by
/// 1 ± 2 %·k (k = 1..=rel, + before −); offset by ±3k/256 px/tick in x,
/// then in y (k = 1..=abs); each component clamped to `i16`.
pub fn candidates(vx: i16, vy: i16, rel: u8, abs: u8) -> Vec<(i16, i16)> {
    let clamp = |v: f64| v.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
    // ±3k/256 px per tick, in the velocities' 1/4096 px per tick.
    let offset = |k: i32| 3.0 * f64::from(k) / 256.0 * 4096.0;
    let mut out = vec![(vx, vy)];
    for k in 1..=i32::from(rel) {
        for sign in [1, -1] {
            let s = |v: i16| clamp((f64::from(v) * f64::from(100 + 2 * sign * k) / 100.0).floor());
            out.push((s(vx), s(vy)));
        }
    }
    for k in 1..=i32::from(abs) {
        for sign in [1, -1] {
            out.push((clamp(f64::from(vx) + offset(sign * k)), vy));
        }
    }
    for k in 1..=i32::from(abs) {
        for sign in [1, -1] {
            out.push((vx, clamp(f64::from(vy) + offset(sign * k))));
        }
    }
    out
}

/// Refined velocities, laid out as `pred`'s: for each node — a band of
/// `band` rows in one tile column — the first candidate around the
/// prediction at the band's middle row with the largest sum of squared
/// compensated counts over the node's pixels and `window` ticks, if that
/// sum exceeds the prediction's by more than `min_gain`/1000 (else the
/// prediction); per column, rows between band centres linear (floored),
/// constant beyond the outer centres.
pub fn refine(
    vol: &SpikeVolume,
    kc: u32,
    pred: Grid<'_>,
    band: usize,
    window: u16,
    (rel, abs, min_gain): (u8, u8, u16),
) -> (Vec<i16>, Vec<i16>) {
    let rows = vol.rows;
    let cols = pred.cols.max(1);
    let mut vx = vec![0i16; rows * cols];
    let mut vy = vec![0i16; rows * cols];
    for col in 0..cols {
        // The node's pixel columns.
        let xs: Vec<usize> = (0..vol.width).filter(|&x| pred.col(x) == col).collect();
        let mut winners = Vec::new();
        for r0 in (0..rows).step_by(band) {
            let r1 = (r0 + band).min(rows);
            let mid = r0 + (r1 - r0) / 2;
            let prediction = xs.first().map_or_else(
                || {
                    let i = mid * cols + col;
                    let get = |a: &[i16]| a.get(i).copied().unwrap_or(0);
                    (get(pred.vx), get(pred.vy))
                },
                |&x| pred.at(mid, x),
            );
            let mut best: Option<(f64, (i16, i16))> = None;
            let mut pred_e = 0.0;
            for (i, cand) in candidates(prediction.0, prediction.1, rel, abs)
                .into_iter()
                .enumerate()
            {
                let mut e = 0.0;
                for r in r0..r1 {
                    for &c in &xs {
                        let n = f64::from(compensated_count(vol, kc, window, (r, c), cand));
                        e += n * n;
                    }
                }
                if i == 0 {
                    pred_e = e;
                }
                if best.is_none_or(|(be, _)| e > be) {
                    best = Some((e, cand));
                }
            }
            winners.push(match best {
                Some((e, v)) if e * 1000.0 > pred_e * (1000.0 + f64::from(min_gain)) => v,
                _ => prediction,
            });
        }
        let centre = |b: usize| (b * band) as f64 + (band as f64 - 1.0) / 2.0;
        let last = winners.len() - 1;
        for r in 0..rows {
            let y = r as f64;
            let b = (((y - centre(0)) / band as f64).floor().max(0.0) as usize).min(last);
            let b1 = (b + 1).min(last);
            let lerp = |a: i16, z: i16| -> i16 {
                if b1 == b || y <= centre(b) {
                    a
                } else if y >= centre(b1) {
                    z
                } else {
                    let d = (f64::from(z) - f64::from(a)) * (y - centre(b)) / band as f64;
                    (f64::from(a) + d.floor()) as i16
                }
            };
            vx[r * cols + col] = lerp(winners[b].0, winners[b1].0);
            vy[r * cols + col] = lerp(winners[b].1, winners[b1].1);
        }
    }
    (vx, vy)
}
