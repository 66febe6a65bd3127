//! `spiv flow INPUT.dat|.npz [--dt N] [--out DIR] …`: the main job on any
//! spike recording.

use std::path::PathBuf;

use clap::Args;
use serde_json::json;
use spiv_formats::dat::DatOptions;
use spiv_formats::image::write_levels;
use spiv_formats::vectors::write_vectors;
use spiv_host::flow::{run_flow, FlowRequest, Recording};
use spiv_host::reconstruct::FileOptions;
use spiv_host::report::plot;

use super::reconstruct::method_parser;
use super::{bar, parse_dwell_cap, CliError};

/// Frame pairs through the core at a fixed schedule, PIV on each, the flow
/// predicted (motion-compensated frames by default); one vectors CSV per
/// pair, the mean field, plots.
#[derive(Debug, Args)]
pub struct FlowArgs {
    /// The spike recording: a Vidar .dat or a .npz capture.
    input: PathBuf,
    /// Width of a .dat's planes, px (else from scene.json beside it).
    #[arg(long)]
    width: Option<u16>,
    /// Height, px.
    #[arg(long)]
    height: Option<u16>,
    /// Ticks between the two frames of a pair (else scene.json's pair).
    #[arg(long)]
    dt: Option<u32>,
    /// Ticks between pairs (default 4·dt).
    #[arg(long)]
    every: Option<u32>,
    /// Tick of the first pair's first frame (default: the first whole
    /// window, n_max/2, or as central as a short recording allows).
    #[arg(long)]
    start: Option<u64>,
    /// No frame at or after this tick (default: the end of the recording).
    #[arg(long)]
    end: Option<u64>,
    /// Frame method.
    #[arg(long, default_value = "mc", value_parser = method_parser())]
    method: spiv_core::Method,
    /// TFP window, or the adaptive/TFI n_max, ticks (default 128, TFP 8).
    #[arg(long)]
    window: Option<u16>,
    /// Adaptive: blur budget of the closed-loop window caps, px, or "off"
    /// for the paper's algorithm with one n_max everywhere.
    #[arg(long, default_value = "8")]
    dwell_cap: String,
    /// Motion-compensated pairs: also measure over a wide baseline, a
    /// second compensated pair this many pair separations apart centred on
    /// the pair, kept per vector where the flow allows it; "off" for the
    /// pair alone.
    #[arg(long, default_value = "4")]
    wide: String,
    /// PIV window side of each pass, px (default: 64,32,32, and
    /// 64,32,32,32,32 for motion-compensated pairs).
    #[arg(long, value_delimiter = ',')]
    windows: Option<Vec<usize>>,
    /// The file's rows are stored upright (some public simulators).
    #[arg(long)]
    no_flip: bool,
    /// Columns to drop at the right of every row (16 for 416-wide captures).
    #[arg(long, default_value_t = 0)]
    strip_head: u16,
    /// Read a file whose last plane is truncated.
    #[arg(long)]
    allow_truncated: bool,
    /// Also run the dense stage on every pair and write its mean,
    /// `mean_dense.flo` (one vector per pixel, px per pair, v down).
    #[arg(long)]
    dense: bool,
    /// Output folder (created if missing).
    #[arg(long, default_value = "spiv-flow")]
    out: PathBuf,
}

