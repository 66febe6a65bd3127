//! What limits spike frames in the glare rows, with the core's
//! segmentation, suppression and adaptive windows taken away: frames
//! counted along each row's path (compensated TFP over 128 ticks, no
//! segmentation), with the scene's true velocity or (`predicted`) with the
//! velocity `spiv run` gives the core (the TFP pair's PIV refined by the
//! core's contrast search, then a second round from the pair's own PIV),
//! as they come and with the static light subtracted exactly (the same
//! seed simulated without particles: the same glare, thresholds and
//! phases, counted the same way). PIV with the compensated pairs'
//! settings; glare-row and other-row RMAE over seeds 1..=N.
//!
//! Measured (10 seeds, glare / other rows; the core's compensated frames
//! in `spiv bench paper`: quadratic 0.063 / 0.003, linear 0.023 / 0.002,
//! log 0.061 / 0.001):
//! - true velocity: quadratic 0.046 / 0.0011 (0.047 with the static light
//!   removed: the PIV's high-pass already takes it), linear 0.010 /
//!   0.0010, log 0.020 / 0.0006; with the sensor reset by subtraction
//!   (`subtract`: no rate plateaus) quadratic 0.036;
//! - predicted velocity: quadratic 0.040 / 0.0021, linear 0.058 / 0.0015,
//!   log 0.123 / 0.0017 — where refine keeps a poor prediction (glare
//!   rows of the fast profiles), one 128-tick window blurs, and the core's
//!   per-region SNR windows are what keep those rows sharp.
//!
//! `cargo run --release -p spiv-host --example oracle_probe -- [linear|quadratic|log] [SEEDS] [zero|subtract] [true|predicted] [WIDTH]`
mod common;

use ndarray::Array2;
use spiv_firmware_sim::scene::SceneParams;
use spiv_firmware_sim::sensor::Reset;
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_host::metrics::{region_error, row_profile};
use spiv_host::piv::{piv, Settings};

