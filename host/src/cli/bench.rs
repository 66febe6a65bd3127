//! `spiv bench (paper | blasius | speed | link)`: the paper's comparison over
//! seeds, the Blasius validation, and speed against error.

use std::path::PathBuf;
use std::time::Instant;

use clap::{Args, Subcommand};
use ndarray::Array2;
use plotters::prelude::*;
use serde_json::json;
use spiv_firmware_sim::scene::{vector_grid, SceneKind, SceneParams};
use spiv_firmware_sim::simulation::simulate_planes;
use spiv_host::metrics::{mean_ci, region_error, rmae_ratio, row_profile, MeanCi};
use spiv_host::pipeline::{run as run_job, Job, Source};
use spiv_host::piv::{piv, to_f32, Interp, Settings};
use spiv_host::reconstruct::{frame_from_planes, Method, Planes};
use spiv_host::reference::{adaptive_frame, SpikeVolume};

use super::run::label;
use super::{bar, CliError};

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
        #[arg(long, default_value = "8")]
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
}

/// Runs it.
pub fn run(a: &BenchArgs) -> Result<(), CliError> {
    match &a.which {
        Which::Paper {
            seeds,
            json,
            dwell_cap,
        } => paper(
            *seeds,
            json.as_ref(),
            super::run::parse_dwell_cap(dwell_cap)?,
        ),
        Which::Blasius { seeds } => blasius(*seeds),
        Which::Speed { plot } => speed(plot),
        Which::Link(l) => super::bench_link::run(l),
    }
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
    let scenes = [
        (SceneKind::PaperLinear, 0.084, Some(8.594)),
        (SceneKind::PaperQuadratic, 0.028, None),
        (SceneKind::PaperLog, 0.113, None),
    ];
    let b = bar(seeds * scenes.len() as u64, "runs");
    let mut report = Vec::new();
    let mut tables = Vec::new();
    for (kind, paper_rmae, paper_ratio) in scenes {
        // [source][glare rmae, glare rmse, rest rmae, rest rmse]
        let mut acc = vec![[Vec::new(), Vec::new(), Vec::new(), Vec::new()]; 3];
        let mut ratios = vec![[Vec::new(), Vec::new()]; 2];
        for seed in 1..=seeds {
            let mut job = Job::new(SceneParams::new(kind), seed);
            job.dwell_cap = dwell_cap;
            let o = run_job(&job, |_| {})?;
            for (k, x) in o.measured.iter().enumerate() {
                acc[k][0].push(x.glare.rmae);
                acc[k][1].push(x.glare.rmse);
                acc[k][2].push(x.rest.rmae);
                acc[k][3].push(x.rest.rmse);
            }
            let f = &o.measured[0];
            for (k, x) in o.measured[1..].iter().enumerate() {
                ratios[k][0].push(rmae_ratio(f.glare.rmae, x.glare.rmae));
                ratios[k][1].push(rmae_ratio(f.rest.rmae, x.rest.rmae));
            }
            b.inc(1);
        }
        tables.push((kind, paper_rmae, paper_ratio, acc, ratios));
    }
    b.finish_and_clear();
    for (kind, paper_rmae, paper_ratio, acc, ratios) in &tables {
        println!(
            "\n{} — {} seeds, mean ± 95 % CI; glare rows: vector rows within 2σ = 50 px of the wall; adaptive {}",
            kind.name(),
            seeds,
            dwell_cap.map_or("as in the paper (one n_max)".to_string(), |c| format!("with a dwell cap of {c} px"))
        );
        println!(
            "{:<20} | {:>15} {:>15} | {:>15} {:>15}",
            "frames", "glare RMAE", "glare RMSE px", "other RMAE", "other RMSE px"
        );
        let mut rows = Vec::new();
        for (k, s) in Source::ALL.iter().enumerate() {
            let m: Vec<MeanCi> = acc[k].iter().map(|v| mean_ci(v)).collect();
            println!(
                "{:<20} | {:>15} {:>15} | {:>15} {:>15}",
                label(*s, 8),
                fmt(m[0]),
                fmt(m[1]),
                fmt(m[2]),
                fmt(m[3])
            );
            rows.push(json!({"source": s, "glare_rmae": m[0], "glare_rmse": m[1], "rest_rmae": m[2], "rest_rmse": m[3]}));
        }
        for (k, s) in [Source::Tfp, Source::Adaptive].iter().enumerate() {
            let (g, r) = (mean_ci(&ratios[k][0]), mean_ci(&ratios[k][1]));
            println!(
                "{:<20} | {:>15} {:>15} | {:>15}",
                format!("frame/{} RMAE", s.name()),
                fmt(g),
                "",
                fmt(r)
            );
            rows.push(json!({"ratio": s, "glare": g, "rest": r}));
        }
        println!(
            "paper (spike camera, glare rows): RMAE {paper_rmae}{}",
            paper_ratio.map_or(String::new(), |r| format!(", frame/spike ratio {r}"))
        );
        report.push(json!({"scene": kind.name(), "seeds": seeds, "paper_rmae": paper_rmae, "paper_ratio": paper_ratio, "rows": rows}));
    }
    if let Some(p) = json_out {
        std::fs::write(p, serde_json::to_string_pretty(&report).unwrap_or_default())
            .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?;
    }
    Ok(())
}

