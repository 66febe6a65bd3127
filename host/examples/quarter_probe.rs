//! Are wrong vectors flagged valid? Runs `spiv run`'s pipeline on a paper
//! profile over seeds and re-runs PIV on each frame kind's pair with `spiv
//! piv`'s defaults; prints, per kind, the valid vectors whose error against
//! the truth exceeds 1 px, 2 px and a quarter of the last window.
//!
//! `cargo run --release -p spiv-host --example quarter_probe -- [linear|quadratic|log] [GLARE_PEAK] [SEEDS]`
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_host::pipeline::{run, Job};
use spiv_host::piv::options::PivOptions;
use spiv_host::piv::{piv, to_f32, State};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // `linear`, `quadratic` (the default) or `log`.
    let profile = args.get(1).map_or("quadratic", String::as_str);
    let kind =
        SceneKind::from_name(&format!("paper-{profile}")).unwrap_or(SceneKind::PaperQuadratic);
    let glare: Option<f64> = args.get(2).and_then(|s| s.parse().ok());
    let seeds: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(3);
    let ratio: f64 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(1.5);
    let opts = PivOptions {
        min_peak_ratio: ratio,
        dense_fallback: false,
        ..PivOptions::default()
    };
    let settings = opts.settings().expect("defaults");
    let quarter = settings.windows.last().copied().unwrap_or(32) as f64 / 4.0;
    for seed in 1..=seeds {
        let mut p = SceneParams::new(kind);
        if let Some(g) = glare {
            p.glare_peak = g;
        }
        let (w, h) = (usize::from(p.width), usize::from(p.height));
        let job = Job::new(p, seed);
        let o = run(&job, |_| {}).expect("runs");
        for m in &o.measured {
            let a = to_f32(&m.pair[0], w, h);
            let b = to_f32(&m.pair[1], w, h);
            let f = piv(&a, &b, None, &settings).expect("piv");
            let pts: Vec<(f64, f64)> = f.vectors().iter().map(|v| (v.x, v.y)).collect();
            let t = o
                .sim
                .scene
                .truth(&pts, f64::from(o.sim.meta.scene.params.pair_dt));
            let mut n = [0usize; 4];
            let mut rms = (0.0f64, 0usize);
            let mut worst = 0.0f64;
            for (v, t) in f.vectors().iter().zip(&t) {
                let e = (v.u - t.2).hypot(v.v - t.3);
                if v.state.is_measured() {
                    rms.0 += e * e;
                    rms.1 += 1;
                }
                if v.state == State::Valid {
                    n[0] += 1;
                    n[1] += usize::from(e > 1.0);
                    n[2] += usize::from(e > 2.0);
                    n[3] += usize::from(e > quarter);
                    if e > quarter && std::env::var_os("SHOW").is_some() {
                        println!(
                            "  ({:.0},{:.0}) measured ({:.2},{:.2}) truth ({:.2},{:.2})",
                            v.x, v.y, v.u, v.v, t.2, t.3
                        );
                    }
                    worst = worst.max(e);
                }
            }
            let mut g = f.clone();
            let d = spiv_host::piv::dense::dense_flow(
                &a,
                &b,
                None,
                &spiv_host::piv::dense::DenseMode::Pyramid.settings(),
            );
            for st in g.state.iter_mut() {
                *st = State::Invalid;
            }
            spiv_host::piv::dense::fill(&mut g, &d);
            let drms = {
                let (mut s2, mut k) = (0.0, 0usize);
                for (v, t) in g.vectors().iter().zip(&t) {
                    if v.state.is_measured() {
                        s2 += (v.u - t.2).powi(2) + (v.v - t.3).powi(2);
                        k += 1;
                    }
                }
                (s2 / k.max(1) as f64).sqrt()
            };
            print!("dense rms {drms:.3} | ");
            println!(
                "seed {seed} {:9} valid {:4} >1px {:3} >2px {:3} >{quarter}px {:3} worst {worst:.2} measured {} rms {:.3}",
                m.source.name(),
                n[0],
                n[1],
                n[2],
                n[3],
                rms.1,
                (rms.0 / rms.1.max(1) as f64).sqrt()
            );
        }
    }
}
