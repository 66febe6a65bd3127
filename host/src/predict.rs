//! The prediction that motion-compensated frames need (beyond the paper):
//! a PIV field becomes a velocity per stored row, the core
//! refines it from the spikes by contrast maximisation
//! (`spiv_core::motion::refine`), and the core counts each particle along
//! its path (`spiv_core::reconstruct_compensated`).

use spiv_core::buffers::WorkspaceBuf;
use spiv_core::label::LabelStats;
use spiv_core::motion::{refine, Motion, Refine};
use spiv_core::{reconstruct_compensated, Params, WorkspaceSizes};
use spiv_formats::Vector;

use crate::reconstruct::{Planes, ReconstructError};

/// Rounds of prediction for a motion-compensated pair made offline (`spiv
/// run`, `spiv flow`, the benches): the TFP pair at the same ticks predicts
/// the first, the compensated pair's own field each later one. The TFP
/// field is biased where glare hides the particles nearest the wall and
/// noisy elsewhere; the compensated field is neither, so later rounds
/// compensate with a better velocity. The compensated pair's frames share
/// most of their spikes, and a shared spike moves between them by exactly
/// the predicted displacement, so PIV of the pair reads about half way
/// between the prediction and the truth (`host/examples/hybrid_probe.rs`,
/// `PSCALE`): each round halves what is left of the prediction's error.
/// Measured (`spiv bench paper --seeds 30`, velocities in 1/4096 px/tick,
/// glare rows of the wide baseline, linear / quadratic / log): two rounds
/// 0.007 / 0.032 / 0.045, four 0.007 / 0.028 / 0.032, six or eight no
/// better beyond the seeds' spread. Live, the previous pair's field plays
/// the later rounds' part.
pub const ROUNDS: usize = 4;

/// Velocities per stored row, 1/4096 px per tick: `(vx, vy)`.
pub type RowVelocities = (Vec<i16>, Vec<i16>);

/// Whether a PIV field can predict motion-compensated frames: the one rule
/// for a usable field ([`crate::piv::usable`]; below it, compensating a
/// guess would move static light into "particles").
pub fn predicts(field: &[Vector]) -> bool {
    crate::piv::usable(field)
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
    let q = |px_per_pair: f64| -> i16 {
        let v = px_per_pair / dt.max(1e-9) * f64::from(spiv_core::motion::Q);
        if v.is_finite() {
            v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
        } else {
            0
        }
    };
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

/// The motion-compensated adaptive frame at `k` (upright, cropped) from
/// `planes`, with the prediction `pred` refined first when `refine_cfg` is
/// given (per band of rows, from the spikes around `k`). Returns the frame
/// and the velocities it used.
pub fn compensated_frame(
    planes: &Planes,
    k: u64,
    core: &Params,
    pred: &RowVelocities,
    refine_cfg: Option<Refine>,
) -> Result<(Vec<u16>, RowVelocities, LabelStats), ReconstructError> {
    let (w, h) = (planes.width, planes.height);
    let mut ring = planes.ring(k, core.n_max)?;
    let tick = ring.tick;
    let hist = ring.history()?;
    let mut used = pred.clone();
    if let Some(cfg) = refine_cfg {
        let m = Motion {
            vx: &pred.0,
            vy: &pred.1,
        };
        refine(&hist, tick, &m, &cfg, &mut used.0, &mut used.1)?;
    }
    let rows = spiv_core::state::strip_rows(w, h, core.margin);
    let mut ws = WorkspaceBuf::new(WorkspaceSizes::for_motion(w, rows));
    let mut out = vec![0u16; usize::from(w) * usize::from(h)];
    let m = Motion {
        vx: &used.0,
        vy: &used.1,
    };
    let stats = reconstruct_compensated(
        &hist,
        tick,
        core,
        &mut ws.workspace()?,
        (0, h),
        &m,
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
        let still = (vec![0i16; usize::from(h)], vec![0i16; usize::from(h)]);
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
