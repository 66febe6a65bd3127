//! `spiv receive (--usb [VID:PID] | --tcp ADDR | --pipe | --file PATH) [--out DIR] [--piv [--control [PATH]]]`

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use spiv_formats::image::write_levels;
use spiv_formats::vectors::write_vectors;
use spiv_host::downlink::{control_for, Downlink};
use spiv_host::link::{receiver_settings, upright_f32};
use spiv_host::piv::piv;
use spiv_host::receive::source::{open, parse_vid_pid};
use spiv_host::receive::{receive, Event, FrameLimit, ReceivedFrame, Spec};

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
    /// motion-compensated frames from the next pair on: back on the TCP
    /// connection or the USB OUT endpoint, or into PATH (a file or FIFO
    /// that `spiv-firmware-sim --control` reads) for --pipe and --file.
    #[arg(long, num_args = 0..=1, value_name = "PATH", requires = "piv")]
    control: Option<Option<PathBuf>>,
    /// PIV window side of each pass, px (default: 64,32,32, and
    /// 64,32,32,32,32 for motion-compensated pairs).
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
    let mut downlink = match &a.control {
        None => None,
        Some(Some(path)) => {
            let f = std::fs::OpenOptions::new()
                .write(true)
                .create(true)
                .truncate(true)
                .open(path)
                .map_err(|e| CliError::Usage(format!("--control {}: {e}", path.display())))?;
            Some(Downlink::new(Box::new(f)))
        }
        Some(None) => match source.downlink() {
            Some(out) => Some(Downlink::new(
                out.map_err(|e| CliError::Usage(e.to_string()))?,
            )),
            None => {
                return Err(CliError::Usage(format!(
                    "--control: {} has no way back to the sidecar; give --control PATH",
                    source.name()
                )))
            }
        },
    };
    let core = spiv_core::Params::default();
    if let Some(d) = &a.out {
        std::fs::create_dir_all(d).map_err(|e| CliError::Usage(format!("{}: {e}", d.display())))?;
    }
    let settings = receiver_settings(a.windows.clone().unwrap_or_else(|| vec![64, 32, 32]));
    // `--windows` sets the passes of both; the compensated pairs keep
    // their own peak and resampling (as `spiv flow` does).
    let mut mc_settings = spiv_host::piv::Settings::for_compensated_frames();
    if let Some(w) = &a.windows {
        mc_settings.windows = w.clone();
    }
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} receiving from {prefix}: {msg} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_prefix(source.name());
    let mut vectors = 0usize;
    let report = receive::<CliError>(
        source.as_mut(),
        a.max_frame,
        |e| {
            match e {
                Event::Frame(f) => {
                    if let Some(d) = &a.out {
                        save_frame(d, &f)?;
                    }
                }
                Event::Pair(pair) => {
                    if a.piv {
                        let [fa, fb] = &*pair;
                        let s = match fa.end.method {
                            spiv_core::Method::Mc => &mc_settings,
                            _ => &settings,
                        };
                        let field = piv(&upright_f32(fa), &upright_f32(fb), None, s)?;
                        let v = field.vectors();
                        vectors += v.len();
                        if let Some(d) = downlink.as_mut() {
                            d.send(&pair, &control_for(&pair, &v, None, &core))?;
                        }
                        if let Some(d) = &a.out {
                            write_vectors(&d.join(format!("vectors_{:05}.csv", fa.end.pair)), &v)?;
                        }
                    }
                }
            }
            Ok(())
        },
        |r| {
            bar.set_message(format!(
                "{} frames, {} pairs, {} bytes, {} lost, {} corrupted",
                r.frames, r.pairs, r.bytes, r.lost_frames, r.corrupted
            ));
            bar.tick();
        },
    )?;
    bar.finish_and_clear();
    if a.json {
        let mut v = serde_json::to_value(report).unwrap_or_default();
        if let (Some(d), Some(m)) = (&downlink, v.as_object_mut()) {
            m.insert(
                "downlink".into(),
                serde_json::to_value(d.report).unwrap_or_default(),
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
        if let Some(d) = &downlink {
            let r = d.report;
            println!(
                "sent {} controls ({} with motion){}",
                r.sent,
                r.with_motion,
                if r.failed > 0 {
                    format!("; {} refused by the link", r.failed)
                } else {
                    String::new()
                }
            );
        }
    }
    if report.bytes > 0 && report.messages == 0 {
        return Err(CliError::Usage(
            "no valid message in the stream (not spiv wire format?)".into(),
        ));
    }
    Ok(())
}

fn save_frame(dir: &std::path::Path, f: &ReceivedFrame) -> Result<(), CliError> {
    let path = dir.join(format!(
        "frame_{:05}_{}.png",
        f.end.pair,
        if f.end.member == 0 { "a" } else { "b" }
    ));
    let up = f.upright();
    let (w, h) = (u32::from(f.width), u32::from(f.height));
    write_levels(&path, w, h, &up, f.end.full_scale)?;
    Ok(())
}
