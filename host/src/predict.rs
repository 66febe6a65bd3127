//! The prediction that motion-compensated frames need (beyond the paper):
//! a PIV field becomes a velocity per stored row, or per stored row and
//! 64-px tile column where the flow varies along x ([`motion_grid`]), the
//! core refines it from the spikes by contrast maximisation
//! (`spiv_core::motion::refine`), and the core counts each particle along
//! its path (`spiv_core::reconstruct_compensated`).

use spiv_core::buffers::WorkspaceBuf;
use spiv_core::label::LabelStats;
use spiv_core::motion::{refine, Motion, Refine};
use spiv_core::{reconstruct_compensated, Params, WorkspaceSizes};
use spiv_formats::Vector;

use crate::reconstruct::Planes;
use crate::Error;

/// Rounds of prediction for a motion-compensated pair made offline (`spiv
/// run`, `spiv flow`, the benches): the TFP pair at the same ticks predicts
/// the first, the compensated pair's own field each later one. The TFP
/// field is biased where glare hides the particles nearest the wall and
/// noisy elsewhere; the compensated field is neither, so later rounds
/// compensate with a better velocity. The compensated pair's frames share
/// most of their spikes, and a shared spike moves between them by exactly
/// the predicted displacement, so PIV of the pair reads about half way
/// between the prediction and the truth (`host/examples/hybrid_probe.rs`,
/// `PSCALE`): each round halves what is left of the prediction's error
/// (`docs/results.md#the-constants-and-what-chose-them`). Live, the previous pair's field plays the later
/// rounds' part.
pub const ROUNDS: usize = 4;

/// Velocities per stored row, 1/4096 px per tick: `(vx, vy)`.
pub type RowVelocities = (Vec<i16>, Vec<i16>);

/// Whether a PIV field can predict motion-compensated frames: the one rule
/// for a usable field ([`crate::piv::usable`]; below it, compensating a
/// guess would move static light into "particles").
pub fn predicts(field: &[Vector]) -> bool {
    crate::piv::usable(field)
}

/// A displacement of `px_per_pair` over `dt` ticks as a core velocity,
/// 1/4096 px per tick, rounded and clamped to `i16` (0 when not finite).
fn q12(px_per_pair: f64, dt: f64) -> i16 {
    let v = px_per_pair / dt.max(1e-9) * f64::from(spiv_core::motion::Q);
    if v.is_finite() {
        v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    } else {
        0
    }
}

/// The velocity of every stored row of an `h`-row frame from an upright
/// `field` measured over `dt` ticks: the mean of each grid row's measured
/// vectors, linear between grid rows and constant beyond the outer ones;
/// rows stored bottom-up when `flip` (then y velocities change sign).
/// All zero when no vector was measured.
pub fn row_velocities(field: &[Vector], h: u16, flip: bool, dt: f64) -> RowVelocities {
    let mut rows: Vec<(f64, f64, f64, usize)> = Vec::new(); // y, Σu, Σv, n
    for v in field.iter().filter(|v| v.state.is_measured()) {
        match rows.iter_mut().find(|r| (r.0 - v.y).abs() < 1e-9) {
            Some(r) => {
                r.1 += v.u;
                r.2 += v.v;
                r.3 += 1;
            }
            None => rows.push((v.y, v.u, v.v, 1)),
        }
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let means: Vec<(f64, f64, f64)> = rows
        .iter()
        .map(|r| (r.0, r.1 / r.3 as f64, r.2 / r.3 as f64))
        .collect();
    let at = |y: f64| -> (f64, f64) {
        let (Some(first), Some(last)) = (means.first(), means.last()) else {
            return (0.0, 0.0);
        };
        if y <= first.0 {
            return (first.1, first.2);
        }
        if y >= last.0 {
            return (last.1, last.2);
        }
        let k = means.partition_point(|m| m.0 < y).max(1);
        let (a, b) = (means[k - 1], means[k]);
        let t = (y - a.0) / (b.0 - a.0);
        (a.1 + t * (b.1 - a.1), a.2 + t * (b.2 - a.2))
    };
    let q = |px_per_pair: f64| q12(px_per_pair, dt);
    let n = usize::from(h);
    let (mut vx, mut vy) = (vec![0i16; n], vec![0i16; n]);
    for r in 0..n {
        let y = if flip { (n - 1 - r) as f64 } else { r as f64 };
        let (u, v) = at(y);
        vx[r] = q(u);
        vy[r] = q(if flip { -v } else { v });
    }
    (vx, vy)
}

/// The tile of [`motion_grid`]'s columns, px: one packed word, the finest
/// tile the core's motion takes ([`spiv_core::motion::Motion`]).
pub const GRID_TILE: u16 = 64;

/// Which motion models [`motion_grid`] may choose from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum MotionModel {
    /// The simpler model the field supports: per row, or per row and
    /// 64-px tile column.
    #[default]
    Auto,
    /// One velocity per row (a shear flow's model).
    Rows,
}