/// Window of the compensated counts, ticks.
const N: i64 = 128;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // `linear`, `quadratic` (the default) or `log`.
    let kind = common::profile(args.get(1));
    let seeds: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(10);
    let reset = match args.get(3).map(String::as_str) {
        Some("subtract") => Reset::Subtract,
        _ => Reset::Zero,
    };
    let predicted = args.get(4).map(String::as_str) == Some("predicted");
    let width: Option<u16> = args.get(5).and_then(|s| s.parse().ok());
    let names = ["as they come", "static light removed"];
    let mut rmae = [[0.0f64; 2]; 2];
    let mut near = common::WallRows::default();
    for seed in 1..=seeds {
        let mut p = SceneParams::new(kind);
        if let Some(w) = width {
            p.width = w;
        }
        let mut req = Request::new(p.clone(), seed);
        req.sensor.reset = reset;
        let (data, sim) = simulate_planes(&req).expect("simulates");
        let mut still = req.clone();
        still.scene.particle_peak = 0.0;
        let (data0, _) = simulate_planes(&still).expect("simulates");
        let (w, h) = (usize::from(p.width), usize::from(p.height));
        let [ka, kb] = sim.meta.capture.pair.map(i64::from);
        let truth_vel: Vec<f64> = (0..h)
            .map(|y| sim.scene.truth(&[(0.0, y as f64)], 1.0)[0].2)
            .collect();
        // The TFP pair (8 ticks), its PIV, row velocities: the core's first
        // prediction.
        let tfp = |k: i64| -> Array2<f32> {
            let pb = w.div_ceil(8) * h;
            Array2::from_shape_fn((h, w), |(y, x)| {
                let r = h - 1 - y;
                let idx = r * w + x;
                let mut c = 0u32;
                for t in k - 4..k + 4 {
                    let byte = data[t as usize * pb + idx / 8];
                    c += u32::from((byte >> (idx % 8)) & 1);
                }
                c as f32 * 32.0
            })
        };
        let ft = piv(&tfp(ka), &tfp(kb), None, &Settings::for_spike_frames())
            .expect("piv")
            .vectors();
        let planes = spiv_host::reconstruct::Planes::simulated(w as u16, h as u16, data.clone());
        let core = spiv_core::Params::default();
        let refined = |pred: &spiv_host::predict::RowVelocities, k: i64| -> Vec<f64> {
            let (_, used, _) = spiv_host::predict::compensated_frame(
                &planes,
                k as u64,
                &core,
                pred,
                Some(spiv_core::motion::Refine::default()),
            )
            .expect("frame");
            (0..h)
                .map(|y| f64::from(used.0[h - 1 - y]) / f64::from(spiv_core::motion::Q))
                .collect()
        };
        let use_pred = predicted;
        let dtp = (kb - ka) as f64;
        let (mut va, mut vb) = (truth_vel.clone(), truth_vel.clone());
        if use_pred {
            let pred = spiv_host::predict::row_velocities(&ft, h as u16, true, dtp);
            va = refined(&pred, ka);
            vb = refined(&pred, kb);
            {
                let a = counted(&data, &va, ka, w, h);
                let b = counted(&data, &vb, kb, w, h);
                let f2 = piv(
                    &a.mapv(|v| v as f32),
                    &b.mapv(|v| v as f32),
                    None,
                    &Settings::for_compensated_frames(),
                )
                .expect("piv")
                .vectors();
                let pred = spiv_host::predict::row_velocities(&f2, h as u16, true, dtp);
                va = refined(&pred, ka);
                vb = refined(&pred, kb);
            }
        }
        let vel = va.clone();
        let a = counted(&data, &va, ka, w, h);
        let b = counted(&data, &vb, kb, w, h);
        let a0 = counted(&data0, &vel, ka, w, h);
        let b0 = counted(&data0, &vb, kb, w, h);
        let pairs = [(a.clone(), b.clone()), (&a - &a0, &b - &b0)];
        for (i, ((fa, fb), acc)) in pairs.iter().zip(rmae.iter_mut()).enumerate() {
            let s = Settings::for_compensated_frames();
            let f = piv(&fa.mapv(|v| v as f32), &fb.mapv(|v| v as f32), None, &s).expect("piv");
            let vs = f.vectors();
            let pts: Vec<(f64, f64)> = vs.iter().map(|v| (v.x, v.y)).collect();
            let truth = sim.scene.truth_vectors(&pts, (kb - ka) as f64);
            let rows = row_profile(&vs, &truth, h as f64);
            acc[0] += region_error(&rows, |y| y < 50.0).rmae / seeds as f64;
            acc[1] += region_error(&rows, |y| y >= 50.0).rmae / seeds as f64;
            near.add(i, &rows);
        }
    }
    for (name, r) in names.iter().zip(&rmae) {
        println!("{name:22} glare RMAE {:.4} other {:.4}", r[0], r[1]);
    }
    near.print(&names.map(String::from));
}

/// Spikes per tick counted along each upright row's true path over the
/// `N` ticks centred on `k` (plane t shifted by round(v·(t − k))), ×1000.
fn counted(data: &[u8], vel: &[f64], k: i64, w: usize, h: usize) -> Array2<f64> {
    let pb = w.div_ceil(8) * h;
    Array2::from_shape_fn((h, w), |(y, x)| {
        // Stored rows run bottom-up.
        let r = h - 1 - y;
        let mut c = 0u32;
        for t in k - N / 2..k - N / 2 + N {
            let xs = (x as f64 + vel[y] * (t - k) as f64).round();
            if t < 0 || xs < 0.0 || xs >= w as f64 {
                continue;
            }
            let idx = r * w + xs as usize;
            let byte = data.get(t as usize * pb + idx / 8).copied().unwrap_or(0);
            c += u32::from((byte >> (idx % 8)) & 1);
        }
        1000.0 * f64::from(c) / N as f64
    })
}
