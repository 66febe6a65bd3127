//! The wide baseline (beyond the paper): a spike camera can make
//! a frame at any tick, so slow rows need not be measured over the pair's
//! `dt` alone. A second pair of motion-compensated frames `s·dt` apart,
//! centred on the same tick as the pair, moves each particle `s` times as
//! far while the frames' positional noise stays what it is: where the flow
//! allows it, the displacement per `dt` is measured `s` times more finely.
//! The wide pair's PIV starts from the narrow pair's field times `s` (it
//! deforms the first pass), so large displacements cost no quarter rule.
//!
//! Where the displacement varies steeply within a window (the log
//! profile's wall: 4 px of change across 32 px per `dt`), `s` times that
//! change distorts the particle images between the frames and the wide
//! pair reads high, so each vector keeps the wide measurement only where
//! the narrow field changes by at most [`MAX_CHANGE`] px across a window
//! over the wide baseline.
//!
//! Measured (`host/examples/separation_probe.rs`, the core's compensated
//! frames, 30 seeds, glare-row RMAE linear / quadratic / log): the pair
//! alone 0.020 / 0.081 / 0.053, the 4·dt pair everywhere 0.0053 / 0.032 /
//! 0.076, chosen per vector 0.0084 / 0.032 / 0.053; other rows 0.0020 /
//! 0.0028 / 0.0014 → 0.0010 / 0.0020 / 0.0012.

use ndarray::Array2;
use spiv_formats::vectors::Vector;
use spiv_formats::State;

use crate::piv::smooth::Edge;
use crate::piv::{piv_predicted, Field, PivError, Settings};

/// The wide pair's separation in pair separations (`s`).
pub const SEPARATION: u32 = 4;

/// Rounds in which the combined field of the pair and its wide pair
/// ([`measure`]) predicts both pairs once more, after
/// [`crate::predict::ROUNDS`] rounds of the pair alone. The pair's frames
/// share most of their spikes and read about half way between the
/// prediction and the truth (`crate::predict::ROUNDS`), so a prediction
/// from the wide baseline, finer on the slow rows, leaves less there
/// (`docs/results.md#the-constants-and-what-chose-them`).
pub const ROUNDS: usize = 1;

/// Largest change of the displacement across one window, over the wide
/// baseline, at which a vector keeps the wide measurement, px (a third of
/// the 32-px final window: the linear profile's 7.8 px passes, the log
/// profile's glare rows, 12–14 px, do not).
pub const MAX_CHANGE: f64 = 10.0;

/// The ticks of the wide pair `s·dt` apart centred on the pair `(ka, ka +
/// dt)`: `(k0, k0 + s·dt)` with `k0 = ka − ⌊(s − 1)·dt/2⌋`, or `None` when
/// `k0` would fall before tick 0 or the ticks overflow.
pub fn ticks(ka: u32, dt: u32, s: u32) -> Option<(u32, u32)> {
    let back = s.checked_sub(1)?.checked_mul(dt)? / 2;
    let k0 = ka.checked_sub(back)?;
    Some((k0, k0.checked_add(s.checked_mul(dt)?)?))
}

/// [`ticks`] for a pair at `ka`, when both wide frames' windows (⌊n_max/2⌋
/// ticks before each, as many after) lie within `planes` planes.
pub fn ticks_within(ka: u64, dt: u32, s: u32, n_max: u16, planes: u64) -> Option<(u64, u64)> {
    let (k0, k1) = ticks(u32::try_from(ka).ok()?, dt, s)?;
    let (k0, k1) = (u64::from(k0), u64::from(k1));
    let half = u64::from(n_max / 2);
    (k0 >= half && k1 + half <= planes).then_some((k0, k1))
}

/// How far the wide pair's second frame lies beyond the pair's, ticks
/// (⌈(s − 1)·dt/2⌉; the first frame lies ⌊(s − 1)·dt/2⌋ before the
/// pair's): what a recording must hold besides the pair's own windows.
pub fn reach(dt: u32, s: u32) -> u32 {
    let span = s.saturating_sub(1).saturating_mul(dt);
    span - span / 2
}

