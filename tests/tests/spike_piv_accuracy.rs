//! Spike-frame PIV against the simulator's ground truth, end to end on the
//! path `spiv run` ships: simulated camera → sidecar firmware (fixed-point
//! core, dwell caps, lossless wire) → receiver → PIV → the paper's row
//! profile metrics (docs/spec.md §7).
//!
//! Bounds: the mean over two seeds of the glare-row and other-row RMAE of
//! the adaptive frames, about 1.5× what they measure today (README), so a
//! regression of the adaptive frames (streaks, lost rows, wrong gray
//! levels) fails them; and in the glare band the spike camera must beat
//! the saturated frame camera by at least 1.5×, which is the paper's point.

use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_host::pipeline::{run, FrameKind, Job};

/// Mean glare and other-row RMAE of (frame camera, TFP, adaptive,
/// motion-compensated, motion-compensated with the wide baseline) over
/// seeds.
fn measure(kind: SceneKind, seeds: &[u64], dwell_cap: Option<f64>) -> [[f64; 2]; 5] {
    let mut sum = [[0.0; 2]; 5];
    for &seed in seeds {
        let mut job = Job::new(SceneParams::new(kind), seed);
        // `spiv run`'s default is `--dwell-cap 8`.
        job.dwell_cap = dwell_cap;
        let o = run(&job, |_| {}).expect("the pipeline runs");
        assert_eq!(
            o.measured.iter().map(|m| m.source).collect::<Vec<_>>(),
            FrameKind::ALL
        );
        // The link is lossless: what PIV saw is what the core made.
        assert_eq!(o.link.lost_frames, 0);
        assert!(o.link.bit_exact);
        for (s, m) in sum.iter_mut().zip(&o.measured) {
            assert!(m.glare.rows >= 2 && m.rest.rows >= 10, "{m:?}");
            s[0] += m.glare.rmae / seeds.len() as f64;
            s[1] += m.rest.rmae / seeds.len() as f64;
        }
    }
    sum
}

/// Asserts the adaptive frames' bounds and the glare advantage, and that
/// motion compensation measures the other rows within `mc_rest_max` and
/// better than half the adaptive frames' error there (switched off, the
/// compensated row is the adaptive one and fails), and the glare rows
/// within `mc_glare_max` and better than the adaptive frames, and the
/// other rows within 2× of the frame camera (without the
/// plain-count floor of the compensated particle test, glare particles
/// drown in false ones and the linear profile's glare rows measured 0.16 /
/// 0.28).
///
/// The wide baseline (`FrameKind::McWide`, `spiv_host::baseline`) must
/// measure the glare rows within `wide_glare_max` and no worse than the
/// pair alone, and the other rows no worse than the pair alone and within
/// 1.25× of the frame camera (measured: at or below it).
fn check(
    kind: SceneKind,
    glare_max: f64,
    rest_max: f64,
    (mc_rest_max, mc_glare_max): (f64, f64),
    wide_glare_max: f64,
) {
    let [frame, tfp, adaptive, mc, wide] = measure(kind, &[1, 2], Some(8.0));
    eprintln!(
        "{kind:?}: frame {frame:.4?} tfp {tfp:.4?} adaptive {adaptive:.4?} mc {mc:.4?} wide {wide:.4?}"
    );
    assert!(
        mc[0] <= mc_glare_max && mc[0] < adaptive[0],
        "{kind:?}: motion-compensated glare RMAE {:.3} (bound {mc_glare_max}, adaptive {:.3})",
        mc[0],
        adaptive[0]
    );
    assert!(
        mc[1] <= mc_rest_max && mc[1] < 0.5 * adaptive[1],
        "{kind:?}: motion-compensated other-row RMAE {:.3} (bound {mc_rest_max}, adaptive {:.3})",
        mc[1],
        adaptive[1]
    );
    // Beyond the glare the compensated spike frames measure within 2x of
    // the frame camera (10x worse without compensation).
    assert!(
        mc[1] <= 2.0 * frame[1],
        "{kind:?}: mc other rows {:.4} against the frame camera's {:.4}",
        mc[1],
        frame[1]
    );
    assert!(
        mc[0] < frame[0],
        "{kind:?}: mc glare {:.3} against the frame camera's {:.3}",
        mc[0],
        frame[0]
    );
    assert!(
        wide[0] <= wide_glare_max && wide[0] <= mc[0],
        "{kind:?}: wide-baseline glare RMAE {:.4} (bound {wide_glare_max}, the pair alone {:.4})",
        wide[0],
        mc[0]
    );
    assert!(
        wide[1] <= mc[1] && wide[1] <= 1.25 * frame[1],
        "{kind:?}: wide-baseline other rows {:.4} (the pair alone {:.4}, frame camera {:.4})",
        wide[1],
        mc[1],
        frame[1]
    );
    assert!(
        adaptive[0] <= glare_max,
        "{kind:?}: adaptive glare RMAE {:.3} > {glare_max}",
        adaptive[0]
    );
    assert!(
        adaptive[1] <= rest_max,
        "{kind:?}: adaptive other-row RMAE {:.3} > {rest_max}",
        adaptive[1]
    );
    assert!(
        frame[0] >= 1.5 * adaptive[0],
        "{kind:?}: the frame camera's glare RMAE {:.3} is not 1.5x the spike camera's {:.3}",
        frame[0],
        adaptive[0]
    );
    // The frame camera is saturated in the glare and fine elsewhere.
    assert!(frame[0] > 0.3 && frame[1] < 0.02, "{kind:?}: {frame:?}");
}

#[test]
fn paper_linear_spike_frames_measure_the_flow() {
    // Seeds 1, 2 (glare / other rows): adaptive 0.199 / 0.031, the
    // compensated pair 0.0098 / 0.0014, the wide baseline 0.0029 / 0.0008
    // (frame camera 0.531 / 0.0020).
    check(SceneKind::PaperLinear, 0.23, 0.05, (0.0045, 0.035), 0.0045);
}

#[test]
fn paper_quadratic_spike_frames_measure_the_flow() {
    // Seeds 1, 2 (glare / other rows): adaptive 0.361 / 0.039, the
    // compensated pair 0.118 / 0.0037, the wide baseline 0.017 / 0.0024
    // (frame camera 0.688 / 0.0038). The pair alone scatters most here:
    // its last round is predicted by the wide field, and its row 26 px
    // above the wall varies twice as much from seed to seed as before that
    // round (mean |error| 0.012 → 0.022 px over ten seeds, its bias within
    // 0.002 px), hence its loose bound of 0.13; the wide bound 0.020 sits
    // just above the 0.017 measured.
    check(SceneKind::PaperQuadratic, 0.45, 0.10, (0.010, 0.13), 0.020);
}

#[test]
fn paper_log_spike_frames_measure_the_flow() {
    // Seeds 1, 2 (glare / other rows): adaptive 0.167 / 0.022, the
    // compensated pair 0.019 / 0.0017, the wide baseline 0.018 / 0.0009
    // (frame camera 0.494 / 0.0012).
    check(SceneKind::PaperLog, 0.40, 0.03, (0.003, 0.10), 0.040);
}

#[test]
fn the_bounds_catch_streaked_adaptive_frames() {
    // The paper's one window limit everywhere (no dwell cap): fast
    // particles streak and PIV loses the fast rows. The same bounds as
    // above must reject these frames, or they would not guard anything.
    let [_, _, adaptive, _, _] = measure(SceneKind::PaperLinear, &[1], None);
    assert!(
        adaptive[0] > 0.23 || adaptive[1] > 0.05,
        "streaked frames passed the bounds: {adaptive:?}"
    );
}