/// Runs it.
pub fn run(a: &FlowArgs) -> Result<(), CliError> {
    let fopts = FileOptions {
        width: a.width,
        height: a.height,
        dat: DatOptions {
            flip: !a.no_flip,
            strip_head: a.strip_head,
            allow_truncated: a.allow_truncated,
        },
    };
    let mut rec = Recording::open(&a.input, &fopts).map_err(flow_err)?;
    let o = FlowRequest {
        dt: a.dt,
        every: a.every,
        start: a.start,
        end: a.end,
        method: a.method,
        window: a.window,
        dwell_cap: parse_dwell_cap(&a.dwell_cap)?,
        windows: a.windows.clone(),
        dense: a.dense,
        wide: parse_wide(&a.wide)?,
    }
    .options(&rec, &a.input)
    .map_err(flow_err)?;
    std::fs::create_dir_all(&a.out)
        .map_err(|e| CliError::Usage(format!("{}: {e}", a.out.display())))?;
    let pairs = o.pair_ticks().len() as u64;
    let b = bar(pairs, "pairs");
    let t0 = std::time::Instant::now();
    let out = run_flow(&mut rec, &o, |i, _| b.set_position(i as u64)).map_err(flow_err)?;
    b.finish_and_clear();
    for (i, p) in out.pairs.iter().enumerate() {
        write_vectors(&a.out.join(format!("vectors_{i:05}.csv")), &p.vectors)?;
    }
    if let Some(d) = &out.mean_dense {
        spiv_formats::dense::write_dense(&a.out.join("mean_dense.flo"), d)?;
    }
    let mean = out.mean_field();
    write_vectors(&a.out.join("mean.csv"), &mean)?;
    let (w, h) = out.size;
    for (name, f) in ["pair_a.png", "pair_b.png"].iter().zip(&out.first_frames) {
        write_levels(
            &a.out.join(name),
            u32::from(w),
            u32::from(h),
            f,
            out.full_scale,
        )?;
    }
    let plot_err = |e: plot::PlotError| CliError::Usage(e.to_string());
    plot::vectors(
        &a.out.join("mean_field.png"),
        &out.first_frames[0],
        u32::from(w),
        u32::from(h),
        out.full_scale,
        &mean,
        1.0,
    )
    .map_err(plot_err)?;
    plot::vectors(
        &a.out.join("pair_vectors.png"),
        &out.first_frames[0],
        u32::from(w),
        u32::from(h),
        out.full_scale,
        &out.pairs[0].vectors,
        1.0,
    )
    .map_err(plot_err)?;
    let (mut valid, mut all) = (0, 0);
    let per_pair: Vec<_> = out
        .pairs
        .iter()
        .map(|p| {
            let (v, r, i) = p.counts();
            valid += v;
            all += v + r + i;
            json!({
                "ticks": p.ticks,
                "method": p.method.name(),
                "valid": v, "replaced": r, "invalid": i,
                "bootstrapped": p.bootstrapped,
                "caps": p.caps,
                "wide_ticks": p.wide,
                "lost_to_full_tables": {"regions": p.lost.regions, "pixels": p.lost.pixels},
            })
        })
        .collect();
    let summary = json!({
        "input": a.input.display().to_string(),
        "width": w, "height": h, "planes": rec.planes,
        "method": o.method.name(),
        "window": o.window,
        "dwell_cap_px": o.dwell_cap,
        "wide_baseline": o.wide,
        "dt_ticks": o.dt, "every_ticks": o.every,
        "piv": o.piv,
        "pairs": per_pair,
    });
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary).unwrap_or_default(),
    )
    .map_err(|e| CliError::Usage(format!("summary.json: {e}")))?;
    println!(
        "{}: {w}x{h} px, {} planes; {} pair{} {} ticks apart every {} ({} {}{}): {valid}/{all} vectors valid; {:.2} s -> {}",
        a.input.display(),
        rec.planes,
        out.pairs.len(),
        if out.pairs.len() == 1 { "" } else { "s" },
        o.dt,
        o.every,
        o.method.name(),
        o.window,
        match (o.method, o.dwell_cap) {
            (spiv_core::Method::Adaptive, Some(c)) => format!(", dwell cap {c} px"),
            _ => String::new(),
        },
        t0.elapsed().as_secs_f64(),
        a.out.display()
    );
    let lost = out.lost();
    if !lost.is_none() {
        eprintln!(
            "warning: the core's tables were full: {} regions and {} particle pixels were left as background (summary.json, lost_to_full_tables)",
            lost.regions, lost.pixels
        );
    }
    Ok(())
}

fn flow_err(e: spiv_host::flow::FlowError) -> CliError {
    use spiv_host::flow::FlowError;
    match e {
        FlowError::Format(f) => CliError::Format(f),
        FlowError::Reconstruct(r) => CliError::Reconstruct(r),
        FlowError::Piv(p) => CliError::Piv(p),
        FlowError::Schedule(s) => CliError::Usage(s),
    }
}

/// `--wide`: a separation in pair separations, or "off".
fn parse_wide(s: &str) -> Result<Option<u32>, CliError> {
    if s.eq_ignore_ascii_case("off") {
        return Ok(None);
    }
    s.parse::<u32>().map(Some).map_err(|_| {
        CliError::Usage(format!(
            "--wide {s}: expected a whole number 2..=64, or off"
        ))
    })
}
