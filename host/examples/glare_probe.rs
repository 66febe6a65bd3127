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
mod common;

use spiv_firmware_sim::scene::SceneParams;
use spiv_host::pipeline::{run, Job};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // `linear`, `quadratic` (the default) or `log`.
    let kind = common::profile(args.get(1));
    let glare: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.65);
    let seeds: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(10);
    let width: Option<u16> = args.get(4).and_then(|s| s.parse().ok());
    let mut near = common::WallRows::default();
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
            near.add(i, &m.rows);
        }
    }
    for (i, r) in rmae.iter().enumerate() {
        let name = spiv_host::pipeline::FrameKind::ALL[i].name();
        println!("{name} glare RMAE {:.4} other {:.4}", r[0], r[1]);
    }
    let names: Vec<String> = spiv_host::pipeline::FrameKind::ALL
        .iter()
        .map(|k| k.name().to_string())
        .collect();
    near.print(&names);
}
