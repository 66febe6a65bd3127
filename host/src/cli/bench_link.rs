//! `spiv bench link`: the options and the table of
//! [`spiv_host::bench::link`].

use std::path::PathBuf;

use clap::Args;
use spiv_host::bench::link::{link_bench, LinkBench, LinkFrames};

use super::CliError;

/// Options of `spiv bench link`.
#[derive(Debug, Args)]
pub struct LinkArgs {
    /// Seeds 1..=N per scene.
    #[arg(long, default_value_t = 2)]
    seeds: u64,
    /// Pairs per stream.
    #[arg(long, default_value_t = 4)]
    pairs: u32,
    /// M as multiples of the pair's dt (the default M is 4·dt).
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    every: Vec<u32>,
    /// Lossy mode: largest error of a background sample, gray levels.
    #[arg(long, default_value_t = 12)]
    tolerance: u16,
    /// Lossy mode: the tolerance in a block is at most its contrast (its
    /// brightest sample above its background) over this; 0: off.
    #[arg(long, default_value_t = 4)]
    contrast: u16,
    /// Lossy mode: the contrast rule on motion-compensated frames.
    #[arg(long, default_value_t = 2)]
    contrast_mc: u16,
    /// Adaptive window cap against streaks (as `spiv run --dwell-cap`), px
    /// of blur, or "off" for the paper's one n_max everywhere.
    #[arg(long, default_value = spiv_host::dwell::DWELL_CAP_ARG)]
    dwell_cap: String,
    /// The frames to send: tfp (n = 8), adaptive (with the dwell cap) and
    /// mc (motion-compensated, with the control `spiv run` predicts).
    #[arg(long, value_delimiter = ',', default_value = "tfp,adaptive,mc")]
    frames: Vec<String>,
    /// Write the rows as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Runs it.
pub fn run(a: &LinkArgs) -> Result<(), CliError> {
    if a.every.is_empty() || a.every.iter().any(|&f| f == 0 || f > 64) {
        return Err(CliError::Usage("--every: multiples of dt in 1..=64".into()));
    }
    if a.seeds == 0 || a.pairs == 0 {
        return Err(CliError::Usage(
            "--seeds and --pairs must be at least 1".into(),
        ));
    }
    let dwell_cap = super::parse_dwell_cap(&a.dwell_cap)?;
    let mut frames = Vec::new();
    for name in &a.frames {
        let f = LinkFrames::ALL
            .into_iter()
            .find(|f| f.name() == name.as_str())
            .ok_or_else(|| {
                CliError::Usage(format!("--frames: unknown {name:?} (tfp, adaptive, mc)"))
            })?;
        if !frames.contains(&f) {
            frames.push(f);
        }
    }
    if frames.is_empty() {
        return Err(CliError::Usage("--frames: name at least one".into()));
    }
    let bench = LinkBench {
        seeds: a.seeds,
        pairs: a.pairs,
        every: a.every.clone(),
        tolerance: a.tolerance,
        contrast: a.contrast,
        contrast_mc: a.contrast_mc,
        dwell_cap,
        frames,
    };
    let bar = super::bar(3 * a.seeds, "link benchmark (scene x seed)");
    let rows = link_bench(&bench, || bar.inc(1))?;
    bar.finish_and_clear();
    println!(
        "sidecar link, {} seeds x {} pairs per scene, lossy tolerance {} gray levels (bytes per pair; reduction against the raw spike stream over M ticks)",
        a.seeds, a.pairs, a.tolerance
    );
    println!("| scene | frames | M (ticks) | raw | lossless | × | lossy | × | bits/sample Rice · Context · Sparse · SparseContext | u(y) RMSE lossless (px) | u(y) RMSE lossy (px) | added error | rows lost (lossless/lossy) | exact |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let frames = match r.fallbacks {
            0 => r.frames.name().to_string(),
            n => format!("{} ({n} seeds adaptive: no prediction)", r.frames.name()),
        };
        println!(
            "| {} | {} | {}·dt = {} | {:.0} | {:.0} | {:.1} | {:.0} | {:.1} | {:.2} · {:.2} · {:.2} · {:.2} | {:.4} | {:.4} | {:+.1} % | {}/{} | {} |",
            r.scene,
            frames,
            r.every_dt,
            r.every_ticks,
            r.raw_bytes_per_pair,
            r.lossless_bytes_per_pair,
            r.lossless_reduction,
            r.lossy_bytes_per_pair,
            r.lossy_reduction,
            r.bits_per_sample[0],
            r.bits_per_sample[1],
            r.bits_per_sample[2],
            r.bits_per_sample[3],
            r.rmse_lossless,
            r.rmse_lossy,
            100.0 * r.added_error,
            r.lost_rows_lossless,
            r.lost_rows_lossy,
            if r.lossless_bit_exact { "yes" } else { "NO" }
        );
    }
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&rows).unwrap_or_default();
        std::fs::write(path, text)
            .map_err(|e| CliError::Usage(format!("{}: {e}", path.display())))?;
    }
    if rows.iter().any(|r| !r.lossless_bit_exact) {
        return Err(CliError::Usage(
            "lossless frames were not bit-exact after the link, or the lossy codecs disagreed"
                .into(),
        ));
    }
    Ok(())
}
