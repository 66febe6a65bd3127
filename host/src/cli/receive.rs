//! `spiv receive (--usb [VID:PID] | --tcp ADDR | --pipe | --file PATH) [--out DIR] [--piv [--control [PATH]]]`

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use spiv_host::estimator::ladder::LadderSettings;
use spiv_host::live::{open_downlink, run_live, LiveOptions};
use spiv_host::predict::MotionModel;
use spiv_host::receive::source::{open, parse_vid_pid};
use spiv_host::receive::{FrameLimit, Spec};

use super::CliError;

/// Receive frames from a sidecar; write them and/or run PIV on each pair.
#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["usb", "tcp", "pipe", "file"])))]
pub struct ReceiveArgs {
    /// USB bulk IN from the sidecar (default c0de:cafe).
    #[arg(long, num_args = 0..=1, default_missing_value = "c0de:cafe", value_name = "VID:PID")]
    usb: Option<String>,
    /// Connect to a sidecar listening at ADDR (host:port).
    #[arg(long, value_name = "ADDR")]
    tcp: Option<String>,
    /// Read the message stream from standard input.
    #[arg(long)]
    pipe: bool,
    /// Replay a file of recorded messages.
    #[arg(long, value_name = "PATH")]
    file: Option<PathBuf>,
    /// Write every frame (PNG, upright) and the vectors here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run PIV on every pair received.
    #[arg(long)]
    piv: bool,
    /// After each pair, send the sidecar the motion its PIV measured, for
    /// motion-compensated frames from the next pair on (a sidecar run with
    /// `--method ladder`: the ask of `spiv flow`'s time ladder, its rung
    /// frames along the field measured): back on the TCP connection or
    /// the USB OUT endpoint, or into PATH (a file or FIFO that
    /// `spiv-firmware-sim --control` reads) for --pipe and --file.
    #[arg(long, num_args = 0..=1, value_name = "PATH", requires = "piv")]
    control: Option<Option<PathBuf>>,
    /// The motion model of the controls: auto (per row, or per row and
    /// 64-px tile column where the flow varies along x) or rows.
    #[arg(long, value_enum, default_value_t = MotionModel::Auto, requires = "control")]
    motion_model: MotionModel,
    /// PIV window side of each pass, px (default: 64,32,32, and
    /// 64,32,32,32,32 for motion-compensated pairs; the time ladder's own
    /// for the pairs of a sidecar run with `--method ladder`).
    #[arg(long, value_delimiter = ',')]
    windows: Option<Vec<usize>>,
    /// Largest frame accepted, WxH px: a message claiming a larger (or an
    /// empty) frame is counted as corrupt before anything is allocated.
    #[arg(long, value_name = "WxH", default_value = "8192x8192")]
    max_frame: FrameLimit,
    /// Print the final counts as JSON instead of a line.
    #[arg(long)]
    json: bool,
}

/// Runs it.
pub fn run(a: &ReceiveArgs) -> Result<(), CliError> {
    let spec = if let Some(id) = &a.usb {
        let (v, p) = parse_vid_pid(id).map_err(|e| CliError::Usage(e.to_string()))?;
        Spec::Usb(v, p)
    } else if let Some(t) = &a.tcp {
        Spec::Tcp(t.clone())
    } else if let Some(f) = &a.file {
        Spec::File(f.clone())
    } else {
        Spec::Pipe
    };
    let mut source = open(&spec).map_err(|e| CliError::Usage(e.to_string()))?;
    let downlink = match &a.control {
        None => None,
        Some(path) => Some(open_downlink(source.as_ref(), path.as_deref())?),
    };
    let opts = LiveOptions {
        max_frame: a.max_frame,
        piv_windows: a
            .piv
            .then(|| a.windows.clone().unwrap_or_else(|| vec![64, 32, 32])),
        out: a.out.clone(),
        motion_model: a.motion_model,
        ladder: {
            let mut l = LadderSettings::default();
            if let Some(w) = &a.windows {
                l.piv.windows = w.clone();
            }
            l
        },
    };
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} receiving from {prefix}: {msg} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_prefix(source.name());
    let live = run_live(source.as_mut(), &opts, downlink, |r| {
        bar.set_message(format!(
            "{} frames, {} pairs, {} bytes, {} lost, {} corrupted",
            r.frames, r.pairs, r.bytes, r.lost_frames, r.corrupted
        ));
        bar.tick();
    });
    bar.finish_and_clear();
    let live = live?;
    let report = live.received;
    let vectors = live.vectors;
    if a.json {
        let mut v = serde_json::to_value(report).unwrap_or_default();
        if let (Some(d), Some(m)) = (live.downlink, v.as_object_mut()) {
            m.insert(
                "downlink".into(),
                serde_json::to_value(d).unwrap_or_default(),
            );
        }
        println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
    } else {
        println!(
            "received {} frames ({} pairs{}), {} bytes, {} messages; lost {} frames ({} messages, {} broken pairs); corrupted {}{}",
            report.frames,
            report.pairs,
            if a.piv {
                format!(", {vectors} vectors")
            } else {
                String::new()
            },
            report.bytes,
            report.messages,
            report.lost_frames,
            report.lost_messages,
            report.broken_pairs,
            report.corrupted,
            if report.truncated_tail > 0 {
                format!("; {} bytes of a truncated last message", report.truncated_tail)
            } else {
                String::new()
            }
        );
        if let Some(r) = live.downlink {
            println!(
                "sent {} controls ({} with motion, {} of them on a grid of tile columns){}",
                r.sent,
                r.with_motion,
                r.with_grid,
                if r.failed > 0 {
                    format!("; {} refused by the link", r.failed)
                } else {
                    String::new()
                }
            );
        }
    }
    Ok(())
}