/// The field of a compensated pair measured over the wide baseline as
/// well: PIV of the wide pair `s·dt` apart (upright images), its first
/// pass deformed by `narrow` (the pair's own field) times `s`, each vector
/// then chosen by [`combine`] (px per pair).
///
/// The wide pair's predictor filter keeps quadratics at the grid's edges
/// ([`Edge::Quadratic`]) whatever `settings` say: next to a glare band
/// the line's edge bias was most of what the quadratic glare rows
/// measured (`docs/results.md#the-constants-and-what-chose-them`), while the
/// pair's own PIV, which predicts the loop's rounds, keeps the line
/// ([`Edge`]).
pub fn measure(
    narrow: &Field,
    (a, b): (&Array2<f32>, &Array2<f32>),
    s: u32,
    settings: &Settings,
) -> Result<Vec<Vector>, PivError> {
    let wide_settings = Settings {
        edge: Edge::Quadratic,
        ..settings.clone()
    };
    let wide = piv_predicted(a, b, None, &wide_settings, Some(&scaled(narrow, s)))?;
    Ok(combine(narrow, &wide, s))
}

/// The field `f` times `s`: the wide pair's predictor.
pub fn scaled(f: &Field, s: u32) -> Field {
    let mut out = f.clone();
    let s = f64::from(s);
    out.u.mapv_inplace(|u| u * s);
    out.v.mapv_inplace(|v| v * s);
    out
}

/// Each vector of `narrow` (px per pair) replaced by `wide`'s divided by
/// `s` where `wide` measured it and it passed validation (a replaced wide
/// vector is its neighbours' plane, not a measurement: next to a corner a
/// patch of them read 0.84 px per pair where the truth was 0.18 and the
/// pair measured 0.36) and the narrow field changes
/// by at most [`MAX_CHANGE`]/`s` px across a window there. The change is
/// taken over two grid steps (a window at 50 % overlap) between means of
/// up to five neighbours along the other axis, so that one noisy vector
/// does not decide. The two fields must share a grid; otherwise `narrow`
/// is returned as it is.
pub fn combine(narrow: &Field, wide: &Field, s: u32) -> Vec<Vector> {
    let mut out = narrow.vectors();
    if narrow.grid != wide.grid || s == 0 {
        return out;
    }
    let (ny, nx) = narrow.u.dim();
    let sf = f64::from(s);
    let wide_v = wide.vectors();
    for r in 0..ny {
        for c in 0..nx {
            let i = r * nx + c;
            if wide_v[i].state != State::Valid {
                continue;
            }
            let change = change_across(&narrow.u, r, c).max(change_across(&narrow.v, r, c));
            if sf * change <= MAX_CHANGE {
                let w = wide_v[i];
                out[i] = Vector {
                    u: w.u / sf,
                    v: w.v / sf,
                    ..w
                };
            }
        }
    }
    out
}

