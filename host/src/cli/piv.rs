//! `spiv piv A B -o vectors.csv [--windows 64,32,32] [--overlap 0.5] [--mask M.png]`

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use spiv_firmware_sim::formats::csv::write_vectors;
use spiv_host::piv::{load_image, load_mask, piv, Interp, Settings, Validation};

use super::CliError;

/// Image resampling for the deformation passes.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum InterpArg {
    /// Cubic B-spline (most accurate).
    Bspline,
    /// Keys' bicubic.
    Bicubic,
    /// Bilinear (fastest).
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
    /// Minimum correlation peak ratio (1 disables).
    #[arg(long, default_value_t = 1.5)]
    min_peak_ratio: f64,
}

/// Runs it.
pub fn run(a: &PivArgs) -> Result<(), CliError> {
    let settings = Settings {
        windows: a.windows.clone(),
        overlap: a.overlap,
        interp: match a.interp {
            InterpArg::Bspline => Interp::Bspline,
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
    let start = std::time::Instant::now();
    let field = piv(&ia, &ib, mask.as_ref(), &settings)?;
    let took = start.elapsed();
    write_vectors(&a.out, &field.vectors())?;
    let (valid, replaced, invalid) = field.counts();
    println!(
        "{} vectors ({}x{}): {valid} valid, {replaced} replaced, {invalid} invalid; {:.1} ms -> {}",
        field.grid.len(),
        field.grid.nx,
        field.grid.ny,
        took.as_secs_f64() * 1e3,
        a.out.display()
    );
    Ok(())
}