fn blasius(seeds: u64) -> Result<(), CliError> {
    if seeds == 0 || seeds > 100 {
        return Err(CliError::Usage("--seeds must be in 1..=100".into()));
    }
    let b = bar(seeds, "runs");
    let mut dev = vec![Vec::new(); 3];
    let mut lost = [0usize; 3];
    let mut u_pair = 0.0;
    for seed in 1..=seeds {
        let mut job = Job::new(SceneParams::new(SceneKind::Blasius), seed);
        job.dwell_cap = Some(8.0);
        let o = run_job(&job, |_| {})?;
        let dt = f64::from(o.sim.meta.capture.pair[1] - o.sim.meta.capture.pair[0]);
        u_pair = job.request.scene.top_speed * dt;
        for (k, x) in o.measured.iter().enumerate() {
            let used: Vec<f64> = x
                .rows
                .iter()
                .filter_map(|r| r.measured.map(|m| (m - r.truth).powi(2)))
                .collect();
            lost[k] += x.rows.iter().filter(|r| r.measured.is_none()).count();
            let rms = (used.iter().sum::<f64>() / used.len().max(1) as f64).sqrt();
            dev[k].push(100.0 * rms / u_pair);
        }
        b.inc(1);
    }
    b.finish_and_clear();
    println!(
        "blasius (400x800 px, U = {:.2} px per pair, δ99 = 730 px), {seeds} seed(s): RMS deviation of the row profile from the Blasius solution, % of U (target ≤ 2 %)",
        u_pair
    );
    for (k, s) in Source::ALL.iter().enumerate() {
        println!(
            "{:<20} {:>16} %   rows without a vector: {}",
            label(*s, 8),
            fmt(mean_ci(&dev[k])),
            lost[k]
        );
    }
    Ok(())
}

struct Row {
    name: String,
    ms: f64,
    rmse: f64,
}

