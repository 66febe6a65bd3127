//! How much of the spike path's glare-row error is the glare's, and how
//! much is PIV's own? Runs `spiv run`'s pipeline on a paper profile with a
//! chosen glare peak (0: none) over seeds 1..=N and prints each frame
//! kind's mean glare-row and other-row RMAE, then the mean signed and
//! absolute errors of the rows within 90 px of the wall. With no glare at
//! all, the frame camera's bottom rows on the quadratic profile still
//! measure RMAE 0.071
//! (10 seeds): the paper's 0.028 there is below this PIV's noise floor for
//! displacements of 0.2–0.5 px (README, `spiv bench paper`).
//!
//! The optional WIDTH (default 400 px) widens the canvas: a row profile
//! averages more vectors, as on the paper's 6400-px canvas.
//!
//! `cargo run --release -p spiv-host --example glare_probe -- [linear|quadratic|log] [GLARE_PEAK] [SEEDS] [WIDTH]`
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_host::pipeline::{run, Job};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // `linear`, `quadratic` (the default) or `log`.
    let profile = args.get(1).map_or("quadratic", String::as_str);
    let kind =
        SceneKind::from_name(&format!("paper-{profile}")).unwrap_or(SceneKind::PaperQuadratic);
    let glare: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.65);
    let seeds: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(10);
    let width: Option<u16> = args.get(4).and_then(|s| s.parse().ok());
    let mut bias = std::collections::BTreeMap::<(usize, i64), (f64, f64, usize, f64)>::new();
    let mut rmae = [[0.0f64; 2]; 5];
    for seed in 1..=seeds {
        let mut p = SceneParams::new(kind);
        p.glare_peak = glare;
        if let Some(w) = width {
            p.width = w;
        }
        let job = Job::new(p, seed);
        let o = run(&job, |_| {}).expect("runs");
        for (i, m) in o.measured.iter().enumerate() {
            rmae[i][0] += m.glare.rmae / seeds as f64;
            rmae[i][1] += m.rest.rmae / seeds as f64;
            for r in &m.rows {
                if r.y_wall < 90.0 {
                    let e = bias.entry((i, r.y_wall.round() as i64)).or_default();
                    e.0 += r.measured.unwrap_or(0.0) - r.truth;
                    e.1 += r.truth;
                    e.2 += 1;
                    e.3 += (r.measured.unwrap_or(0.0) - r.truth).abs();
                }
            }
        }
    }
    for (i, r) in rmae.iter().enumerate() {
        let name = spiv_host::pipeline::FrameKind::ALL[i].name();
        println!("{name} glare RMAE {:.4} other {:.4}", r[0], r[1]);
    }
    for ((i, y), (b, t, n, a)) in bias {
        let name = spiv_host::pipeline::FrameKind::ALL[i].name();
        let (t, b, a) = (t / n as f64, b / n as f64, a / n as f64);
        println!("{name} y_wall {y}: truth {t:.3} mean error {b:+.4} mean |error| {a:.4}");
    }
}
