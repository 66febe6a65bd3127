//! The experiment behind the motion-compensation design (issue 14): does
//! counting along the predicted path help, and how good must the
//! prediction be? Shifts each stored row of every plane by
//! round(d(y)·(t − k_c)) — d the displacement per tick, from the truth or
//! from PIV — and runs the unmodified core (adaptive, n_max 128) on the
//! shifted planes. Valid for the paper's scenes only: their flow is u(y) and
//! their glare varies in y only, so shifting rows in x leaves the static
//! light where it was (the core's motion compensation must not rely on
//! that). Prints glare/other-row RMAE per profile, mean over seeds.
//!
//! `cargo run --release -p spiv-host --example mc_probe -- SEEDS ITERATIONS [wall]`
//! (`wall`: the PIV prediction ignores the glare rows and pins u = 0 at the
//! wall).

use spiv_core::Params;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::simulate_planes;
use spiv_host::metrics::{region_error, row_profile};
use spiv_host::pipeline::Job;
use spiv_host::piv::{piv, to_f32};
use spiv_host::reconstruct::{frame_from_planes, Method, Planes};

fn bit(p: &[u8], i: usize) -> bool {
    p[i / 8] >> (i % 8) & 1 == 1
}

/// Planes around kc (window n), each shifted row by row by d[r]·(t−kc) px
/// (d per stored row, px per tick, in x), returned with their first tick.
fn compensated(data: &[u8], w: usize, h: usize, kc: u64, n: u64, d: &[f64]) -> (u64, Vec<u8>) {
    let pb = w * h / 8;
    let first = kc.saturating_sub(n / 2);
    let last = (kc + n - n / 2).min((data.len() / pb) as u64);
    let mut out = vec![0u8; pb * (last - first) as usize];
    for t in first..last {
        let src = &data[t as usize * pb..(t as usize + 1) * pb];
        let dst = &mut out[(t - first) as usize * pb..(t - first + 1) as usize * pb];
        let dtk = t as f64 - kc as f64;
        for (r, &dr) in d.iter().enumerate().take(h) {
            let s = (dr * dtk).round() as i64;
            for x in 0..w {
                let xs = x as i64 + s;
                if xs >= 0 && (xs as usize) < w && bit(src, r * w + xs as usize) {
                    let i = r * w + x;
                    dst[i / 8] |= 1 << (i % 8);
                }
            }
        }
    }
    (first, out)
}

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(2);
    let iters: usize = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let wall = std::env::args().nth(3).is_some_and(|s| s == "wall");
    for kind in [
        SceneKind::PaperLinear,
        SceneKind::PaperQuadratic,
        SceneKind::PaperLog,
    ] {
        let mut acc = [[0.0f64; 2]; 4];
        for seed in 1..=seeds {
            let job = Job::new(SceneParams::new(kind), seed);
            let p = &job.request.scene;
            let (w, h) = (p.width, p.height);
            let (wu, hu) = (usize::from(w), usize::from(h));
            let (data, sim) = simulate_planes(&job.request).unwrap();
            let [ka, kb] = sim.meta.capture.pair.map(u64::from);
            let dt = (kb - ka) as f64;
            let truth = sim.scene.truth_vectors(&job.piv.centres(w, h), dt);
            let glare_limit = 2.0 * p.glare_sigma;
            let planes = Planes::simulated(w, h, data.clone());
            let measure = |a: &[u16], b: &[u16]| {
                let f = piv(&to_f32(a, wu, hu), &to_f32(b, wu, hu), None, &job.piv).unwrap();
                let rows = row_profile(&f.vectors(), &truth, f64::from(h));
                [
                    region_error(&rows, |y| y < glare_limit).rmae,
                    region_error(&rows, |y| y >= glare_limit).rmae,
                ]
            };
            let core = Params::default();
            let tfp = [ka, kb].map(|k| {
                frame_from_planes(&planes, k, Method::Tfp, 8, &core)
                    .unwrap()
                    .data
            });
            let e_tfp = measure(&tfp[0], &tfp[1]);
            let ad = [ka, kb].map(|k| {
                frame_from_planes(&planes, k, Method::Adaptive, 128, &core)
                    .unwrap()
                    .data
            });
            let e_ad = measure(&ad[0], &ad[1]);
            // Truth prediction per stored row (px per tick).
            let d_true: Vec<f64> = (0..hu)
                .map(|r| {
                    let y = (hu - 1 - r) as f64;
                    sim.scene.truth(&[(wu as f64 / 2.0, y)], 1.0)[0].2
                })
                .collect();
            // TFP prediction: the TFP field's row means, interpolated.
            let tf = piv(
                &to_f32(&tfp[0], wu, hu),
                &to_f32(&tfp[1], wu, hu),
                None,
                &job.piv,
            )
            .unwrap();
            let rows = row_profile(&tf.vectors(), &truth, f64::from(h));
            let d_tfp: Vec<f64> = (0..hu)
                .map(|r| {
                    let yw = r as f64 + 0.5; // stored row r is this far above the wall
                    let mut pts: Vec<(f64, f64)> = rows
                        .iter()
                        .filter(|x| !wall || x.y_wall >= glare_limit)
                        .filter_map(|x| x.measured.map(|m| (x.y_wall, m / dt)))
                        .collect();
                    if wall {
                        pts.push((0.0, 0.0));
                    }
                    interp(&pts, yw)
                })
                .collect();
            let mc_frames = |d: &[f64]| {
                [ka, kb].map(|k| {
                    let (first, buf) = compensated(&data, wu, hu, k, 128, d);
                    let pl = Planes {
                        first,
                        ..Planes::simulated(w, h, buf)
                    };
                    frame_from_planes(&pl, k, Method::Adaptive, 128, &core)
                        .unwrap()
                        .data
                })
            };
            let mc = |d: &[f64]| {
                let fr = mc_frames(d);
                measure(&fr[0], &fr[1])
            };
            let e_true = mc(&d_true);
            // Contrast maximisation around the TFP prediction (±40 % in 2 % steps,
            // and ±0.05 px/tick), per 16-row band, from the spikes of frame A.
            let d_cm = cmax(&data, wu, hu, ka, 64, 16, |r| {
                let c = d_tfp[r];
                (-20..=20)
                    .map(|k| c * (1.0 + 0.02 * f64::from(k)))
                    .chain((-5..=5).map(|k| c + 0.01 * f64::from(k)))
                    .collect()
            });
            let e_cm = mc(&d_cm);
            if seed == 1 {
                let pe = |d: &[f64], lo: usize, hi: usize| {
                    (lo..hi)
                        .map(|r| ((d[r] - d_true[r]) / d_true[r].abs().max(1e-3)).abs())
                        .sum::<f64>()
                        / (hi - lo) as f64
                };
                eprintln!("  {kind:?} cmax: {:.3}/{:.3}  pred rel err glare {:.3} other {:.3} (tfp pred: {:.3} {:.3})", e_cm[0], e_cm[1], pe(&d_cm, 0, 50), pe(&d_cm, 50, hu), pe(&d_tfp, 0, 50), pe(&d_tfp, 50, hu));
            }
            let mut d = d_tfp.clone();
            let mut e_pred = [0.0; 2];
            for it in 0..iters {
                let fr = mc_frames(&d);
                e_pred = measure(&fr[0], &fr[1]);
                if seed == 1 {
                    let pe = |lo: usize, hi: usize| {
                        (lo..hi)
                            .map(|r| ((d[r] - d_true[r]) / d_true[r].abs().max(1e-3)).abs())
                            .sum::<f64>()
                            / (hi - lo) as f64
                    };
                    eprintln!(
                        "  {kind:?} iter {it}: {:.3}/{:.3}  pred rel err glare {:.3} other {:.3}",
                        e_pred[0],
                        e_pred[1],
                        pe(0, 50),
                        pe(50, hu)
                    );
                }
                let f = piv(
                    &to_f32(&fr[0], wu, hu),
                    &to_f32(&fr[1], wu, hu),
                    None,
                    &job.piv,
                )
                .unwrap();
                let rows = row_profile(&f.vectors(), &truth, f64::from(h));
                let mut pts: Vec<(f64, f64)> = rows
                    .iter()
                    .filter(|x| x.used >= 12 && (!wall || x.y_wall >= glare_limit))
                    .filter_map(|x| x.measured.map(|m| (x.y_wall, m / dt)))
                    .collect();
                if wall {
                    pts.push((0.0, 0.0));
                }
                if seed == 1 {
                    eprintln!(
                        "    rows used: {:?}",
                        rows.iter()
                            .map(|x| (
                                x.y_wall,
                                x.used,
                                x.measured.map(|m| (m * 100.0).round() / 100.0),
                                (x.truth * 100.0).round() / 100.0
                            ))
                            .take(4)
                            .collect::<Vec<_>>()
                    );
                }
                d = (0..hu).map(|r| interp(&pts, r as f64 + 0.5)).collect();
            }
            for (a, e) in acc.iter_mut().zip([e_tfp, e_ad, e_true, e_pred]) {
                a[0] += e[0] / seeds as f64;
                a[1] += e[1] / seeds as f64;
            }
        }
        println!(
            "{kind:?}: glare/other RMAE  tfp {:.3}/{:.3}  adaptive128 {:.3}/{:.3}  mc(truth) {:.3}/{:.3}  mc(tfp pred) {:.3}/{:.3}",
            acc[0][0], acc[0][1], acc[1][0], acc[1][1], acc[2][0], acc[2][1], acc[3][0], acc[3][1]
        );
    }
}

