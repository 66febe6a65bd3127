//! Would a longer baseline measure the slow glare rows better? The core's
//! motion-compensated frames (`spiv run`'s prediction: the TFP pair's PIV,
//! refined by the core, a second round from the compensated pair's own
//! PIV) at ticks `s·dt` apart centred on the pair's centre, PIV with the
//! compensated pairs' settings, vectors divided by `s`; glare-row and
//! other-row RMAE and the rows nearest the wall, mean over seeds 1..=N.
//!
//! `s = 0` is the per-vector choice of `spiv_host::baseline` between the
//! s = 1 and s = 4 fields (LIMIT 10 in the numbers below is its
//! `MAX_CHANGE`). Measured (30 seeds, glare rows linear / quadratic /
//! log): s = 1: 0.020 / 0.081 / 0.053; s = 2: 0.008 / 0.035 / 0.058;
//! s = 4: 0.0053 / 0.032 / 0.076; s = 8: 0.0053 / 0.052 / 0.171; chosen
//! per vector (LIMIT 10): 0.0084 / 0.032 / 0.053.
//!
//! `cargo run --release -p spiv-host --example separation_probe -- [linear|quadratic|log] [SEEDS] [WIDTH]`
mod common;

use spiv_firmware_sim::scene::SceneParams;
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_host::metrics::{region_error, row_profile};
use spiv_host::piv::{piv, piv_predicted, to_f32, Field, Settings};
use spiv_host::predict::{compensated_frame, row_velocities};

const SEPARATIONS: [u32; 5] = [1, 2, 4, 0, 8];

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = common::profile(args.get(1));
    let seeds: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(4);
    let width: Option<u16> = args.get(3).and_then(|s| s.parse().ok());
    let mut acc = vec![[0.0f64; 2]; SEPARATIONS.len()];
    let mut near = common::WallRows::default();
    for seed in 1..=seeds {
        let mut p = SceneParams::new(kind);
        if let Some(w) = width {
            p.width = w;
        }
        let dt = p.pair_dt;
        let mut req = Request::new(p.clone(), seed);
        let smax = *SEPARATIONS.iter().max().unwrap_or(&1);
        req.ticks = Some(smax * dt + 2 * 64 + 2);
        let _ = smax;
        let (data, sim) = simulate_planes(&req).expect("sim");
        let (w, h) = (p.width, p.height);
        let (wu, hu) = (usize::from(w), usize::from(h));
        let [ka, kb] = sim.meta.capture.pair;
        let planes = spiv_host::reconstruct::Planes::simulated(w, h, data.clone());
        let core = spiv_core::Params::default();
        let tfp = |k: u32| {
            spiv_host::reconstruct::frame_from_planes(
                &planes,
                u64::from(k),
                spiv_core::Method::Tfp,
                8,
                &spiv_core::Params::default(),
            )
            .expect("tfp")
            .data
        };
        let ft = piv(
            &to_f32(&tfp(ka), wu, hu),
            &to_f32(&tfp(kb), wu, hu),
            None,
            &Settings::for_spike_frames(),
        )
        .expect("piv")
        .vectors();
        let fdt = f64::from(dt);
        let mut pred = row_velocities(&ft, h, true, fdt);
        let refine = Some(spiv_core::motion::Refine::default());
        let ms = Settings::for_compensated_frames();
        let (a, _, _) = compensated_frame(&planes, u64::from(ka), &core, &pred, refine).expect("a");
        let (b, _, _) = compensated_frame(&planes, u64::from(kb), &core, &pred, refine).expect("b");
        let narrow: Field = piv(&to_f32(&a, wu, hu), &to_f32(&b, wu, hu), None, &ms).expect("piv");
        pred = row_velocities(&narrow.vectors(), h, true, fdt);
        let use_init = std::env::var("INIT").map_or(true, |v| v != "0");
        let mut wide4field: Option<Field> = None;
        let mut narrow1field: Option<Field> = None;
        for (i, &s) in SEPARATIONS.iter().enumerate() {
            if s == 0 {
                // Per vector, as `spiv run`: `spiv_host::baseline`.
                let (Some(n1), Some(w4)) = (&narrow1field, &wide4field) else {
                    continue;
                };
                let f = spiv_host::baseline::combine(n1, w4, 4);
                let pts: Vec<(f64, f64)> = f.iter().map(|v| (v.x, v.y)).collect();
                let truth = sim.scene.truth_vectors(&pts, fdt);
                let rows = row_profile(&f, &truth, f64::from(h));
                acc[i][0] += region_error(&rows, |y| y < 50.0).rmae / seeds as f64;
                acc[i][1] += region_error(&rows, |y| y >= 50.0).rmae / seeds as f64;
                continue;
            }
            let Some((k0, k1)) = spiv_host::baseline::ticks(ka, dt, s) else {
                continue;
            };
            // WIDE_NMAX: the wide frames' window limit (default 128).
            let wn: u16 = std::env::var("WIDE_NMAX")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(128);
            let wcore = if s > 1 {
                spiv_core::Params { n_max: wn, ..core }
            } else {
                core
            };
            let (a, _, _) =
                compensated_frame(&planes, u64::from(k0), &wcore, &pred, refine).expect("a");
            let (b, _, _) =
                compensated_frame(&planes, u64::from(k1), &wcore, &pred, refine).expect("b");
            let mut init = narrow.clone();
            init.u.mapv_inplace(|u| u * f64::from(s));
            init.v.mapv_inplace(|v| v * f64::from(s));
            let field = piv_predicted(
                &to_f32(&a, wu, hu),
                &to_f32(&b, wu, hu),
                None,
                &ms,
                (use_init && s > 1).then_some(&init),
            )
            .expect("piv");
            if s == 4 {
                wide4field = Some(field.clone());
            }
            if s == 1 {
                narrow1field = Some(field.clone());
            }
            let mut f = field.vectors();
            for v in &mut f {
                v.u /= f64::from(s);
                v.v /= f64::from(s);
            }
            let pts: Vec<(f64, f64)> = f.iter().map(|v| (v.x, v.y)).collect();
            let truth = sim.scene.truth_vectors(&pts, fdt);
            let rows = row_profile(&f, &truth, f64::from(h));
            acc[i][0] += region_error(&rows, |y| y < 50.0).rmae / seeds as f64;
            acc[i][1] += region_error(&rows, |y| y >= 50.0).rmae / seeds as f64;
            near.add(i, &rows);
        }
    }
    for (i, s) in SEPARATIONS.iter().enumerate() {
        println!("s = {s}: glare {:.4} other {:.4}", acc[i][0], acc[i][1]);
    }
    let names: Vec<String> = SEPARATIONS.iter().map(|s| format!("s = {s}")).collect();
    near.print(&names);
}