/// How much lower [`motion_grid`]'s grid must make the Bayesian
/// information criterion to be chosen: 10, "very strong" evidence on
/// Kass & Raftery's scale. Over the paper's three shear profiles (3 seeds,
/// 45 predictions of `spiv bench paper`) the grid's criterion came within
/// 0.5 of the row model's once, by noise; on the vortex array through the
/// loop it is 130–350 lower.
pub const GRID_EVIDENCE: f64 = 10.0;

/// A prediction for the core: velocities per stored row and tile column,
/// 1/4096 px per tick (`rows × cols`, row-major; `cols = 1`: per row).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Prediction {
    /// x velocities.
    pub vx: Vec<i16>,
    /// y velocities (stored rows, down).
    pub vy: Vec<i16>,
    /// Tile columns (≥ 1).
    pub cols: u16,
    /// Tile width, px (a multiple of 64).
    pub tile: u16,
}

impl Prediction {
    /// One velocity per row.
    pub fn rows((vx, vy): RowVelocities) -> Prediction {
        Prediction {
            vx,
            vy,
            cols: 1,
            tile: spiv_core::motion::ROW_TILE,
        }
    }

    /// The core's view of it.
    pub fn motion(&self) -> Motion<'_> {
        // Built by this module with one column or a positive multiple of
        // 64 and at most MAX_COLS columns; per row otherwise.
        Motion::grid(&self.vx, &self.vy, self.cols, self.tile)
            .unwrap_or_else(|_| Motion::rows(&self.vx, &self.vy))
    }

    /// The control that tells a sidecar this prediction.
    pub fn control(self) -> spiv_core::wire::control::Control {
        spiv_core::wire::control::Control {
            motion: (self.vx, self.vy),
            cols: self.cols,
            tile: self.tile,
            ..Default::default()
        }
    }
}

