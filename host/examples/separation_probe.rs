//! Would a longer baseline measure the slow glare rows better? The core's
//! motion-compensated frames (`spiv run`'s prediction: the TFP pair's PIV,
//! refined by the core, a second round from the compensated pair's own
//! PIV) at ticks `s·dt` apart centred on the pair's centre, PIV with the
//! compensated pairs' settings, vectors divided by `s`; glare-row and
//! other-row RMAE and the rows nearest the wall, mean over seeds 1..=N.
//!
//! `s = 0` is the per-vector choice of `spiv_host::baseline` written out
//! (the 4·dt pair where the narrow field changes by at most `LIMIT` px,
//! default 12, across a window over 4·dt; `DEBUG=1` prints the choices
//! near the wall). Measured (30 seeds, glare rows linear / quadratic /
//! log): s = 1: 0.020 / 0.081 / 0.053; s = 2: 0.008 / 0.035 / 0.058;
//! s = 4: 0.0053 / 0.032 / 0.076; s = 8: 0.0053 / 0.052 / 0.171; chosen
//! per vector (LIMIT 10): 0.0084 / 0.032 / 0.053.
//!
//! `cargo run --release -p spiv-host --example separation_probe -- [linear|quadratic|log] [SEEDS] [WIDTH]`
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_host::metrics::{region_error, row_profile};
use spiv_host::piv::{piv, piv_predicted, to_f32, Field, Settings};
use spiv_host::predict::{compensated_frame, row_velocities};

const SEPARATIONS: [u32; 5] = [1, 2, 4, 0, 8];

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let profile = args.get(1).map_or("quadratic", String::as_str);
    let kind =
        SceneKind::from_name(&format!("paper-{profile}")).unwrap_or(SceneKind::PaperQuadratic);
    let seeds: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(4);
    let width: Option<u16> = args.get(3).and_then(|s| s.parse().ok());
    let mut acc = vec![[0.0f64; 2]; SEPARATIONS.len()];
    let mut bias = std::collections::BTreeMap::<(usize, i64), (f64, f64, usize, f64)>::new();
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
        let limit: f64 = std::env::var("LIMIT")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(12.0);
        let mut wide4: Option<Vec<spiv_formats::vectors::Vector>> = None;
        let mut wide4field: Option<Field> = None;
        let mut narrow1field: Option<Field> = None;
        let mut narrow1: Option<Vec<spiv_formats::vectors::Vector>> = None;
        for (i, &s) in SEPARATIONS.iter().enumerate() {
            if s == 0 {
                // Per vector: the 4·dt pair where the narrow field varies
                // by at most `limit`/4 px across a window, else the narrow.
                let nf = wide4field.clone().unwrap_or_else(|| narrow.clone());
                let n1f = narrow1field.clone().unwrap_or_else(|| narrow.clone());
                let (ny, nx) = nf.u.dim();
                let mut f = narrow1.clone().unwrap_or_default();
                let wide = wide4.clone().unwrap_or_default();
                for r in 0..ny {
                    for c in 0..nx {
                        // The change of the narrow field across a window:
                        // differences of 5-vector means across the
                        // neighbouring rows and columns.
                        let g = |a: &ndarray::Array2<f64>| -> f64 {
                            let (r0, r1) = (r.saturating_sub(1), (r + 1).min(ny - 1));
                            let (c0, c1) = (c.saturating_sub(1), (c + 1).min(nx - 1));
                            let row = |rr: usize| {
                                let (a0, a1) = (c.saturating_sub(2), (c + 2).min(nx - 1));
                                (a0..=a1).map(|cc| a[[rr, cc]]).sum::<f64>() / (a1 - a0 + 1) as f64
                            };
                            let col = |cc: usize| {
                                let (a0, a1) = (r.saturating_sub(2), (r + 2).min(ny - 1));
                                (a0..=a1).map(|rr| a[[rr, cc]]).sum::<f64>() / (a1 - a0 + 1) as f64
                            };
                            let dy = (row(r1) - row(r0)).abs() * 2.0 / (r1 - r0).max(1) as f64;
                            let dx = (col(c1) - col(c0)).abs() * 2.0 / (c1 - c0).max(1) as f64;
                            dy.max(dx)
                        };
                        let _ = &nf;
                        let du = g(&n1f.u).max(g(&n1f.v));
                        let i = r * nx + c;
                        if 4.0 * du <= limit && wide[i].state != spiv_formats::State::Invalid {
                            f[i] = wide[i];
                            if std::env::var("DEBUG").is_ok() && r + 3 >= ny {
                                eprintln!("wide at row {r} col {c}: du {du:.3}");
                            }
                        }
                    }
                }
                let pts: Vec<(f64, f64)> = f.iter().map(|v| (v.x, v.y)).collect();
                let truth = sim.scene.truth_vectors(&pts, fdt);
                let rows = row_profile(&f, &truth, f64::from(h));
                acc[i][0] += region_error(&rows, |y| y < 50.0).rmae / seeds as f64;
                acc[i][1] += region_error(&rows, |y| y >= 50.0).rmae / seeds as f64;
                continue;
            }
            let k0 = ka - (s - 1) * dt / 2;
            let k1 = k0 + s * dt;
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
            if s == 4 {
                wide4 = Some(f.clone());
            }
            if s == 1 {
                narrow1 = Some(f.clone());
            }
            let pts: Vec<(f64, f64)> = f.iter().map(|v| (v.x, v.y)).collect();
            let truth = sim.scene.truth_vectors(&pts, fdt);
            let rows = row_profile(&f, &truth, f64::from(h));
            acc[i][0] += region_error(&rows, |y| y < 50.0).rmae / seeds as f64;
            acc[i][1] += region_error(&rows, |y| y >= 50.0).rmae / seeds as f64;
            for r in rows.iter().filter(|r| r.y_wall < 90.0) {
                let e = bias.entry((i, r.y_wall.round() as i64)).or_default();
                let err = r.measured.unwrap_or(0.0) - r.truth;
                e.0 += err;
                e.1 += r.truth;
                e.2 += 1;
                e.3 += err.abs();
            }
        }
    }
    for (i, s) in SEPARATIONS.iter().enumerate() {
        println!("s = {s}: glare {:.4} other {:.4}", acc[i][0], acc[i][1]);
    }
    for ((i, y), (b, t, n, a)) in bias {
        let (t, b, a) = (t / n as f64, b / n as f64, a / n as f64);
        println!(
            "s = {} y_wall {y}: truth {t:.3} mean error {b:+.4} mean |error| {a:.4}",
            SEPARATIONS[i]
        );
    }
}
