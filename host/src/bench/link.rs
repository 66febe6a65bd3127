//! `spiv bench link`: what the sidecar link costs and saves. On the paper's
//! scenes, the firmware loop sends pairs every M ticks in the lossless and
//! the lossy mode; the host receives them through its decoder, checks the
//! lossless frames bit-exact against what the firmware made, and runs PIV.
//! Reported per scene and M: bytes per pair, the bandwidth reduction against
//! the raw spike stream over the same ticks (M·W·H/8 bytes per pair), PIV
//! RMSE of the u(y) profile against the truth (the paper's Tables 1–2
//! metric, over all rows; a row with no valid vector counts as 0 and is
//! reported as lost), and the added error RMSE(lossy)/RMSE(lossless) − 1.

use serde::Serialize;
use spiv_core::wire::Encoding;
use spiv_firmware_sim::firmware::Config;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_planes, Request};

use crate::link::{dwell_caps, piv_pairs, transfer};
use crate::metrics::{region_error, row_profile};
use crate::pipeline::{Job, JobError};

/// What the link benchmark runs.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkBench {
    /// Seeds 1..=N per scene.
    pub seeds: u64,
    /// Pairs per stream.
    pub pairs: u32,
    /// M as multiples of the pair's dt.
    pub every: Vec<u32>,
    /// Lossy mode: largest error of a background sample, gray levels.
    pub tolerance: u16,
    /// Lossy mode: contrast rule (0: off).
    pub contrast: u16,
    /// Dwell cap, px of blur (`None`: one n_max everywhere).
    pub dwell_cap: Option<f64>,
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

/// One scene and M.
#[derive(Debug, Clone, Serialize)]
pub struct LinkRow {
    /// Scene name.
    pub scene: String,
    /// M in multiples of dt.
    pub every_dt: u32,
    /// M, ticks.
    pub every_ticks: u32,
    /// Pairs received in both modes.
    pub pairs: usize,
    /// Raw spike bytes over M ticks.
    pub raw_bytes_per_pair: f64,
    /// Lossless (Rice) bytes per pair.
    pub lossless_bytes_per_pair: f64,
    /// Raw over lossless.
    pub lossless_reduction: f64,
    /// Lossy (sparse) bytes per pair.
    pub lossy_bytes_per_pair: f64,
    /// Raw over lossy.
    pub lossy_reduction: f64,
    /// u(y) RMSE through the lossless link, px per pair.
    pub rmse_lossless: f64,
    /// u(y) RMSE through the lossy link, px per pair.
    pub rmse_lossy: f64,
    /// Rows without a valid vector, lossless.
    pub lost_rows_lossless: usize,
    /// Rows without a valid vector, lossy.
    pub lost_rows_lossy: usize,
    /// RMSE(lossy)/RMSE(lossless) − 1.
    pub added_error: f64,
    /// Every lossless frame arrived as the firmware made it.
    pub lossless_bit_exact: bool,
}

/// Runs the benchmark on the three paper scenes; `progress` is called after
/// each scene × seed.
pub fn link_bench(b: &LinkBench, mut progress: impl FnMut()) -> Result<Vec<LinkRow>, JobError> {
    let scenes = [
        SceneKind::PaperLinear,
        SceneKind::PaperQuadratic,
        SceneKind::PaperLog,
    ];
    let mut rows = Vec::new();
    for kind in scenes {
        let mut acc = vec![Acc::default(); b.every.len()];
        let p = SceneParams::new(kind);
        let (w, h, dt) = (p.width, p.height, p.pair_dt);
        for seed in 1..=b.seeds {
            let job = Job::new(p.clone(), seed);
            let mut base = Config::new(u32::from(job.core.n_max / 2), dt);
            base.params = job.core;
            base.schedule.pairs = Some(b.pairs);
            base.lossy.tolerance = b.tolerance;
            base.lossy.contrast = b.contrast;
            let max_every = b.every.iter().max().copied().unwrap_or(4) * dt;
            let mut req = Request::new(p.clone(), seed);
            let mut longest = base;
            longest.schedule.every = max_every;
            req.ticks = Some(longest.ticks_for(b.pairs));
            let (planes, sim) = simulate_planes(&req)?;
            let truth = sim
                .scene
                .truth_vectors(&job.piv.centres(w, h), f64::from(dt));
            let mut caps = Vec::new();
            if let Some(budget) = b.dwell_cap {
                // The caps come from a TFP pair sent through the link first,
                // as a sidecar would be told them over the control endpoint.
                (caps, _) = dwell_caps(&planes, w, h, &base, job.tfp_window, budget, &job.piv)?;
            }
            for (i, &f) in b.every.iter().enumerate() {
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
                )?;
                let lossy = transfer(
                    &planes,
                    w,
                    h,
                    Config {
                        encoding: Encoding::Sparse,
                        ..cfg
                    },
                    caps.clone(),
                )?;
                let exact = lossless.pairs.len() == b.pairs as usize
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
                    for field in piv_pairs(&t.pairs, &job.piv)? {
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
            progress();
        }
        for (i, &f) in b.every.iter().enumerate() {
            let e = &acc[i];
            let npairs = (b.seeds * u64::from(b.pairs)) as f64;
            let m = f * dt;
            let raw = f64::from(m) * f64::from(w) * f64::from(h) / 8.0;
            let (bl, by) = (e.bytes[0] as f64 / npairs, e.bytes[1] as f64 / npairs);
            let (rl, ry) = (
                (e.sq[0] / e.n[0] as f64).sqrt(),
                (e.sq[1] / e.n[1] as f64).sqrt(),
            );
            rows.push(LinkRow {
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
    Ok(rows)
}

fn kind_name(k: SceneKind) -> String {
    SceneKind::ALL
        .iter()
        .find(|(_, kk)| *kk == k)
        .map(|(n, _)| (*n).to_string())
        .unwrap_or_default()
}
