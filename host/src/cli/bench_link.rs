//! `spiv bench link`: what the sidecar link costs and saves. On the paper's
//! scenes, the firmware loop sends pairs every M ticks in the lossless and
//! the lossy mode; the host receives them through its decoder, checks the
//! lossless frames bit-exact against what the firmware made, and runs PIV.
//! Reported per scene and M: bytes per pair, the bandwidth reduction against
//! the raw spike stream over the same ticks (M·W·H/8 bytes per pair), PIV
//! RMSE of the u(y) profile against the truth (the paper's Tables 1–2
//! metric, over all rows; a row with no valid vector counts as 0 and is
//! reported as lost), and the added error RMSE(lossy)/RMSE(lossless) − 1.

use std::path::PathBuf;

use clap::Args;
use serde::Serialize;
use spiv_core::wire::Encoding;
use spiv_firmware_sim::firmware::Config;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_host::link::{dwell_caps, piv_pairs, transfer, LinkError};
use spiv_host::metrics::{region_error, row_profile};
use spiv_host::pipeline::Job;

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

/// Sums over seeds for one M: [lossless, lossy].
#[derive(Debug, Clone, Default)]
struct Acc {
    bytes: [u64; 2],
    sq: [f64; 2],
    n: [usize; 2],
    lost: [usize; 2],
    pairs: usize,
    inexact: bool,
}

#[derive(Debug, Clone, Serialize)]
struct Row {
    scene: String,
    every_dt: u32,
    every_ticks: u32,
    pairs: usize,
    raw_bytes_per_pair: f64,
    lossless_bytes_per_pair: f64,
    lossless_reduction: f64,
    lossy_bytes_per_pair: f64,
    lossy_reduction: f64,
    rmse_lossless: f64,
    rmse_lossy: f64,
    lost_rows_lossless: usize,
    lost_rows_lossy: usize,
    added_error: f64,
    lossless_bit_exact: bool,
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
    let scenes = [
        SceneKind::PaperLinear,
        SceneKind::PaperQuadratic,
        SceneKind::PaperLog,
    ];
    let bar = super::bar(
        scenes.len() as u64 * a.seeds,
        "link benchmark (scene x seed)",
    );
    let mut rows = Vec::new();
    for kind in scenes {
        let mut acc = vec![Acc::default(); a.every.len()];
        let p = SceneParams::new(kind);
        let (w, h, dt) = (p.width, p.height, p.pair_dt);
        for seed in 1..=a.seeds {
            let job = Job::new(p.clone(), seed);
            let mut base = Config::new(u32::from(job.core.n_max / 2), dt);
            base.params = job.core;
            base.schedule.pairs = Some(a.pairs);
            base.lossy.tolerance = a.tolerance;
            base.lossy.contrast = a.contrast;
            let max_every = a.every.iter().max().copied().unwrap_or(4) * dt;
            let mut req = Request::new(p.clone(), seed);
            let mut longest = base;
            longest.schedule.every = max_every;
            req.ticks = Some(longest.ticks_for(a.pairs));
            let (planes, sim) = simulate_planes(&req)?;
            let truth = sim
                .scene
                .truth_vectors(&job.piv.centres(w, h), f64::from(dt));
            let mut caps = Vec::new();
            if let Some(budget) = dwell_cap {
                // The caps come from a TFP pair sent through the link first,
                // as a sidecar would be told them over the control endpoint.
                (caps, _) = dwell_caps(&planes, w, h, &base, job.tfp_window, budget, &job.piv)
                    .map_err(link_err)?;
            }
            for (i, &f) in a.every.iter().enumerate() {
                let mut cfg = base;
                cfg.schedule.every = f * dt;
                let lossless = transfer(
                    &planes,
                    w,
                    h,
                    Config {
                        encoding: Encoding::Rice,
                        ..cfg
                    },
                    caps.clone(),
                )
                .map_err(link_err)?;
                let lossy = transfer(
                    &planes,
                    w,
                    h,
                    Config {
                        encoding: Encoding::Sparse,
                        ..cfg
                    },
                    caps.clone(),
                )
                .map_err(link_err)?;
                let exact = lossless.pairs.len() == a.pairs as usize
                    && lossless.pairs.iter().flatten().all(|r| {
                        lossless
                            .sent
                            .iter()
                            .any(|s| s.frame_id == r.frame_id && s.data == r.data)
                    });
                let e = &mut acc[i];
                e.bytes[0] += lossless.bytes;
                e.bytes[1] += lossy.bytes;
                e.inexact |= !exact;
                e.pairs += lossless.pairs.len().min(lossy.pairs.len());
                for (mode, t) in [&lossless, &lossy].into_iter().enumerate() {
                    for field in piv_pairs(&t.pairs, &job.piv).map_err(link_err)? {
                        // The paper's metric (Tables 1–2): the u(y) profile
                        // of the valid vectors, a lost row counting as 0.
                        let rows = row_profile(&field, &truth, f64::from(h));
                        let r = region_error(&rows, |_| true);
                        e.sq[mode] += r.rmse.powi(2) * r.rows as f64;
                        e.n[mode] += r.rows;
                        e.lost[mode] += r.lost;
                    }
                }
            }
            bar.inc(1);
        }
        for (i, &f) in a.every.iter().enumerate() {
            let e = &acc[i];
            let npairs = (a.seeds * u64::from(a.pairs)) as f64;
            let m = f * dt;
            let raw = f64::from(m) * f64::from(w) * f64::from(h) / 8.0;
            let (bl, by) = (e.bytes[0] as f64 / npairs, e.bytes[1] as f64 / npairs);
            let (rl, ry) = (
                (e.sq[0] / e.n[0] as f64).sqrt(),
                (e.sq[1] / e.n[1] as f64).sqrt(),
            );
            rows.push(Row {
                scene: kind_name(kind),
                every_dt: f,
                every_ticks: m,
                pairs: e.pairs,
                raw_bytes_per_pair: raw,
                lossless_bytes_per_pair: bl,
                lossless_reduction: raw / bl,
                lossy_bytes_per_pair: by,
                lossy_reduction: raw / by,
                rmse_lossless: rl,
                rmse_lossy: ry,
                lost_rows_lossless: e.lost[0],
                lost_rows_lossy: e.lost[1],
                added_error: ry / rl - 1.0,
                lossless_bit_exact: !e.inexact,
            });
        }
    }
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

fn kind_name(k: SceneKind) -> String {
    SceneKind::ALL
        .iter()
        .find(|(_, kk)| *kk == k)
        .map(|(n, _)| (*n).to_string())
        .unwrap_or_default()
}

fn link_err(e: LinkError) -> CliError {
    CliError::Usage(e.to_string())
}
