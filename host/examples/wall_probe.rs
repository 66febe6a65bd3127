//! How well does this PIV measure a wall-bounded profile on ideal images?
//! Noise-free particle images of a paper profile (no glare, no sensor,
//! the scene's light at the pair's two ticks), optionally blind within
//! BLIND px of the wall (no particle shows there, as in the glare band of
//! a spike camera whose pixels sit at its rate limit), through `spiv
//! piv`'s engine with the compensated pairs' settings (or the spike
//! frames', `spike`). Prints the glare-row and other-row RMAE (the mean
//! over seeds 1..=N, as `spiv bench paper`) and the mean error of the
//! rows nearest the wall.
//!
//! Measured (quadratic, 10 seeds, 400 px): glare RMAE 0.034 with the
//! compensated pairs' settings (mean error +0.019 / +0.003 px at 26 / 42
//! px above the wall), 0.038 blind below 18 px, 0.084 with the spike
//! frames' three passes; the linear profile 0.012 with those. That is the
//! engine's own floor on these rows: the paper's 0.028 leaves a spike
//! camera almost nothing.
//!
//! `SEP=s` puts the second image `s` pair separations after the first (the
//! wide baseline) and divides the vectors by `s`. Measured in stop 34
//! (quadratic, 10 seeds): the bottom row's +0.019 px is the same at s = 1,
//! 2 and 4 — a bias of the window over a curved profile next to the
//! grid's edge, not noise. Blind below 18 px with s = 4 the rows read
//! −0.016 / +0.009 px (glare 0.039), the pattern of the spike path's
//! wide baseline (−0.010 / +0.008); the fast rows are lost at s = 4, as
//! this probe starts PIV without a predictor. A predictor filter that keeps
//! quadratics at the grid's edges (the least-squares quadratic through
//! four nodes instead of the line through three) took the blind rows
//! from −0.015 / +0.010 to −0.011 / +0.007 here (30 seeds, s = 1). It is
//! the wide pair's stencil since (`piv::smooth::Edge`, `baseline::measure`):
//! `spiv bench paper --seeds 30` 0.026 → 0.020; in the pair's own PIV,
//! which predicts the loop, it made `spiv flow`'s glare rows drift.
//!
//! `cargo run --release -p spiv-host --example wall_probe -- [linear|quadratic|log] [SEEDS] [WIDTH] [BLIND] [mc|spike]`
use ndarray::Array2;
mod common;

use spiv_firmware_sim::scene::{Scene, SceneParams};
use spiv_host::metrics::{region_error, row_profile};
use spiv_host::piv::{piv, Settings};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // `linear`, `quadratic` (the default) or `log`.
    let kind = common::profile(args.get(1));
    let seeds: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(10);
    let width: u16 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(400);
    let blind: f64 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(0.0);
    let settings = match args.get(5).map(String::as_str) {
        Some("spike") => Settings::for_spike_frames(),
        _ => Settings::for_compensated_frames(),
    };
    // The wide baseline: the second image `SEP` pair separations after
    // the first, vectors divided by `SEP`.
    let sep: u32 = std::env::var("SEP")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1)
        .max(1);
    let mut bias = std::collections::BTreeMap::<i64, (f64, f64, usize)>::new();
    let mut rmae = [0.0f64; 2];
    for seed in 1..=seeds {
        let mut p = SceneParams::new(kind);
        p.glare_peak = 0.0;
        p.width = width;
        let dt = p.pair_dt;
        let (w, h) = (usize::from(p.width), usize::from(p.height));
        let scene = Scene::new(p, seed, 64 + sep * dt + 1);
        let image = |t: u32| {
            let mut light = vec![0f32; w * h];
            scene.render(f64::from(t), &mut light);
            Array2::from_shape_fn((h, w), |(i, j)| {
                let above_wall = h as f64 - 0.5 - i as f64;
                if above_wall < blind {
                    0.0
                } else {
                    1000.0 * light[i * w + j]
                }
            })
        };
        let f = piv(&image(64), &image(64 + sep * dt), None, &settings).expect("piv");
        let mut vs = f.vectors();
        for v in &mut vs {
            v.u /= f64::from(sep);
            v.v /= f64::from(sep);
        }
        let pts: Vec<(f64, f64)> = vs.iter().map(|v| (v.x, v.y)).collect();
        let truth = scene.truth_vectors(&pts, f64::from(dt));
        let rows = row_profile(&vs, &truth, h as f64);
        rmae[0] += region_error(&rows, |y| y < 50.0).rmae / seeds as f64;
        rmae[1] += region_error(&rows, |y| y >= 50.0).rmae / seeds as f64;
        for r in &rows {
            let b = bias.entry(r.y_wall.round() as i64).or_default();
            b.0 += r.measured.unwrap_or(0.0) - r.truth;
            b.1 += r.truth;
            b.2 += 1;
        }
    }
    println!("glare RMAE {:.4} other {:.4}", rmae[0], rmae[1]);
    for (y, (b, t, n)) in bias.iter().take(4) {
        let n = *n as f64;
        println!("y {y}: truth {:.4} mean error {:+.5}", t / n, b / n);
    }
}
