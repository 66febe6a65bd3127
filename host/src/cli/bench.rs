//! `spiv bench (paper | blasius | speed | link | turbulence | flows | live)`: the
//! paper's comparison over seeds, the Blasius validation, speed against
//! error, the link, PIV against eddies below the window, and `spiv flow`
//! on every scene family, and the live loop beside it.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use spiv_host::bench::flows::FlowRun;
use spiv_host::bench::paper::{blasius_bench, paper_bench, PAPER};
use spiv_host::metrics::MeanCi;

use super::{bar, CliError};
use spiv_host::report::table::label;

/// Benchmarks.
#[derive(Debug, Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    which: Which,
}

#[derive(Debug, Subcommand)]
enum Which {
    /// Tables 1–2 of the paper for the three profiles over N seeds.
    Paper {
        /// Seeds 1..=N.
        #[arg(long, default_value_t = 5)]
        seeds: u64,
        /// Write the results as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Beyond the paper: cap adaptive windows to this blur, px, or "off"
        /// for the paper's algorithm (see `spiv run`).
        #[arg(long, default_value = spiv_host::dwell::DWELL_CAP_ARG)]
        dwell_cap: String,
    },
    /// The Blasius boundary layer: measured u(y) against the solution.
    Blasius {
        /// Seeds 1..=N.
        #[arg(long, default_value_t = 1)]
        seeds: u64,
    },
    /// The sidecar link: bandwidth reduction and added PIV error per mode and M.
    Link(super::bench_link::LinkArgs),
    /// Speed against error: configurations of the core and PIV.
    Speed {
        /// Pareto plot (PNG).
        #[arg(long, default_value = "speed.png")]
        plot: PathBuf,
    },
    /// Window PIV and the dense stage on the turbulence and large-shift
    /// scenes (frame camera and spike TFP pairs) against the dense truth:
    /// EPE, outliers (> 3 px), time. OpenPIV: bench/openpiv_compare.sh.
    Turbulence {
        /// Seed of the particles.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Also write the rows as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Every scene family through `spiv flow` with its defaults against
    /// the dense truth, beside the frame camera and TFP 8 through `spiv
    /// piv`: EPE in glare and other rows, flagged share, uncertainty
    /// coverage, dense EPE, time per pair.
    Flows {
        /// Seeds: "101-110" (the report's), "1-5" (tuning), or a list.
        #[arg(long, default_value = "101-110")]
        seeds: String,
        /// Families (default: all), comma separated, e.g.
        /// "vortex-array 0.3,turbulence".
        #[arg(long, value_delimiter = ',')]
        families: Option<Vec<String>>,
        /// Also write every row as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Append every vector of `spiv flow` (errors, uncertainties) to
        /// this CSV, for fitting an uncertainty model on tuning seeds.
        #[arg(long)]
        vectors: Option<PathBuf>,
        /// Run `spiv flow --dense` instead (the row "spiv flow --dense"):
        /// its dense column is the EPE of the dense field it writes
        /// (`mean_dense.flo`), not of its vectors interpolated.
        #[arg(long)]
        dense: bool,
        /// With --dense, `spiv flow --dense --no-joint` instead (the row
        /// "spiv flow --dense --no-joint"): each pair's dense flow as the
        /// ladder or the dense ensemble measured it.
        #[arg(long, requires = "dense")]
        no_joint: bool,
    },
    /// Every scene family through the live loop (asks 1 and 3 pairs
    /// late, 1 late with 10 % lost, or 1 late with 5 % lost and 5 %
    /// corrupted) beside `spiv flow` on the same
    /// recording: EPE in glare and other rows after the third pair,
    /// flagged share, bytes per pair on the wire against the raw spikes.
    Live {
        /// Seeds: "101-110" (the report's), "1-5" (tuning), or a list.
        #[arg(long, default_value = "101-110")]
        seeds: String,
        /// Families (default: all), comma separated.
        #[arg(long, value_delimiter = ',')]
        families: Option<Vec<String>>,
        /// Pairs scored per recording, after the first three (1–200).
        #[arg(long, default_value_t = 8)]
        pairs: usize,
        /// Also write every row as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
}

/// Runs it.
pub fn run(a: &BenchArgs) -> Result<(), CliError> {
    match &a.which {
        Which::Paper {
            seeds,
            json,
            dwell_cap,
        } => paper(*seeds, json.as_ref(), super::parse_dwell_cap(dwell_cap)?),
        Which::Blasius { seeds } => blasius(*seeds),
        Which::Speed { plot } => speed(plot),
        Which::Link(l) => super::bench_link::run(l),
        Which::Turbulence { seed, json } => turbulence(*seed, json.as_ref()),
        Which::Flows {
            seeds,
            families,
            json,
            vectors,
            dense,
            no_joint,
        } => flows(
            seeds,
            families.as_deref(),
            json.as_ref(),
            vectors.as_deref(),
            match (*dense, *no_joint) {
                (false, _) => FlowRun::Vectors,
                (true, false) => FlowRun::Dense,
                (true, true) => FlowRun::DenseNoJoint,
            },
        ),
        Which::Live {
            seeds,
            families,
            pairs,
            json,
        } => live(seeds, families.as_deref(), *pairs, json.as_ref()),
    }
}

/// The mean of the values present, `None` when none is.
fn mean(xs: Vec<Option<f64>>) -> Option<f64> {
    let v: Vec<f64> = xs.into_iter().flatten().collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Three decimals, or "-" for nothing.
fn f3(x: Option<f64>) -> String {
    x.map_or("-".to_string(), |x| format!("{x:.3}"))
}

/// The mean of the values present (three decimals), with how many there
/// were in brackets when some are missing ("0.923 (8)" of 10 seeds), so
/// that a mean over fewer members says so; "-" for none.
fn of_some(xs: Vec<Option<f64>>) -> String {
    let n = xs.iter().flatten().count();
    let all = xs.len();
    match mean(xs) {
        Some(m) if n < all => format!("{m:.3} ({n})"),
        m => f3(m),
    }
}

/// Seeds from "A-B", "N" or "A,B,C": each 1..=1_000_000, at most 1000.
fn parse_seeds(s: &str) -> Result<Vec<u64>, CliError> {
    let bad = || CliError::Usage(format!("--seeds {s}: expected A-B, N or a list like 1,2,7"));
    let num = |t: &str| t.trim().parse::<u64>().map_err(|_| bad());
    let out: Vec<u64> = if let Some((a, b)) = s.split_once('-') {
        let (a, b) = (num(a)?, num(b)?);
        if a > b {
            return Err(bad());
        }
        (a..=b).collect()
    } else {
        s.split(',').map(num).collect::<Result<_, _>>()?
    };
    if out.is_empty() || out.len() > 1000 || out.iter().any(|&x| x == 0 || x > 1_000_000) {
        return Err(bad());
    }
    Ok(out)
}

/// The families named by `--families` (all without it).
fn chosen_families(
    only: Option<&[String]>,
) -> Result<Vec<spiv_host::bench::flows::Family>, CliError> {
    use spiv_host::bench::flows::families;
    let fams: Vec<_> = families()
        .into_iter()
        .filter(|f| only.is_none_or(|o| o.iter().any(|n| n.trim() == f.name)))
        .collect();
    if fams.is_empty() {
        let names: Vec<String> = families().into_iter().map(|f| f.name).collect();
        return Err(CliError::Usage(format!(
            "--families: none of {}",
            names.join(", ")
        )));
    }
    Ok(fams)
}

fn live(
    seeds: &str,
    only: Option<&[String]>,
    pairs: usize,
    json_out: Option<&PathBuf>,
) -> Result<(), CliError> {
    use spiv_host::bench::live::{live_rows, modes, LiveRow};
    if !(1..=200).contains(&pairs) {
        return Err(CliError::Usage(format!(
            "--pairs {pairs}: expected 1..=200"
        )));
    }
    let seeds = parse_seeds(seeds)?;
    let fams = chosen_families(only)?;
    let b = bar((fams.len() * seeds.len()) as u64, "recordings");
    let mut rows: Vec<LiveRow> = Vec::new();
    for f in &fams {
        for &seed in &seeds {
            rows.extend(live_rows(f, seed, pairs)?);
            b.inc(1);
        }
    }
    b.finish_and_clear();
    println!(
        "seeds {:?}; EPE px per pair of measured vectors, pairs after the third (mean over seeds); bytes: a pair's frames and events on the wire",
        seeds
    );
    println!(
        "{:<17} {:<31} {:>9} {:>9} {:>8} {:>12} {:>9}",
        "family", "mode", "glare", "other", "flagged", "bytes/pair", "raw/wire"
    );
    for f in &fams {
        for (mode, _) in modes(0) {
            let rs: Vec<&LiveRow> = rows
                .iter()
                .filter(|r| r.family == f.name && r.mode == mode)
                .collect();
            let bytes = mean(rs.iter().map(|r| Some(r.bytes_per_pair)).collect()).unwrap_or(0.0);
            let raw = mean(rs.iter().map(|r| Some(r.raw_per_pair)).collect()).unwrap_or(0.0);
            println!(
                "{:<17} {:<31} {:>9} {:>9} {:>7.1}% {:>12.0} {:>8.1}x",
                f.name,
                mode,
                f3(mean(rs.iter().map(|r| r.glare).collect())),
                f3(mean(rs.iter().map(|r| r.other).collect())),
                100.0 * mean(rs.iter().map(|r| Some(r.flagged)).collect()).unwrap_or(0.0),
                bytes,
                if bytes > 0.0 { raw / bytes } else { 0.0 },
            );
        }
    }
    if pairs >= 150 {
        // Drift: the last 50 scored pairs against pairs 51–100.
        println!("drift: EPE of the last 50 pairs / pairs 51-100 (mean over seeds)");
        for f in &fams {
            for (mode, _) in modes(0) {
                let ratios: Vec<Option<f64>> = rows
                    .iter()
                    .filter(|r| r.family == f.name && r.mode == mode)
                    .map(|r| {
                        let n = r.per_pair.len();
                        match (r.epe_over(n.saturating_sub(50)..n), r.epe_over(50..100)) {
                            (Some(a), Some(b)) if b > 0.0 => Some(a / b),
                            _ => None,
                        }
                    })
                    .collect();
                println!("{:<17} {:<31} {:>9}", f.name, mode, f3(mean(ratios)));
            }
        }
    }
    if let Some(p) = json_out {
        std::fs::write(p, serde_json::to_string_pretty(&rows).unwrap_or_default())
            .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?;
    }
    Ok(())
}

fn flows(
    seeds: &str,
    only: Option<&[String]>,
    json_out: Option<&PathBuf>,
    vectors: Option<&Path>,
    run: FlowRun,
) -> Result<(), CliError> {
    use spiv_host::bench::flows::{family_rows, worst, FlowsRow};
    let seeds = parse_seeds(seeds)?;
    let fams = chosen_families(only)?;
    let b = bar((fams.len() * seeds.len()) as u64, "recordings");
    let mut rows: Vec<FlowsRow> = Vec::new();
    for f in &fams {
        for &seed in &seeds {
            rows.extend(family_rows(f, seed, vectors, run)?);
            b.inc(1);
        }
    }
    b.finish_and_clear();
    // The method column fits the longest method name.
    let mw = run.name().len().max(13);
    println!(
        "seeds {:?}; EPE px per pair of measured vectors (mean over seeds); worst: the seed whose measured vectors are furthest off, their EPE; coverage: error components within 1σ; >3σ: valid vectors off by more than 3σ and 0.3 px",
        seeds
    );
    println!(
        "{:<19} {:<mw$} {:>9} {:>9} {:>13} {:>8} {:>9} {:>6} {:>9} {:>10} {:>9}",
        "family",
        "method",
        "glare",
        "other",
        "worst",
        "flagged",
        "coverage",
        ">3σ",
        "dense",
        "mean |d|",
        "ms/pair"
    );
    for f in &fams {
        let flow = run.name();
        for method in ["frame camera", "TFP 8", flow] {
            let rs: Vec<&FlowsRow> = rows
                .iter()
                .filter(|r| r.family == f.name && r.method == method)
                .collect();
            let worst = worst(&rs).map_or("-".into(), |r| {
                format!("{:.3} s{}", r.measured.unwrap_or(f64::NAN), r.seed)
            });
            println!(
                "{:<19} {:<mw$} {:>9} {:>9} {:>13} {:>7.1}% {:>9} {:>6} {:>9} {:>10.2} {:>9.1}",
                f.name,
                method,
                f3(mean(rs.iter().map(|r| r.glare).collect())),
                f3(mean(rs.iter().map(|r| r.other).collect())),
                worst,
                100.0 * mean(rs.iter().map(|r| Some(r.flagged)).collect()).unwrap_or(0.0),
                mean(rs.iter().map(|r| r.coverage).collect())
                    .map_or("-".into(), |c| format!("{:.0}%", 100.0 * c)),
                mean(rs.iter().map(|r| r.beyond_3sigma).collect())
                    .map_or("-".into(), |c| format!("{:.1}%", 100.0 * c)),
                of_some(rs.iter().map(|r| r.dense).collect()),
                mean(rs.iter().map(|r| Some(r.mean_truth)).collect()).unwrap_or(0.0),
                mean(rs.iter().map(|r| Some(r.ms_per_pair)).collect()).unwrap_or(0.0),
            );
        }
    }
    for f in &fams {
        members(&rows, &f.name, run.name());
    }
    if let Some(p) = json_out {
        std::fs::write(p, serde_json::to_string_pretty(&rows).unwrap_or_default())
            .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?;
    }
    Ok(())
}

/// The table of a family whose seeds are members of their own (the
/// spectral turbulence): one line per seed with what it drew and the
/// dense EPE of each method; nothing for the other families.
fn members(rows: &[spiv_host::bench::flows::FlowsRow], family: &str, flow: &str) {
    let of = |seed: u64, method: &str| {
        rows.iter()
            .find(|r| r.family == family && r.seed == seed && r.method == method)
    };
    let mut seeds: Vec<u64> = rows
        .iter()
        .filter(|r| r.family == family && r.member.is_some())
        .map(|r| r.seed)
        .collect();
    seeds.dedup();
    if seeds.is_empty() {
        return;
    }
    println!(
        "\n{family}, each seed a member: smallest eddy px, rms px per pair, particles per 32² cell, diameters px, light thresholds/tick, sheet px, out-of-plane travel per pair / sheet, turnover rate; dense EPE px per pair; {flow}: measured EPE, coverage, >3σ"
    );
    println!(
        "{:>5} {:>6} {:>6} {:>5} {:>9} {:>6} {:>6} {:>6} {:>5} {:>8} {:>8} {:>8} {:>8} {:>9} {:>9} {:>6}",
        "seed", "eddy", "rms", "cell", "d", "light", "sheet", "w", "rate", "|d|",
        "frame", "TFP 8", "dense", "measured", "coverage", ">3σ"
    );
    for seed in seeds {
        let Some(r) = of(seed, flow) else { continue };
        let Some(m) = r.member else { continue };
        let dense = |method: &str| f3(of(seed, method).and_then(|r| r.dense));
        println!(
            "{:>5} {:>6.1} {:>6.2} {:>5} {:>9} {:>6.3} {:>6.1} {:>6.2} {:>5.2} {:>8.2} {:>8} {:>8} {:>8} {:>9} {:>9} {:>6}",
            seed,
            m.smallest_eddy,
            m.rms_shift,
            m.per_cell,
            format!("{:.1}-{:.1}", m.diameter.0, m.diameter.1),
            m.particle_peak,
            m.sheet,
            m.out_of_plane,
            m.evolution,
            r.mean_truth,
            dense("frame camera"),
            dense("TFP 8"),
            f3(r.dense),
            f3(r.measured),
            r.coverage.map_or("-".into(), |c| format!("{:.0}%", 100.0 * c)),
            r.beyond_3sigma
                .map_or("-".into(), |c| format!("{:.1}%", 100.0 * c)),
        );
    }
}

fn turbulence(seed: u64, json_out: Option<&PathBuf>) -> Result<(), CliError> {
    use spiv_host::bench::turbulence::turbulence_rows;
    let rows = turbulence_rows(seed)?;
    println!(
        "{:<12} {:<13} {:<27} {:>13} {:>9} {:>9} {:>9} {:>9}",
        "scene", "frames", "method", "measured", "EPE px", "> 3 px", "mean |d|", "ms"
    );
    for r in &rows {
        let f = |v: Option<f64>, d: usize| v.map_or("-".to_string(), |x| format!("{x:.d$}"));
        println!(
            "{:<12} {:<13} {:<27} {:>13} {:>9} {:>9} {:>9.2} {:>9.1}",
            r.scene,
            r.frames,
            r.method,
            format!("{}/{}", r.measured.0, r.measured.1),
            f(r.epe, 3),
            f(r.outliers.map(|o| 100.0 * o), 1),
            r.mean_displacement,
            r.ms
        );
    }
    if let Some(p) = json_out {
        std::fs::write(p, serde_json::to_string_pretty(&rows).unwrap_or_default())
            .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?;
    }
    Ok(())
}

fn fmt(m: MeanCi) -> String {
    format!("{:.3} ± {:.3}", m.mean, m.ci95)
}

fn paper(seeds: u64, json_out: Option<&PathBuf>, dwell_cap: Option<f64>) -> Result<(), CliError> {
    if dwell_cap.is_some_and(|c| !(c.is_finite() && c > 0.0 && c <= 1000.0)) {
        return Err(CliError::Usage(
            "--dwell-cap: expected 0 < px <= 1000".into(),
        ));
    }
    if seeds == 0 || seeds > 1000 {
        return Err(CliError::Usage("--seeds must be in 1..=1000".into()));
    }
    let b = bar(seeds * PAPER.len() as u64, "runs");
    let tables = paper_bench(seeds, dwell_cap, || b.inc(1))?;
    b.finish_and_clear();
    for t in &tables {
        println!(
            "\n{} — {} seeds, mean ± 95 % CI; glare rows: vector rows within 2σ = 50 px of the wall; adaptive {}",
            t.scene.name(),
            seeds,
            dwell_cap.map_or("as in the paper (one n_max)".to_string(), |c| format!("with a dwell cap of {c} px"))
        );
        println!(
            "{:<20} | {:>15} {:>15} | {:>15} {:>15}",
            "frames", "glare RMAE", "glare RMSE px", "other RMAE", "other RMSE px"
        );
        for r in &t.rows {
            println!(
                "{:<20} | {:>15} {:>15} | {:>15} {:>15}",
                label(r.source, 8),
                fmt(r.glare_rmae),
                fmt(r.glare_rmse),
                fmt(r.rest_rmae),
                fmt(r.rest_rmse)
            );
        }
        for r in &t.ratios {
            println!(
                "{:<20} | {:>15} {:>15} | {:>15}",
                format!("frame/{} RMAE", r.ratio.name()),
                fmt(r.glare),
                "",
                fmt(r.rest)
            );
        }
        println!(
            "paper (spike camera, glare rows): RMAE {}{}",
            t.paper_rmae,
            t.paper_ratio
                .map_or(String::new(), |r| format!(", frame/spike ratio {r}"))
        );
    }
    if let Some(p) = json_out {
        std::fs::write(p, serde_json::to_string_pretty(&tables).unwrap_or_default())
            .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?;
    }
    Ok(())
}

fn blasius(seeds: u64) -> Result<(), CliError> {
    if seeds == 0 || seeds > 100 {
        return Err(CliError::Usage("--seeds must be in 1..=100".into()));
    }
    let b = bar(seeds, "runs");
    let r = blasius_bench(seeds, || b.inc(1))?;
    b.finish_and_clear();
    println!(
        "blasius (400x800 px, U = {:.2} px per pair, δ99 = 730 px), {seeds} seed(s): RMS deviation of the row profile from the Blasius solution, % of U (target ≤ 2 %)",
        r.u_pair
    );
    for (k, dev, lost) in &r.rows {
        println!(
            "{:<20} {:>16} %   rows without a vector: {}",
            label(*k, 8),
            fmt(*dev),
            lost
        );
    }
    Ok(())
}

fn speed(plot_path: &Path) -> Result<(), CliError> {
    let b = bar(18, "configurations");
    let rows = spiv_host::bench::speed::speed_against_error(|| b.inc(1))?;
    b.finish_and_clear();
    println!("speed against error, paper-linear seed 1 (400x250): wall time per frame pair (reconstruction of both frames + PIV, the PIV a median of 3 runs) and RMSE of the row profile, px per pair");
    println!("{:<76} {:>8} {:>8}", "configuration", "ms/pair", "RMSE px");
    for r in &rows {
        println!("{:<76} {:>8.1} {:>8.3}", r.name, r.ms, r.rmse);
    }
    spiv_host::bench::speed::pareto(plot_path, &rows)
        .map_err(|e| CliError::Usage(e.to_string()))?;
    println!("Pareto plot -> {}", plot_path.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mean over fewer members than asked says how many it had.
    #[test]
    fn a_mean_over_some_members_says_how_many() {
        assert_eq!(of_some(vec![Some(1.0), Some(2.0)]), "1.500");
        assert_eq!(of_some(vec![Some(1.0), None, Some(2.0)]), "1.500 (2)");
        assert_eq!(of_some(vec![None, None]), "-");
        assert_eq!(of_some(vec![]), "-");
    }
}
