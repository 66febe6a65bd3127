//! `spiv run [--scene NAME] [--out DIR] [--seed N]`: the main job.

use std::path::{Path, PathBuf};

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use plotters::style::RGBColor;
use serde_json::json;
use spiv_firmware_sim::scene::{SceneKind, SceneParams, PIXEL_MM, TICK_HZ};
use spiv_firmware_sim::simulation::write_frame;
use spiv_formats::image::write_levels;
use spiv_formats::vectors::write_vectors;
use spiv_host::metrics::rmae_ratio;
use spiv_host::pipeline::{run as run_job, Job, Measured, Outcome, Source};
use spiv_host::plot::{self, Series};

use super::CliError;

/// The main job: one scene through both cameras, the core and PIV; the
/// paper's comparison table, images, vectors, plots and a JSON summary.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scene: paper-linear, paper-quadratic, paper-log, blasius, uniform, vortex.
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
    #[arg(long, default_value = "8")]
    dwell_cap: String,
    /// How the sidecar codes frames on the wire: rice (lossless, default),
    /// sparse (lossy: particles exact, background at low resolution) or raw.
    #[arg(long, default_value = "rice")]
    encoding: String,
}

/// Parses `--encoding`.
pub fn parse_encoding(v: &str) -> Result<spiv_core::wire::Encoding, CliError> {
    use spiv_core::wire::Encoding;
    match v {
        "rice" => Ok(Encoding::Rice),
        "sparse" => Ok(Encoding::Sparse),
        "raw" => Ok(Encoding::Raw8),
        _ => Err(CliError::Usage(format!(
            "--encoding {v}: expected rice, sparse or raw"
        ))),
    }
}

/// Parses `--dwell-cap`: px, or "off".
pub fn parse_dwell_cap(v: &str) -> Result<Option<f64>, CliError> {
    if v == "off" {
        return Ok(None);
    }
    match v.parse::<f64>() {
        Ok(c) if c.is_finite() && c > 0.0 && c <= 1000.0 => Ok(Some(c)),
        _ => Err(CliError::Usage(format!(
            "--dwell-cap {v}: expected px in (0, 1000] or off"
        ))),
    }
}

/// Parses a scene name into its defaults.
pub fn scene_params(name: &str) -> Result<SceneParams, CliError> {
    let kind = SceneKind::parse(name).map_err(|e| CliError::Usage(e.to_string()))?;
    Ok(SceneParams::new(kind))
}

/// Human name of a source.
pub fn label(s: Source, tfp: u16) -> String {
    match s {
        Source::Frame => "frame camera".into(),
        Source::Tfp => format!("spike, TFP n={tfp}"),
        Source::Adaptive => "spike, adaptive".into(),
    }
}