fn speed(plot_path: &PathBuf) -> Result<(), CliError> {
    let job = Job::new(SceneParams::new(SceneKind::PaperLinear), 1);
    let p = &job.request.scene;
    let (w, h) = (p.width, p.height);
    let (data, sim) = simulate_planes(&job.request)?;
    let planes = Planes::simulated(w, h, data);
    let [ka, kb] = sim.meta.capture.pair.map(u64::from);
    let dt = (kb - ka) as f64;
    let truth = sim.scene.truth_vectors(&vector_grid(w, h, 32, 16), dt);
    let (wu, hu) = (usize::from(w), usize::from(h));
    let to = |d: &[u16]| to_f32(d, wu, hu);
    // PIV time: the median of 3 runs (the first run of the process also
    // pays for starting the thread pool and touching fresh memory).
    let err = |a: &Array2<f32>, b: &Array2<f32>, s: &Settings| -> Result<(f64, f64), CliError> {
        let mut times = [0.0f64; 3];
        let mut field = None;
        for t in times.iter_mut() {
            let start = Instant::now();
            field = Some(piv(a, b, None, s)?);
            *t = start.elapsed().as_secs_f64() * 1e3;
        }
        times.sort_by(f64::total_cmp);
        let ms = times[1];
        let f = field.ok_or_else(|| CliError::Usage("no PIV run".into()))?;
        let rows = row_profile(&f.vectors(), &truth, f64::from(h));
        Ok((ms, region_error(&rows, |_| true).rmse))
    };
    let mut rows: Vec<Row> = Vec::new();
    let base = job.piv.clone();
    let piv_cfgs = [
        ("PIV 64,32,32 B-spline", base.clone()),
        (
            "PIV 64,32 B-spline",
            Settings {
                windows: vec![64, 32],
                ..base.clone()
            },
        ),
        (
            "PIV 64,32,32 bilinear",
            Settings {
                interp: Interp::Bilinear,
                ..base.clone()
            },
        ),
    ];
    let b = bar(14, "configurations");
    // Frame camera.
    let (fa, fb) = (to(&sim.frames[0]), to(&sim.frames[1]));
    for (name, s) in &piv_cfgs {
        let (ms, e) = err(&fa, &fb, s)?;
        rows.push(Row {
            name: format!("frame camera, {name}"),
            ms,
            rmse: e,
        });
        b.inc(1);
    }
    // Core: TFP and adaptive at several window limits.
    let recon = |m: Method, n: u16| -> Result<(f64, Array2<f32>, Array2<f32>), CliError> {
        let t = Instant::now();
        let a = frame_from_planes(&planes, ka, m, n, &job.core)?;
        let bb = frame_from_planes(&planes, kb, m, n, &job.core)?;
        Ok((t.elapsed().as_secs_f64() * 1e3, to(&a.data), to(&bb.data)))
    };
    for (m, n) in [
        (Method::Tfp, 8),
        (Method::Tfp, 16),
        (Method::Adaptive, 32),
        (Method::Adaptive, 64),
        (Method::Adaptive, 128),
    ] {
        let (rms, a, bb) = recon(m, n)?;
        for (name, s) in &piv_cfgs[..1] {
            let (ms, e) = err(&a, &bb, s)?;
            rows.push(Row {
                name: format!("core {m:?} n={n} (fixed point), {name}"),
                ms: rms + ms,
                rmse: e,
            });
        }
        b.inc(1);
    }
    // Beyond the paper: adaptive windows capped per band by the TFP field.
    for cap in [6.0, 8.0, 16.0] {
        let t = Instant::now();
        let (_, ta, tb) = recon(Method::Tfp, 8)?;
        let tfp_field = piv(&ta, &tb, None, &piv_cfgs[0].1)?;
        let caps = spiv_host::dwell::band_caps(&tfp_field.vectors(), hu, dt, cap, &job.core);
        let a = spiv_host::dwell::adaptive_banded(&planes, ka, &job.core, &caps)?;
        let bb = spiv_host::dwell::adaptive_banded(&planes, kb, &job.core, &caps)?;
        let rec_ms = t.elapsed().as_secs_f64() * 1e3;
        let (ms, e) = err(&to(&a), &to(&bb), &piv_cfgs[0].1)?;
        rows.push(Row {
            name: format!("core Adaptive, dwell cap {cap} px, PIV 64,32,32 B-spline"),
            ms: rec_ms + ms,
            rmse: e,
        });
        b.inc(1);
    }
    // The sidecar as `spiv run` drives it: firmware (core frames, dwell caps
    // from the TFP pair sent through the link), tile coding, the host's
    // decoder and reassembly; lossless and lossy. Time = firmware + wire +
    // receiver for both pairs (TFP and adaptive) + PIV on the adaptive pair.
    for (enc, label) in [
        (spiv_core::wire::Encoding::Rice, "lossless Rice"),
        (spiv_core::wire::Encoding::Sparse, "lossy Sparse"),
    ] {
        use spiv_firmware_sim::firmware::Config;
        let t = Instant::now();
        let mut base = Config::new(ka as u32, (kb - ka) as u32);
        base.params = job.core;
        base.schedule.pairs = Some(1);
        base.encoding = enc;
        let (caps, _) =
            spiv_host::link::dwell_caps(&planes.data, w, h, &base, 8, 8.0, &piv_cfgs[0].1)
                .map_err(|e| CliError::Usage(e.to_string()))?;
        let ad_t = spiv_host::link::transfer(&planes.data, w, h, base, caps)
            .map_err(|e| CliError::Usage(e.to_string()))?;
        let [a, bb] = ad_t
            .pairs
            .first()
            .ok_or_else(|| CliError::Usage("the link delivered no adaptive pair".into()))?;
        let (a, bb) = (
            spiv_host::link::upright_f32(a),
            spiv_host::link::upright_f32(bb),
        );
        let rec_ms = t.elapsed().as_secs_f64() * 1e3;
        let (ms, e) = err(&a, &bb, &piv_cfgs[0].1)?;
        rows.push(Row {
            name: format!(
                "sidecar + wire {label}, {:.0} KB/pair, dwell cap 8 px, PIV 64,32,32",
                ad_t.bytes as f64 / 1e3
            ),
            ms: rec_ms + ms,
            rmse: e,
        });
        b.inc(1);
    }
    // The f64 reference of the adaptive frame.
    let t = Instant::now();
    let vol = SpikeVolume::from_packed(&planes.data, wu, hu, 0);
    let ra = adaptive_frame(&vol, ka as u32, &job.core, f64::from(job.core.full_scale));
    let rb = adaptive_frame(&vol, kb as u32, &job.core, f64::from(job.core.full_scale));
    let ref_ms = t.elapsed().as_secs_f64() * 1e3;
    let up = |v: &[f64]| -> Array2<f32> {
        // The reference works in stored (bottom-up) rows.
        Array2::from_shape_fn((hu, wu), |(i, j)| v[(hu - 1 - i) * wu + j] as f32)
    };
    let (a, bb) = (up(&ra.gray), up(&rb.gray));
    let (ms, e) = err(&a, &bb, &piv_cfgs[0].1)?;
    rows.push(Row {
        name: format!("f64 reference Adaptive n=128, {}", piv_cfgs[0].0),
        ms: ref_ms + ms,
        rmse: e,
    });
    b.finish_and_clear();
    println!("speed against error, paper-linear seed 1 (400x250): wall time per frame pair (reconstruction of both frames + PIV, the PIV a median of 3 runs) and RMSE of the row profile, px per pair");
    println!("{:<76} {:>8} {:>8}", "configuration", "ms/pair", "RMSE px");
    for r in &rows {
        println!("{:<76} {:>8.1} {:>8.3}", r.name, r.ms, r.rmse);
    }
    pareto(plot_path, &rows)
        .map_err(|e| CliError::Usage(format!("{}: {e}", plot_path.display())))?;
    println!("Pareto plot -> {}", plot_path.display());
    Ok(())
}

fn pareto(path: &PathBuf, rows: &[Row]) -> Result<(), String> {
    spiv_host::plot::ensure_font();
    let root = BitMapBackend::new(path, (760, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let tmax = rows.iter().map(|r| r.ms).fold(1.0, f64::max) * 1.3;
    let emax = rows.iter().map(|r| r.rmse).fold(0.1, f64::max) * 1.2;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "speed against error (paper-linear, 400x250)",
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d((1.0..tmax).log_scale(), 0.0..emax)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("ms per frame pair (log)")
        .y_desc("RMSE of u(y), px per pair")
        .draw()
        .map_err(|e| e.to_string())?;
    for r in rows {
        chart
            .draw_series(std::iter::once(Circle::new(
                (r.ms.max(1.0), r.rmse),
                5,
                RED.filled(),
            )))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(std::iter::once(Text::new(
                r.name.split(',').next().unwrap_or("").to_string(),
                (r.ms.max(1.0) * 1.05, r.rmse),
                ("sans-serif", 11),
            )))
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}
