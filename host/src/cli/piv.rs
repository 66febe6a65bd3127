//! `spiv piv A B -o vectors.csv [--windows 64,32,32] [--overlap 0.5] [--mask M.png] [--dense F.flo]`

use std::path::PathBuf;

use clap::Args;
use spiv_formats::dense::write_dense;
use spiv_formats::vectors::write_vectors_scored;
use spiv_host::piv::dense::{fill, for_piv, DenseMode};
use spiv_host::piv::options::PivOptions;
use spiv_host::piv::{load_image, load_mask, piv};

use super::CliError;

/// PIV on an image pair: PNG/TIFF/BMP, 8- or 16-bit gray.
#[derive(Debug, Args)]
pub struct PivArgs {
    /// First image.
    a: PathBuf,
    /// Second image.
    b: PathBuf,
    /// Output CSV (x,y,u,v,flag; docs/formats.md), then each vector's confidence:
    /// peak_ratio and correlation (0 where no peak); a name ending in `.nc`
    /// writes the same as netCDF (CF conventions, one time step).
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
    /// Deformation resampling: bspline (cubic B-spline), bspline5
    /// (quintic), bicubic (Keys) or bilinear (least accurate).
    #[arg(long, default_value = "bspline")]
    interp: String,
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
    /// Sub-pixel estimator: parabolic, gaussian or gaussian2d.
    #[arg(long, default_value = "parabolic")]
    subpixel: String,
    /// Minimum correlation peak ratio (1 disables).
    #[arg(long, default_value_t = 1.5)]
    min_peak_ratio: f64,
    /// Where the last pass fails as a whole, report nothing (flags 2)
    /// instead of the dense stage's field (flags 1).
    #[arg(long)]
    no_dense_fallback: bool,
    /// Also write the dense field, one vector per pixel (`.flo` or `.npy`;
    /// px per pair, v down): the PIV field refined below the window by the
    /// variational stage, or, where PIV failed, that stage alone.
    #[arg(long)]
    dense: Option<PathBuf>,
    /// Run the PIV this many times (1..=1000) and report the median time:
    /// for benchmarks (the images are read once, the vectors written once).
    #[arg(long, default_value_t = 1)]
    repeat: usize,
}

/// Runs it.
pub fn run(a: &PivArgs) -> Result<(), CliError> {
    let settings = PivOptions {
        windows: a.windows.clone(),
        overlap: a.overlap,
        interp: a.interp.clone(),
        median_threshold: a.median_threshold,
        clip: a.clip.clone(),
        highpass: a.highpass,
        subpixel: a.subpixel.clone(),
        min_peak_ratio: a.min_peak_ratio,
        // With --dense the dense stage runs once, after PIV (below).
        dense_fallback: !a.no_dense_fallback && a.dense.is_none(),
    }
    .settings()?;
    // The CSV and netCDF written below carry no uncertainty.
    let settings = spiv_host::piv::Settings {
        uncertainty: false,
        ..settings
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
    let mut field = field;
    let dense_note = match &a.dense {
        None => String::new(),
        Some(path) => {
            let t0 = std::time::Instant::now();
            // Raw images, as the fallback (see `piv::piv`).
            let (flow, mode) = for_piv(&ia, &ib, &field);
            let (valid, replaced, _) = field.counts();
            if !a.no_dense_fallback && valid + replaced == 0 {
                fill(&mut field, &flow);
            }
            write_dense(path, &flow.to_field())?;
            format!(
                "; dense ({}) {:.0} ms -> {}",
                match mode {
                    DenseMode::Refine => "refined from PIV",
                    DenseMode::Pyramid => "from rest: PIV measured under half",
                },
                t0.elapsed().as_secs_f64() * 1e3,
                path.display()
            )
        }
    };
    let is_nc = a
        .out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("nc"));
    if is_nc {
        let command: Vec<String> = std::env::args().collect();
        let s = spiv_host::report::netcdf::piv_series(
            &field.grid,
            &field.vectors(),
            &field.scores(),
            &command.join(" "),
        );
        spiv_formats::netcdf::write_field_series(&a.out, &s)?;
    } else {
        write_vectors_scored(&a.out, &field.vectors(), &field.scores())?;
    }
    let (valid, replaced, invalid) = field.counts();
    println!(
        "{} vectors ({}x{}): {valid} valid, {replaced} replaced, {invalid} invalid; {:.1} ms{} -> {}{dense_note}",
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
