//! `spiv reconstruct INPUT.dat [--width W --height H] --at TICK
//! [--method adaptive|tfp|tfi] [--window N] [--no-flip] [--strip-head N] -o OUT.png`

use std::path::PathBuf;

use clap::Args;
use spiv_core::Params;
use spiv_formats::dat::DatOptions;
use spiv_formats::image::write_levels;
use spiv_host::reconstruct::{frame_from_file, FileOptions, Method};

use super::CliError;

/// `--method`: the core's frame methods by name, with their help.
pub fn method_parser() -> impl clap::builder::TypedValueParser<Value = Method> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new([
        PossibleValue::new("adaptive").help("The paper's adaptive integration"),
        PossibleValue::new("tfp").help("Spike count over a window"),
        PossibleValue::new("tfi").help("Inverse inter-spike interval"),
        PossibleValue::new("mc").help(
            "The sidecar's motion-compensated frames along the host's per-row or per-tile motion",
        ),
        PossibleValue::new("ladder").help(
            "The time ladder: pairs of rung frames along the flow measured from the spikes (spiv flow)",
        ),
    ])
    .try_map(|name| Method::from_name(&name).ok_or("unknown method"))
}

/// Make one frame from a spike file (.dat, or a .npz capture) at any tick.
#[derive(Debug, Args)]
pub struct ReconstructArgs {
    /// The spike file.
    input: PathBuf,
    /// Width of the file's planes, px (else from scene.json beside it).
    #[arg(long)]
    width: Option<u16>,
    /// Height, px.
    #[arg(long)]
    height: Option<u16>,
    /// Tick (plane index from 0) at the window's centre.
    #[arg(long)]
    at: u64,
    /// Method.
    #[arg(long, default_value = "adaptive", value_parser = method_parser())]
    method: Method,
    /// TFP window length, or the adaptive/TFI n_max, ticks (default 128 adaptive/TFI, 8 TFP).
    #[arg(long)]
    window: Option<u16>,
    /// The file's rows are stored upright (some public simulators).
    #[arg(long)]
    no_flip: bool,
    /// Columns to drop at the right of every row (16 for 416-wide captures).
    #[arg(long, default_value_t = 0)]
    strip_head: u16,
    /// Read a file whose last plane is truncated (the rest is reported).
    #[arg(long)]
    allow_truncated: bool,
    /// Output bit depth, 8 or 16.
    #[arg(long, default_value_t = 8)]
    bits: u8,
    /// Output image (.png, .tif, .bmp).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
}

/// Runs it.
pub fn run(a: &ReconstructArgs) -> Result<(), CliError> {
    let method = a.method;
    let window = a
        .window
        .unwrap_or(if method == Method::Tfp { 8 } else { 128 });
    if a.bits != 8 && a.bits != 16 {
        return Err(CliError::Usage(format!("--bits {}: 8 or 16", a.bits)));
    }
    if a.width.is_some() != a.height.is_some() {
        return Err(CliError::Usage(
            "give both --width and --height, or neither".into(),
        ));
    }
    let p = Params {
        full_scale: if a.bits == 8 { 255 } else { 65535 },
        ..Params::default()
    };
    let opts = FileOptions {
        width: a.width,
        height: a.height,
        dat: DatOptions {
            flip: !a.no_flip,
            strip_head: a.strip_head,
            allow_truncated: a.allow_truncated,
        },
    };
    let f = frame_from_file(&a.input, a.at, method, window, &p, opts)?;
    let (w, h) = (u32::from(f.width), u32::from(f.height));
    let full_scale = if a.bits == 8 { 255 } else { u16::MAX };
    write_levels(&a.out, w, h, &f.data, full_scale)?;
    match f.stats {
        Some(s) => println!(
            "{}: {w}x{h} adaptive at tick {}: {} regions (mean n* {:.1} ticks), {} saturated px -> {}",
            a.input.display(),
            a.at,
            s.regions_out,
            s.n_star_sum as f64 / f64::from(s.regions_out.max(1)),
            s.segment.saturated_pixels,
            a.out.display()
        ),
        None => println!("{}: {w}x{h} {:?} at tick {}, window {window} -> {}", a.input.display(), a.method, a.at, a.out.display()),
    }
    Ok(())
}
