//! `spiv simulate --scene NAME --out DIR [--seed N] [--width W --height H] [--ticks N]`

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use spiv_firmware_sim::simulation::simulate_to_dir;
use spiv_host::simulate::SimulateRequest;

use super::CliError;

/// Simulate a scene: spikes.dat, scene.json, frame_a.png, frame_b.png, truth.csv, truth.flo (dense), profile.csv.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Scene: paper-linear, paper-quadratic, paper-log, blasius, uniform, vortex, turbulence, large-shift, vortex-array, spectral-turbulence.
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
    /// Top speed of the shear scenes and the vortex array, px/tick.
    #[arg(long)]
    speed: Option<f64>,
    /// Seed of the turbulence field, or of the vortex array's offset and
    /// drift direction.
    #[arg(long)]
    flow_seed: Option<u64>,
    /// Spectral turbulence: the member `spiv bench flows` draws from this
    /// seed (eddies, speed, seeding, light, sheet; its flow seed too).
    #[arg(long)]
    member: Option<u64>,
}

/// Runs it.
pub fn run(a: &SimulateArgs) -> Result<(), CliError> {
    let shift = match a.shift.as_deref() {
        None => None,
        Some(&[u, v]) => Some((u, v)),
        Some(_) => {
            return Err(CliError::Usage(
                "--shift U,V: two numbers within ±1000 px".into(),
            ))
        }
    };
    let req = SimulateRequest {
        scene: a.scene.clone(),
        seed: a.seed,
        width: a.width,
        height: a.height,
        ticks: a.ticks,
        dt: a.dt,
        shift,
        spacing: a.spacing,
        speed: a.speed,
        flow_seed: a.flow_seed,
        member: a.member,
    }
    .request()?;
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
