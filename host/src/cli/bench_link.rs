//! `spiv bench link`: the options and the table of
//! [`spiv_host::bench::link`].

use std::path::PathBuf;

use clap::Args;
use spiv_host::bench::link::{link_bench, LinkBench};

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
    /// Adaptive window cap against streaks (as `spiv run --dwell-cap`), px
    /// of blur, or "off" for the paper's one n_max everywhere.
    #[arg(long, default_value = "8")]
    dwell_cap: String,
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
    let bench = LinkBench {
        seeds: a.seeds,
        pairs: a.pairs,
        every: a.every.clone(),
        tolerance: a.tolerance,
        contrast: a.contrast,
        dwell_cap,
    };
    let bar = super::bar(3 * a.seeds, "link benchmark (scene x seed)");
    let rows = link_bench(&bench, || bar.inc(1))?;
    bar.finish_and_clear();
    println!(
        "sidecar link, {} seeds x {} pairs per scene, lossy tolerance {} gray levels (bytes per pair; reduction against the raw spike stream over M ticks)",
        a.seeds, a.pairs, a.tolerance
    );
    println!("| scene | M (ticks) | raw | lossless | × | lossy | × | u(y) RMSE lossless (px) | u(y) RMSE lossy (px) | added error | rows lost (lossless/lossy) | lossless bit-exact |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {}·dt = {} | {:.0} | {:.0} | {:.1} | {:.0} | {:.1} | {:.4} | {:.4} | {:+.1} % | {}/{} | {} |",
            r.scene,
            r.every_dt,
            r.every_ticks,
            r.raw_bytes_per_pair,
            r.lossless_bytes_per_pair,
            r.lossless_reduction,
            r.lossy_bytes_per_pair,
            r.lossy_reduction,
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
            "lossless frames were not bit-exact after the link".into(),
        ));
    }
    Ok(())
}
