//! `spiv flow INPUT.dat|.npz [--dt N] [--out DIR] …`: the main job on any
//! spike recording.

use std::path::PathBuf;

use clap::Args;
use spiv_formats::dat::DatOptions;
use spiv_host::flow::{run_flow_until, FlowRequest, Recording};
use spiv_host::reconstruct::FileOptions;
use spiv_host::report::flow::{write_flow, RunInfo};

use super::reconstruct::method_parser;
use super::{bar, parse_dwell_cap, CliError};

/// A field per pair at a fixed schedule, measured from the recording's
/// own spikes around each pair (motion-compensated by default), and their
/// robust mean; one vectors CSV per pair with each vector's uncertainty,
/// the mean field, all of it in one netCDF file (`flow.nc`), plots.
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
    /// Frame method (ladder: the time ladder; adaptive, tfp, tfi: plain
    /// frame pairs).
    #[arg(long, default_value = "ladder", value_parser = method_parser())]
    method: spiv_core::Method,
    /// TFP window, or the adaptive/TFI n_max, ticks (default 128, TFP 8).
    #[arg(long)]
    window: Option<u16>,
    /// Adaptive: blur budget of the closed-loop window caps, px, or "off"
    /// for the paper's algorithm with one n_max everywhere.
    #[arg(long, default_value = spiv_host::dwell::DWELL_CAP_ARG)]
    dwell_cap: String,
    /// PIV window side of each pass, px (default: 64,32,32, and
    /// 64,32,32,32,32,32,32 for motion-compensated pairs).
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
    /// Also write the mean dense flow over the pairs, `mean_dense.flo`
    /// (one vector per pixel, px per pair, v down): each pair's is its
    /// vectors between the nodes or the dense ensemble's flow, refined by
    /// the joint fit of every short frame around it where the pair carries
    /// its events (plain frame methods: the dense stage on the pair's
    /// frames); a pair that measured nothing on frames shorter than the
    /// pair is left out.
    #[arg(long)]
    dense: bool,
    /// With --dense, keep each pair's dense flow as the ladder or the
    /// dense ensemble measured it, without the joint fit of every short
    /// frame around the pair (faster, less accurate).
    #[arg(long, requires = "dense")]
    no_joint: bool,
    /// Pixel size on the object, mm (else from scene.json beside the
    /// recording); with the tick rate, the outputs give m/s beside px per
    /// pair.
    #[arg(long)]
    pixel_size: Option<f64>,
    /// Ticks per second, Hz (else from scene.json beside the recording).
    #[arg(long)]
    tick_hz: Option<f64>,
    /// Mask image (the frames' size, upright; pixels above 0 are left out:
    /// a wall, a body, a region outside the flow). Nodes whose centre is
    /// masked are invalid in every pair.
    #[arg(long)]
    mask: Option<PathBuf>,
    /// Also write `flow.gif`: each pair's speed over time, one colour scale,
    /// the glare marked (at most 240 frames: every k-th pair of a longer
    /// run), 10 frames per second.
    #[arg(long)]
    movie: bool,
    /// Output folder (created if missing).
    #[arg(long, default_value = "spiv-flow")]
    out: PathBuf,
    /// No progress bar (it is drawn only when stderr is a terminal).
    #[arg(long)]
    quiet: bool,
    /// Write the outputs with y up: y = height − 1 − row (0 at the bottom
    /// row's centre), v positive up, vorticity positive counterclockwise;
    /// the figures keep the camera's image and label their axes so
    /// (`mean_dense.flo` keeps the .flo convention, y down).
    #[arg(long)]
    y_up: bool,
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
    let rec = Recording::open(&a.input, &fopts)?;
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
        joint: !a.no_joint,
        pixel_mm: a.pixel_size,
        tick_hz: a.tick_hz,
        pairs: None,
        segment: None,
        mask: a
            .mask
            .as_deref()
            .map(spiv_host::piv::load_mask)
            .transpose()?,
    }
    .options(&rec, &a.input)?;
    let o = spiv_host::flow::FlowOptions { y_up: a.y_up, ..o };
    std::fs::create_dir_all(&a.out)
        .map_err(|e| CliError::Usage(format!("{}: {e}", a.out.display())))?;
    let pairs = o.pair_ticks().len() as u64;
    let b = if a.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        bar(pairs, "pairs")
    };
    let t0 = std::time::Instant::now();
    let stop = super::interrupt()?;
    let out = run_flow_until(&rec, &o, |i, _| b.set_position(i as u64), stop)?;
    b.finish_and_clear();
    if out.pairs.is_empty() {
        return Err(CliError::Interrupted(format!(
            "interrupted before the first of {} pairs was measured; nothing written",
            out.scheduled
        )));
    }
    let command: Vec<String> = std::env::args().collect();
    let command = command.join(" ");
    let info = RunInfo {
        input: &a.input,
        planes: rec.planes,
        seconds: t0.elapsed().as_secs_f64(),
        command: &command,
    };
    write_flow(&a.out, &out, &o, info).map_err(|e| CliError::Usage(e.to_string()))?;
    if a.movie {
        spiv_host::report::movie::write_movie(&a.out.join("flow.gif"), &out, &o)
            .map_err(|e| CliError::Usage(e.to_string()))?;
    }
    println!("{}", run_line(a, &rec, &o, &out, info.seconds));
    if a.dense && out.mean_dense.is_none() {
        eprintln!(
            "warning: --dense: no pair measured a usable field (on frames as long as the pair or shorter ones), so no mean_dense.flo was written"
        );
    }
    let lost = out.lost();
    if !lost.is_none() {
        eprintln!(
            "warning: the core's tables were full: {} regions and {} particle pixels were left as background (summary.json, lost_to_full_tables)",
            lost.regions, lost.pixels
        );
    }
    if out.pairs.len() < out.scheduled {
        return Err(CliError::Interrupted(format!(
            "interrupted: {} of {} pairs measured, written to {}",
            out.pairs.len(),
            out.scheduled,
            a.out.display()
        )));
    }
    Ok(())
}

/// The one line a finished run prints: the recording, the pairs, the
/// vectors valid, the time and where the files went.
fn run_line(
    a: &FlowArgs,
    rec: &Recording,
    o: &spiv_host::flow::FlowOptions,
    out: &spiv_host::flow::FlowOutcome,
    seconds: f64,
) -> String {
    let (mut valid, mut all, mut empty) = (0, 0, 0);
    for p in &out.pairs {
        let (v, r, i) = p.counts();
        valid += v;
        all += v + r + i;
        empty += usize::from(!p.measured());
    }
    format!(
        "{}: {}x{} px, {} planes; {} pair{} {} ticks apart every {} ({}{}): {valid}/{all} vectors valid{}; {:.2} s -> {}",
        a.input.display(),
        out.size.0,
        out.size.1,
        rec.planes,
        out.pairs.len(),
        if out.pairs.len() == 1 { "" } else { "s" },
        o.dt,
        o.every,
        o.method.name(),
        match (o.method, o.dwell_cap) {
            (spiv_core::Method::Adaptive, Some(c)) => format!(" {}, dwell cap {c} px", o.window),
            (spiv_core::Method::Ladder, _) => String::new(),
            _ => format!(" {}", o.window),
        },
        if empty > 0 {
            format!(", {empty} pair(s) measured nothing")
        } else {
            String::new()
        },
        seconds,
        a.out.display()
    )
}