/// The prediction of a `w × h` frame from an upright `field` measured over
/// `dt` ticks, with the simpler of two models that the field supports:
/// one velocity per row ([`row_velocities`]: a shear flow's model), or
/// one per row and [`GRID_TILE`]-px column (each column's mean per grid
/// row, linear between grid rows, constant beyond; a column without
/// vectors takes the row model). The grid is chosen when it lowers the
/// Bayesian information criterion of the measured vectors' u and v,
/// `n·ln(RSS/n) + k·ln n` with `k` the model's means: a flow that varies
/// along x (a vortex, a jet, turbulence) lowers the residual much more
/// than its extra means cost; a shear flow's column means differ by noise
/// only, so the grid must win by [`GRID_EVIDENCE`]. Rows stored bottom-up
/// when `flip`, as [`row_velocities`].
/// [`MotionModel::Rows`] takes the row model whatever the field.
pub fn motion_grid(
    field: &[Vector],
    (w, h): (u16, u16),
    flip: bool,
    dt: f64,
    model: MotionModel,
) -> Prediction {
    let rows = Prediction::rows(row_velocities(field, h, flip, dt));
    let cols = usize::from(w).div_ceil(usize::from(GRID_TILE)).max(1);
    let measured: Vec<&Vector> = field.iter().filter(|v| v.state.is_measured()).collect();
    if model == MotionModel::Rows || cols < 2 || measured.len() < 4 {
        return rows;
    }
    let col_of = |x: f64| ((x.max(0.0) / f64::from(GRID_TILE)) as usize).min(cols - 1);
    // Group sums per grid row (by y) and per (grid row, column).
    let mut ys: Vec<f64> = measured.iter().map(|v| v.y).collect();
    ys.sort_by(f64::total_cmp);
    ys.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let row_of = |y: f64| ys.partition_point(|&g| g < y - 1e-9);
    let mut row_sum = vec![(0.0, 0.0, 0usize); ys.len()];
    let mut cell_sum = vec![(0.0, 0.0, 0usize); ys.len() * cols];
    for v in &measured {
        let (i, c) = (row_of(v.y), col_of(v.x));
        for s in [&mut row_sum[i], &mut cell_sum[i * cols + c]] {
            s.0 += v.u;
            s.1 += v.v;
            s.2 += 1;
        }
    }
    let mean = |s: &(f64, f64, usize)| (s.0 / s.2.max(1) as f64, s.1 / s.2.max(1) as f64);
    let (mut rss_row, mut rss_grid) = (0.0, 0.0);
    for v in &measured {
        let (i, c) = (row_of(v.y), col_of(v.x));
        let (a, b) = mean(&row_sum[i]);
        rss_row += (v.u - a).powi(2) + (v.v - b).powi(2);
        let (a, b) = mean(&cell_sum[i * cols + c]);
        rss_grid += (v.u - a).powi(2) + (v.v - b).powi(2);
    }
    let n = 2.0 * measured.len() as f64;
    let k_row = 2.0 * row_sum.iter().filter(|s| s.2 > 0).count() as f64;
    let k_grid = 2.0 * cell_sum.iter().filter(|s| s.2 > 0).count() as f64;
    // A floor on the residual keeps a noiseless field's criterion finite.
    let bic = |rss: f64, k: f64| n * (rss.max(1e-12) / n).ln() + k * n.ln();
    if bic(rss_grid, k_grid) > bic(rss_row, k_row) - GRID_EVIDENCE {
        return rows;
    }
    let q = |px_per_pair: f64| q12(px_per_pair, dt);
    let hn = usize::from(h);
    let (mut vx, mut vy) = (vec![0i16; hn * cols], vec![0i16; hn * cols]);
    for c in 0..cols {
        // This column's means by grid row.
        let means: Vec<(f64, f64, f64)> = (0..ys.len())
            .filter(|&i| cell_sum[i * cols + c].2 > 0)
            .map(|i| {
                let (a, b) = mean(&cell_sum[i * cols + c]);
                (ys[i], a, b)
            })
            .collect();
        for r in 0..hn {
            let e = r * cols + c;
            let Some(first) = means.first() else {
                (vx[e], vy[e]) = (rows.vx[r], rows.vy[r]);
                continue;
            };
            let y = if flip { (hn - 1 - r) as f64 } else { r as f64 };
            let last = means[means.len() - 1];
            let (u, v) = if y <= first.0 {
                (first.1, first.2)
            } else if y >= last.0 {
                (last.1, last.2)
            } else {
                let k = means.partition_point(|m| m.0 < y).max(1);
                let (a, b) = (means[k - 1], means[k]);
                let t = (y - a.0) / (b.0 - a.0);
                (a.1 + t * (b.1 - a.1), a.2 + t * (b.2 - a.2))
            };
            vx[e] = q(u);
            vy[e] = q(if flip { -v } else { v });
        }
    }
    Prediction {
        vx,
        vy,
        cols: cols as u16,
        tile: GRID_TILE,
    }
}