/// The largest change of `a` across two grid steps around `(r, c)`, along
/// rows and along columns, each between means of up to five neighbours
/// (one-sided differences doubled at the grid's edges).
fn change_across(a: &ndarray::Array2<f64>, r: usize, c: usize) -> f64 {
    let (ny, nx) = a.dim();
    let (r0, r1) = (r.saturating_sub(1), (r + 1).min(ny - 1));
    let (c0, c1) = (c.saturating_sub(1), (c + 1).min(nx - 1));
    let row_mean = |rr: usize| {
        let (a0, a1) = (c.saturating_sub(2), (c + 2).min(nx - 1));
        (a0..=a1).map(|cc| a[[rr, cc]]).sum::<f64>() / (a1 - a0 + 1) as f64
    };
    let col_mean = |cc: usize| {
        let (a0, a1) = (r.saturating_sub(2), (r + 2).min(ny - 1));
        (a0..=a1).map(|rr| a[[rr, cc]]).sum::<f64>() / (a1 - a0 + 1) as f64
    };
    let dy = if r1 > r0 {
        (row_mean(r1) - row_mean(r0)).abs() * 2.0 / (r1 - r0) as f64
    } else {
        0.0
    };
    let dx = if c1 > c0 {
        (col_mean(c1) - col_mean(c0)).abs() * 2.0 / (c1 - c0) as f64
    } else {
        0.0
    };
    dy.max(dx)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::piv::Grid;
    use ndarray::Array2;

    fn field(ny: usize, nx: usize, u: impl Fn(usize, usize) -> f64) -> Field {
        let grid = Grid::new(16 * nx + 16, 16 * ny + 16, 32, 16).expect("grid");
        assert_eq!((grid.ny, grid.nx), (ny, nx));
        Field {
            grid,
            u: Array2::from_shape_fn((ny, nx), |(r, c)| u(r, c)),
            v: Array2::zeros((ny, nx)),
            state: Array2::from_elem((ny, nx), State::Valid),
            peak_ratio: Array2::from_elem((ny, nx), 2.0),
            peak_height: Array2::from_elem((ny, nx), 0.5),
            sigma: Array2::from_elem((ny, nx), (0.1, 0.1)),
        }
    }

    #[test]
    fn wide_ticks_are_centred_on_the_pair() {
        // Pair (64, 77): centre 70.5; 4·13 = 52 apart from 45 to 97
        // (centre 71: ⌊3·13/2⌋ = 19 back).
        assert_eq!(ticks(64, 13, 4), Some((45, 97)));
        assert_eq!(ticks(64, 12, 4), Some((46, 94)));
        assert_eq!(ticks(64, 13, 1), Some((64, 77)));
        assert_eq!(ticks(10, 13, 4), None);
        assert_eq!(ticks(64, 13, 0), None);
        assert_eq!(ticks(u32::MAX - 1, 13, 4), None);
        assert_eq!(reach(13, 4), 97 - 77);
        assert_eq!(reach(13, 1), 0);
        // Windows of 128 ticks: 64 before the first frame, 64 after the
        // second.
        assert_eq!(ticks_within(64, 13, 4, 128, 200), None);
        assert_eq!(ticks_within(84, 13, 4, 128, 182), Some((65, 117)));
        assert_eq!(ticks_within(84, 13, 4, 128, 180), None);
        assert_eq!(
            ticks_within(u64::from(u32::MAX) + 1, 13, 4, 128, u64::MAX),
            None
        );
    }

    #[test]
    fn a_gentle_shear_is_measured_over_the_wide_baseline() {
        // 0.06 px per pair per px: 1.9 px across a window, 7.7 over 4·dt.
        let narrow = field(6, 8, |r, _| 0.06 * 16.0 * r as f64 + 0.013);
        let wide = field(6, 8, |r, _| 4.0 * 0.06 * 16.0 * r as f64 + 0.02);
        let out = combine(&narrow, &wide, 4);
        for v in &out {
            let r = ((v.y - 16.0) / 16.0).round();
            assert!((v.u - (0.06 * 16.0 * r + 0.005)).abs() < 1e-9, "{v:?}");
        }
    }

    #[test]
    fn a_steep_shear_keeps_the_pair() {
        // 4 px across a window per pair: 16 px over 4·dt.
        let narrow = field(6, 8, |r, _| 2.0 * r as f64);
        let wide = field(6, 8, |r, _| 8.0 * r as f64 + 1.0);
        let out = combine(&narrow, &wide, 4);
        assert_eq!(out, narrow.vectors());
    }

    #[test]
    fn an_invalid_or_replaced_wide_vector_keeps_the_pair() {
        let narrow = field(4, 4, |_, _| 0.5);
        let mut wide = field(4, 4, |_, _| 2.4);
        wide.state[[1, 2]] = State::Invalid;
        wide.u[[1, 2]] = 0.0;
        wide.state[[3, 0]] = State::Replaced;
        wide.u[[3, 0]] = 3.4;
        let out = combine(&narrow, &wide, 4);
        assert!((out[4 + 2].u - 0.5).abs() < 1e-12);
        assert!((out[12].u - 0.5).abs() < 1e-12);
        assert!((out[0].u - 0.6).abs() < 1e-12);
    }

    #[test]
    fn fields_on_other_grids_are_not_mixed() {
        let narrow = field(4, 4, |_, _| 0.5);
        let wide = field(4, 5, |_, _| 2.0);
        assert_eq!(combine(&narrow, &wide, 4), narrow.vectors());
    }
}