/// Contrast maximisation per band of `band` stored rows: the x velocity
/// (px/tick) among `cands` whose compensated counts over `n` ticks around
/// `kc` have the largest sum of squares; returned per stored row
/// (piecewise linear between band centres).
fn cmax(
    data: &[u8],
    w: usize,
    h: usize,
    kc: u64,
    n: u64,
    band: usize,
    cands: impl Fn(usize) -> Vec<f64>,
) -> Vec<f64> {
    let pb = w * h / 8;
    let first = kc.saturating_sub(n / 2);
    let last = (kc + n - n / 2).min((data.len() / pb) as u64);
    let mut centres = Vec::new();
    let mut counts = vec![0u16; band * w];
    for b0 in (0..h).step_by(band) {
        let b1 = (b0 + band).min(h);
        let mut best = (f64::MIN, 0.0);
        for d in cands((b0 + b1) / 2) {
            counts.iter_mut().for_each(|c| *c = 0);
            for t in first..last {
                let src = &data[t as usize * pb..(t as usize + 1) * pb];
                let s = (d * (t as f64 - kc as f64)).round() as i64;
                for r in b0..b1 {
                    for x in 0..w {
                        let xs = x as i64 + s;
                        if xs >= 0 && (xs as usize) < w && bit(src, r * w + xs as usize) {
                            counts[(r - b0) * w + x] += 1;
                        }
                    }
                }
            }
            let e: f64 = counts[..(b1 - b0) * w]
                .iter()
                .map(|&c| f64::from(c) * f64::from(c))
                .sum();
            if e > best.0 {
                best = (e, d);
            }
        }
        centres.push(((b0 + b1) as f64 / 2.0 - 0.5, best.1));
    }
    (0..h).map(|r| interp(&centres, r as f64)).collect()
}

fn interp(pts: &[(f64, f64)], y: f64) -> f64 {
    let mut p: Vec<(f64, f64)> = pts.to_vec();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    if p.is_empty() {
        return 0.0;
    }
    if y <= p[0].0 {
        return p[0].1;
    }
    for k in 1..p.len() {
        if y <= p[k].0 {
            let t = (y - p[k - 1].0) / (p[k].0 - p[k - 1].0);
            return p[k - 1].1 * (1.0 - t) + p[k].1 * t;
        }
    }
    p[p.len() - 1].1
}
