//! `spiv piv A B -o vectors.csv [--windows 64,32,32] [--overlap 0.5] [--mask M.png]`

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use spiv_formats::vectors::write_vectors;
use spiv_host::piv::{load_image, load_mask, piv, Clip, Interp, Settings, Subpixel, Validation};

use super::CliError;

/// Image resampling for the deformation passes.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum InterpArg {
    /// Cubic B-spline.
    Bspline,
    /// Quintic B-spline.
    Bspline5,
    /// Keys' bicubic.
    Bicubic,
    /// Bilinear (least accurate).
    Bilinear,
}

/// PIV on an image pair: PNG/TIFF/BMP, 8- or 16-bit gray.
#[derive(Debug, Args)]
pub struct PivArgs {
    /// First image.
    a: PathBuf,
    /// Second image.
    b: PathBuf,
    /// Output CSV (x,y,u,v,flag; FORMATS.md).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
    /// Window side of each pass, px; the list sets the passes.
    #[arg(long, value_delimiter = ',', default_value = "64,32,32")]
    windows: Vec<usize>,
    /// Overlap of neighbouring windows, 0..=0.9.
    #[arg(long, default_value_t = 0.5)]
    overlap: f64,
    /// Mask image: pixels above 0 are excluded.
    #[arg(long)]
    mask: Option<PathBuf>,
    /// Deformation resampling.
    #[arg(long, value_enum, default_value = "bspline")]
    interp: InterpArg,
    /// Normalised median test threshold (0 disables).
    #[arg(long, default_value_t = 2.0)]
    median_threshold: f64,
    /// Clipped areas left out: "auto" (each image's maximum when it is
    /// shared by ≥ 0.1 % of pixels), "off", or a gray level.
    #[arg(long, default_value = "auto")]
    clip: String,
    /// High-pass pre-filter: σ of the subtracted background blur, px (0 = off).
    #[arg(long, default_value_t = 3.0)]
    highpass: f32,
    /// Sub-pixel estimator: gaussian or parabolic.
    #[arg(long, default_value = "parabolic")]
    subpixel: String,
    /// Minimum correlation peak ratio (1 disables).
    #[arg(long, default_value_t = 1.5)]
    min_peak_ratio: f64,
    /// Run the PIV this many times (1..=1000) and report the median time:
    /// for benchmarks (the images are read once, the vectors written once).
    #[arg(long, default_value_t = 1)]
    repeat: usize,
}

/// Runs it.
pub fn run(a: &PivArgs) -> Result<(), CliError> {
    let clip = match a.clip.as_str() {
        "auto" => Clip::Auto,
        "off" => Clip::Off,
        v => Clip::Level(
            v.parse::<f32>()
                .ok()
                .filter(|l| l.is_finite())
                .ok_or_else(|| {
                    CliError::Usage(format!("--clip {v}: expected auto, off or a gray level"))
                })?,
        ),
    };
    if !(0.0..=1000.0).contains(&a.highpass) {
        return Err(CliError::Usage(format!(
            "--highpass {}: expected 0..=1000 px",
            a.highpass
        )));
    }
    let subpixel = match a.subpixel.as_str() {
        "gaussian" => Subpixel::Gaussian,
        "parabolic" => Subpixel::Parabolic,
        "gaussian2d" => Subpixel::Gaussian2d,
        v => {
            return Err(CliError::Usage(format!(
                "--subpixel {v}: gaussian or parabolic"
            )))
        }
    };
    let settings = Settings {
        subpixel,
        clip,
        highpass: a.highpass,
        windows: a.windows.clone(),
        overlap: a.overlap,
        interp: match a.interp {
            InterpArg::Bspline => Interp::Bspline,
            InterpArg::Bspline5 => Interp::Bspline5,
            InterpArg::Bicubic => Interp::Bicubic,
            InterpArg::Bilinear => Interp::Bilinear,
        },
        validation: Validation {
            median_threshold: a.median_threshold,
            min_peak_ratio: a.min_peak_ratio,
            ..Validation::default()
        },
        ..Settings::default()
    };
    let ia = load_image(&a.a)?;
    let ib = load_image(&a.b)?;
    let mask = a.mask.as_deref().map(load_mask).transpose()?;
    if !(1..=1000).contains(&a.repeat) {
        return Err(CliError::Usage(format!(
            "--repeat {}: expected 1..=1000",
            a.repeat
        )));
    }
    let mut times = Vec::with_capacity(a.repeat);
    let mut field = None;
    for _ in 0..a.repeat {
        let start = std::time::Instant::now();
        field = Some(piv(&ia, &ib, mask.as_ref(), &settings)?);
        times.push(start.elapsed());
    }
    times.sort();
    let took = times.get(times.len() / 2).copied().unwrap_or_default();
    let field = field.ok_or_else(|| CliError::Usage("--repeat 0".into()))?;
    write_vectors(&a.out, &field.vectors())?;
    let (valid, replaced, invalid) = field.counts();
    println!(
        "{} vectors ({}x{}): {valid} valid, {replaced} replaced, {invalid} invalid; {:.1} ms{} -> {}",
        field.grid.len(),
        field.grid.nx,
        field.grid.ny,
        took.as_secs_f64() * 1e3,
        if a.repeat > 1 {
            format!(" (median of {})", a.repeat)
        } else {
            String::new()
        },
        a.out.display()
    );
    Ok(())
}