/// The motion-compensated adaptive frame at `k` (upright, cropped) from
/// `planes`, with the prediction `pred` refined first when `refine_cfg` is
/// given (per node of a band of rows in a tile column, from the spikes
/// around `k`). Returns the frame and the velocities it used.
pub fn compensated_frame(
    planes: &Planes,
    k: u64,
    core: &Params,
    pred: &Prediction,
    refine_cfg: Option<Refine>,
) -> Result<(Vec<u16>, Prediction, LabelStats), Error> {
    let (w, h) = (planes.width, planes.height);
    let mut ring = planes.ring(k, core.n_max)?;
    let tick = ring.tick;
    let hist = ring.history()?;
    let mut used = pred.clone();
    if let Some(cfg) = refine_cfg {
        refine(
            &hist,
            tick,
            &pred.motion(),
            &cfg,
            &mut used.vx,
            &mut used.vy,
        )?;
    }
    let rows = spiv_core::state::strip_rows(w, h, core.margin);
    let mut ws = WorkspaceBuf::new(WorkspaceSizes::for_motion(w, rows));
    let mut out = vec![0u16; usize::from(w) * usize::from(h)];
    let stats = reconstruct_compensated(
        &hist,
        tick,
        core,
        &mut ws.workspace()?,
        (0, h),
        &used.motion(),
        &mut out,
    )?;
    Ok((planes.output(&out), used, stats.labels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use spiv_formats::State;

    /// A frame whose particles cannot all be labelled says so: 512×512
    /// isolated hot pixels (every other pixel of every other row, firing
    /// every tick) need 65,536 labels against the labeller's 32,766.
    #[test]
    fn a_frame_reports_what_the_full_tables_left_as_background() {
        let (w, h) = (512u16, 512u16);
        let mut plane = vec![0u8; usize::from(w) * usize::from(h) / 8];
        for r in (0..usize::from(h)).step_by(2) {
            for c in (0..usize::from(w)).step_by(2) {
                let i = r * usize::from(w) + c;
                plane[i / 8] |= 1 << (i % 8);
            }
        }
        let planes = Planes::simulated(w, h, plane.repeat(160));
        let still = Prediction::rows((vec![0i16; usize::from(h)], vec![0i16; usize::from(h)]));
        let (frame, _, lost) =
            compensated_frame(&planes, 80, &Params::default(), &still, None).unwrap();
        assert_eq!(frame.len(), usize::from(w) * usize::from(h));
        assert!(
            lost.dropped_pixels + lost.overflow_regions > 10_000,
            "{lost:?}"
        );
        let mut loss = crate::flow::LabelLoss::default();
        assert!(loss.is_none());
        loss.add(&lost);
        loss.add(&lost);
        assert_eq!(loss.pixels, 2 * lost.dropped_pixels);
        assert_eq!(loss.regions, 2 * lost.overflow_regions);
    }

    fn v(y: f64, u: f64, vv: f64, state: State) -> Vector {
        Vector {
            x: 0.0,
            y,
            u,
            v: vv,
            state,
        }
    }

    /// A field on a 16-px grid over `w × h` px from `f(x, y)` (px per
    /// pair) plus a deterministic ±`noise` px.
    fn field_of(w: usize, h: usize, noise: f64, f: impl Fn(f64, f64) -> (f64, f64)) -> Vec<Vector> {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let mut out = Vec::new();
        for y in (8..h).step_by(16) {
            for x in (8..w).step_by(16) {
                let (u, vv) = f(x as f64, y as f64);
                out.push(Vector {
                    x: x as f64,
                    y: y as f64,
                    u: u + noise * rnd(),
                    v: vv + noise * rnd(),
                    state: State::Valid,
                });
            }
        }
        out
    }

    /// A shear flow (u by row only, PIV noise 0.1 px) is predicted per
    /// row; a vortex is predicted per 64-px column, each column's value
    /// the mean of its vectors, and its compensation is closer to the
    /// vortex than the row model's.
    #[test]
    fn the_grid_is_chosen_where_the_flow_varies_along_x() {
        let (w, h, dt) = (256usize, 128usize, 10.0);
        let shear = field_of(w, h, 0.1, |_, y| (y / 20.0, 0.0));
        let p = motion_grid(&shear, (w as u16, h as u16), false, dt, MotionModel::Auto);
        assert_eq!((p.cols, p.vx.len()), (1, h));
        assert_eq!(
            (p.vx.clone(), p.vy.clone()),
            row_velocities(&shear, h as u16, false, dt)
        );
        // Solid-body rotation about the centre: u = −ω·dy, v = ω·dx.
        let om = 0.05;
        let spin = |x: f64, y: f64| (-om * (y - 64.0), om * (x - 128.0));
        let vortex = field_of(w, h, 0.1, spin);
        let p = motion_grid(&vortex, (w as u16, h as u16), false, dt, MotionModel::Auto);
        assert_eq!((p.cols, p.tile, p.vx.len()), (4, 64, 4 * h));
        let q = f64::from(spiv_core::motion::Q) / dt;
        for (c, xc) in [(0usize, 32.0), (3, 224.0)] {
            // Row 40 (between grid rows 40 ± 0): v of the column's centre.
            let want = spin(xc, 40.0).1 * q;
            let got = f64::from(p.vy[40 * 4 + c]);
            assert!((got - want).abs() < 0.05 * want.abs(), "{c}: {got} {want}");
        }
        let rows = row_velocities(&vortex, h as u16, false, dt);
        let err = |vy: &[i16], cols: usize| -> f64 {
            (0..h)
                .flat_map(|r| (0..w).map(move |x| (r, x)))
                .map(|(r, x)| {
                    let c = (x / 64).min(cols - 1);
                    (f64::from(vy[r * cols + c]) - spin(x as f64, r as f64).1 * q).abs()
                })
                .sum::<f64>()
        };
        assert!(err(&p.vy, 4) < 0.3 * err(&rows.1, 1));
        // Nothing measured: the row model's zeros.
        let none: Vec<Vector> = vortex
            .iter()
            .map(|x| Vector {
                state: State::Invalid,
                ..*x
            })
            .collect();
        let z = motion_grid(&none, (w as u16, h as u16), false, dt, MotionModel::Auto);
        assert_eq!(z.cols, 1);
        assert!(z.vx.iter().chain(&z.vy).all(|&a| a == 0));
    }

    #[test]
    fn row_velocities_interpolate_flip_and_skip_holes() {
        let field = [
            v(10.0, 2.0, 1.0, State::Valid),
            v(10.0, 4.0, 1.0, State::Replaced),
            v(20.0, 6.0, 1.0, State::Valid),
            v(20.0, 99.0, 9.0, State::Invalid),
        ];
        // Upright storage: row 10 → mean u 3 px/pair over 10 ticks = 0.3 px/tick.
        let (vx, vy) = row_velocities(&field, 30, false, 10.0);
        assert_eq!(
            vx[10],
            (0.3f64 * f64::from(spiv_core::motion::Q)).round() as i16
        );
        assert_eq!(
            vx[15],
            (0.45f64 * f64::from(spiv_core::motion::Q)).round() as i16
        );
        assert_eq!((vx[0], vx[29]), (vx[10], vx[20]));
        assert_eq!(
            vy[12],
            (0.1f64 * f64::from(spiv_core::motion::Q)).round() as i16
        );
        // Bottom-up storage: stored row 29 − y, y velocities negated.
        let (fx, fy) = row_velocities(&field, 30, true, 10.0);
        assert_eq!((fx[19], fy[19]), (vx[10], -vy[10]));
        // Nothing measured: no motion.
        let (zx, zy) = row_velocities(&field[3..], 30, true, 10.0);
        assert!(zx.iter().chain(&zy).all(|&x| x == 0));
    }
}
