//! `spiv run [--scene NAME] [--out DIR] [--seed N]`: the main job.

use std::path::{Path, PathBuf};

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use plotters::style::RGBColor;
use spiv_firmware_sim::simulation::write_frame;
use spiv_formats::image::write_levels;
use spiv_formats::vectors::write_vectors;
use spiv_host::pipeline::{run as run_job, Job, Measured};
use spiv_host::report::plot::{self, Series};
use spiv_host::report::summary::run_summary;
use spiv_host::report::table::{label, run_table, wire_line};

use super::{parse_dwell_cap, parse_encoding, scene_params, CliError};

/// The main job: one scene through both cameras, the core and PIV; the
/// paper's comparison table, images, vectors, plots and a JSON summary.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scene: paper-linear, paper-quadratic, paper-log, blasius, uniform, vortex, turbulence, large-shift.
    #[arg(long, default_value = "paper-linear")]
    scene: String,
    /// Output folder (created if missing).
    #[arg(long, default_value = "spiv-out")]
    out: PathBuf,
    /// Seed of particles and noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Beyond the paper: cap each band's adaptive window so the fastest
    /// particle (from PIV on the TFP pair) blurs by at most this many px;
    /// "off" runs the paper's algorithm with one n_max everywhere.
    #[arg(long, default_value = spiv_host::dwell::DWELL_CAP_ARG)]
    dwell_cap: String,
    /// How the sidecar codes frames on the wire: rice (lossless, default),
    /// context (lossless, context-modelled range coder), sparse (lossy:
    /// particles exact, background at low resolution), sparse-context
    /// (sparse's frames, range-coded) or raw.
    #[arg(long, default_value = "rice")]
    encoding: String,
}

fn write_pair(dir: &Path, x: &Measured, w: u16, h: u16) -> Result<(), CliError> {
    for (suffix, img) in ["a", "b"].iter().zip(&x.pair) {
        let path = dir.join(format!("{}_{suffix}.png", x.source.name()));
        write_levels(&path, u32::from(w), u32::from(h), img, x.full_scale)?;
    }
    Ok(())
}

/// Runs it.
pub fn run(a: &RunArgs) -> Result<(), CliError> {
    let mut job = Job::new(scene_params(&a.scene)?, a.seed);
    job.dwell_cap = parse_dwell_cap(&a.dwell_cap)?;
    job.encoding = parse_encoding(&a.encoding)?;
    std::fs::create_dir_all(&a.out)
        .map_err(|e| CliError::Usage(format!("{}: {e}", a.out.display())))?;
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(100));
    let o = run_job(&job, |s| bar.set_message(s.to_string()))?;
    bar.set_message("writing images, vectors and plots");
    let (w, h) = (o.sim.meta.capture.width, o.sim.meta.capture.height);
    for (name, f) in ["frame_a.png", "frame_b.png"].iter().zip(&o.sim.frames) {
        write_frame(&a.out.join(name), &job.request, w, h, f)?;
    }
    for x in &o.measured[1..] {
        write_pair(&a.out, x, w, h)?;
    }
    for x in &o.measured {
        write_vectors(
            &a.out.join(format!("vectors_{}.csv", x.source.name())),
            &x.vectors,
        )?;
    }
    write_vectors(&a.out.join("truth.csv"), &o.truth)?;
    let dt = f64::from(o.sim.meta.capture.pair[1] - o.sim.meta.capture.pair[0]);
    let colors = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(148, 103, 189),
    ];
    let names: Vec<String> = o
        .measured
        .iter()
        .map(|x| label(x.source, job.tfp_window))
        .collect();
    let series: Vec<Series<'_>> = o
        .measured
        .iter()
        .zip(&names)
        .zip(colors)
        .map(|((x, n), color)| Series {
            name: n,
            color,
            rows: &x.rows,
        })
        .collect();
    let truth_profile = o.sim.scene.profile(dt);
    plot::profile(
        &a.out.join("profile.png"),
        &format!("{}: u(y), seed {}", o.sim.meta.scene.name, a.seed),
        &truth_profile,
        &series,
        o.glare_limit,
    )
    .map_err(|e| CliError::Usage(e.to_string()))?;
    // The spike camera's headline: the motion-compensated pair, with the
    // field measured over the wide baseline where the flow allows it.
    let (ad, wide) = (&o.measured[3], &o.measured[4]);
    plot::vectors(
        &a.out.join("vectors.png"),
        &ad.pair[0],
        (u32::from(w), u32::from(h)),
        ad.full_scale,
        &wide.vectors,
        1.0,
        plot::VectorCaption {
            title: "motion-compensated pair, wide baseline",
            unit: None,
        },
    )
    .map_err(|e| CliError::Usage(e.to_string()))?;
    let summary = run_summary(&o, &job);
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary).unwrap_or_default(),
    )
    .map_err(|e| CliError::Usage(format!("summary.json: {e}")))?;
    bar.finish_and_clear();
    print!("{}", run_table(&o, &job));
    println!("{}", wire_line(&o, &job));
    println!(
        "simulate {:.0} ms, sidecar core + wire {:.0} ms, PIV {:.0} ms -> {}",
        o.stage_ms[0],
        o.stage_ms[1],
        o.stage_ms[2],
        a.out.display()
    );
    Ok(())
}
