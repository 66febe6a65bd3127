//! `spiv simulate --scene NAME --out DIR [--seed N] [--width W --height H] [--ticks N]`

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_to_dir, Request};
use spiv_formats::MAX_FRAME_PIXELS;

use super::CliError;

/// Simulate a scene: spikes.dat, scene.json, frame_a.png, frame_b.png, truth.csv, profile.csv.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Scene: paper-linear, paper-quadratic, paper-log, blasius, uniform, vortex.
    #[arg(long, default_value = "paper-linear")]
    scene: String,
    /// Output folder (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Seed of particles and noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Width, px (the scene's default otherwise).
    #[arg(long)]
    width: Option<u16>,
    /// Height, px.
    #[arg(long)]
    height: Option<u16>,
    /// Planes to write (default: the pair plus 64 ticks on each side).
    #[arg(long)]
    ticks: Option<u32>,
    /// Pair separation, ticks.
    #[arg(long)]
    dt: Option<u32>,
    /// Displacement of the `uniform` scene per pair, px: "U,V" (right, down).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    shift: Option<Vec<f64>>,
    /// Minimum particle spacing, px (the paper used 15).
    #[arg(long)]
    spacing: Option<f64>,
}

/// Runs it.
pub fn run(a: &SimulateArgs) -> Result<(), CliError> {
    let kind = SceneKind::parse(&a.scene).map_err(|e| CliError::Usage(e.to_string()))?;
    let mut p = SceneParams::new(kind);
    if let Some(w) = a.width {
        p.width = w;
    }
    if let Some(h) = a.height {
        p.height = h;
    }
    if p.width < 8 || p.height < 8 || (usize::from(p.width) * usize::from(p.height)) % 8 != 0 {
        return Err(CliError::Usage(format!(
            "--width {} --height {}: both at least 8 and width*height a multiple of 8",
            p.width, p.height
        )));
    }
    let px = u64::from(p.width) * u64::from(p.height);
    if px > MAX_FRAME_PIXELS {
        return Err(CliError::Usage(format!(
            "--width {} --height {}: {px} px, at most {MAX_FRAME_PIXELS}",
            p.width, p.height
        )));
    }
    if let Some(dt) = a.dt {
        if !(1..=1_000_000).contains(&dt) {
            return Err(CliError::Usage("--dt must be in 1..=1000000 ticks".into()));
        }
        p.pair_dt = dt;
    }
    if let Some(sh) = &a.shift {
        if kind != SceneKind::Uniform {
            return Err(CliError::Usage(
                "--shift applies to the uniform scene".into(),
            ));
        }
        if sh.len() != 2 || sh.iter().any(|v| !v.is_finite() || v.abs() > 1000.0) {
            return Err(CliError::Usage(
                "--shift U,V: two numbers within ±1000 px".into(),
            ));
        }
        p.shift = (sh[0], sh[1]);
    }
    if let Some(s) = a.spacing {
        if !(0.0..=64.0).contains(&s) {
            return Err(CliError::Usage(format!(
                "--spacing {s}: expected 0..=64 px"
            )));
        }
        p.min_spacing = s;
    }
    if a.ticks == Some(0) || a.ticks.is_some_and(|t| t > 1_000_000) {
        return Err(CliError::Usage("--ticks must be in 1..=1000000".into()));
    }
    let mut req = Request::new(p, a.seed);
    req.ticks = a.ticks;
    let (ticks, _) = req.layout()?;
    let bar = ProgressBar::new(u64::from(ticks));
    bar.set_style(
        ProgressStyle::with_template("simulating {bar:30} {pos}/{len} planes {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let sim = simulate_to_dir(&req, &a.out, |done, _| bar.set_position(u64::from(done)))?;
    bar.finish_and_clear();
    let m = &sim.meta;
    println!(
        "{}: {}x{} px, {} planes, pair {:?}, {} spikes (mean rate {:.4}/px/tick), seeding density {}/{} cells -> {}",
        m.scene.name,
        m.capture.width,
        m.capture.height,
        m.capture.planes,
        m.capture.pair,
        sim.spikes,
        sim.spikes as f64 / (f64::from(m.capture.width) * f64::from(m.capture.height) * m.capture.planes as f64),
        m.scene.density_reached.0,
        m.scene.density_reached.1,
        a.out.display()
    );
    Ok(())
}