/// Prints the paper's Tables 1–2 layout for one run.
pub fn print_table(o: &Outcome, job: &Job) {
    let m = &o.sim.meta;
    let dt = f64::from(m.capture.pair[1] - m.capture.pair[0]);
    let to_ms = PIXEL_MM / 1000.0 / (dt / TICK_HZ);
    let g = &o.measured[0].glare;
    let r = &o.measured[0].rest;
    println!(
        "{} seed {}: {}x{} px, pair at ticks {:?} ({} ticks = {:.2} ms apart), truth max {:.2} px/pair",
        m.scene.name,
        m.seed,
        m.capture.width,
        m.capture.height,
        m.capture.pair,
        dt,
        dt / TICK_HZ * 1e3,
        o.truth.iter().map(|v| v.u.abs()).fold(0.0, f64::max)
    );
    println!(
        "{:<20} | {:^29} | {:^29}",
        "",
        format!("glare rows (y < {:.0} px, {} rows)", o.glare_limit, g.rows),
        format!("other rows ({} rows)", r.rows)
    );
    println!(
        "{:<20} | {:>6} {:>7} {:>8} {:>5} | {:>6} {:>7} {:>8} {:>5}",
        "frames", "RMAE", "RMSE px", "RMSE m/s", "lost", "RMAE", "RMSE px", "RMSE m/s", "lost"
    );
    for x in &o.measured {
        println!(
            "{:<20} | {:>6.3} {:>7.3} {:>8.4} {:>5} | {:>6.3} {:>7.3} {:>8.4} {:>5}",
            label(x.source, job.tfp_window),
            x.glare.rmae,
            x.glare.rmse,
            x.glare.rmse * to_ms,
            x.glare.lost,
            x.rest.rmae,
            x.rest.rmse,
            x.rest.rmse * to_ms,
            x.rest.lost,
        );
    }
    let f = &o.measured[0];
    for x in &o.measured[1..] {
        println!(
            "{:<20} | {:>6.3} {:>22} | {:>6.3}",
            format!("frame / {}", x.source.name()),
            rmae_ratio(f.glare.rmae, x.glare.rmae),
            "",
            rmae_ratio(f.rest.rmae, x.rest.rmae)
        );
    }
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
    let ad = &o.measured[2];
    plot::vectors(
        &a.out.join("vectors.png"),
        &ad.pair[0],
        u32::from(w),
        u32::from(h),
        ad.full_scale,
        &ad.vectors,
        1.0,
    )
    .map_err(|e| CliError::Usage(e.to_string()))?;
    let summary = json!({
        "scene": o.sim.meta.scene.name,
        "seed": a.seed,
        "width": w,
        "height": h,
        "pair": o.sim.meta.capture.pair,
        "dt_ticks": dt,
        "glare_rows_below_px": o.glare_limit,
        "core": { "n0": job.core.n0, "n_max": job.core.n_max, "n_fs": job.core.n_fs },
        "tfp_window": job.tfp_window,
        "dwell_cap_px": job.dwell_cap,
        "piv": job.piv,
        "results": o.measured.iter().map(|x| json!({
            "source": x.source,
            "glare": x.glare,
            "rest": x.rest,
            "rows": x.rows,
            "piv_ms": x.piv_ms,
        })).collect::<Vec<_>>(),
        "frame_over_adaptive_rmae": {
            "glare": rmae_ratio(o.measured[0].glare.rmae, o.measured[2].glare.rmae),
            "rest": rmae_ratio(o.measured[0].rest.rmae, o.measured[2].rest.rmae),
        },
        "stage_ms": { "simulate": o.stage_ms[0], "sidecar": o.stage_ms[1], "piv": o.stage_ms[2] },
        "wire": {
            "encoding": format!("{:?}", job.encoding),
            "adaptive_pair_bytes": o.link.adaptive_bytes,
            "tfp_pair_bytes": o.link.tfp_bytes,
            "raw_spike_bytes_per_pair_period": o.link.raw_bytes_per_period,
            "reduction_adaptive": o.link.raw_bytes_per_period as f64 / o.link.adaptive_bytes.max(1) as f64,
            "lost_frames": o.link.lost_frames,
            "bit_exact": o.link.bit_exact,
        },
    });
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary).unwrap_or_default(),
    )
    .map_err(|e| CliError::Usage(format!("summary.json: {e}")))?;
    bar.finish_and_clear();
    print_table(&o, &job);
    println!(
        "wire ({:?}): adaptive pair {} B, TFP pair {} B, raw spikes {} B per pair period ({:.1}x less); lost {}, bit-exact {}",
        job.encoding,
        o.link.adaptive_bytes,
        o.link.tfp_bytes,
        o.link.raw_bytes_per_period,
        o.link.raw_bytes_per_period as f64 / o.link.adaptive_bytes.max(1) as f64,
        o.link.lost_frames,
        if o.link.bit_exact { "yes" } else { "NO" },
    );
    println!(
        "simulate {:.0} ms, sidecar core + wire {:.0} ms, PIV {:.0} ms -> {}",
        o.stage_ms[0],
        o.stage_ms[1],
        o.stage_ms[2],
        a.out.display()
    );
    Ok(())
}
