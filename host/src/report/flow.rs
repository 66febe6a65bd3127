//! What `spiv flow` writes beside its recording's result: one vectors CSV
//! per pair and the mean field with their uncertainties, the first pair's
//! frames, the plots and `summary.json`.

use std::path::Path;

use serde_json::json;
use spiv_formats::image::write_levels;
use spiv_formats::vectors::{write_vectors_with, Column};
use spiv_formats::FormatError;

use crate::flow::{FlowOptions, FlowOutcome};

use super::plot::{self, PlotError};

/// Everything writing a flow run's files can refuse.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// A file.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// A plot.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// `summary.json`.
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
}

/// What the run was asked, for `summary.json`.
#[derive(Debug, Clone, Copy)]
pub struct RunInfo<'a> {
    /// The recording's path as given.
    pub input: &'a Path,
    /// Planes in the recording.
    pub planes: u64,
    /// Wall time of the run, s.
    pub seconds: f64,
    /// The command line that made the run (netCDF `history`).
    pub command: &'a str,
}

/// Writes every file of a run into `dir` (which must exist):
/// `vectors_NNNNN.csv` per pair and `mean.csv` (px per pair, and m/s in
/// `u_m_s`, `v_m_s` when calibrated), `flow.nc` (all of it in one netCDF
/// file, [`super::netcdf`]), `mean_dense.flo` (when the dense stage ran),
/// `pair_a.png`, `pair_b.png`, `mean_field.png`, `pair_vectors.png` and
/// `summary.json`.
pub fn write_flow(
    dir: &Path,
    out: &FlowOutcome,
    opts: &FlowOptions,
    info: RunInfo<'_>,
) -> Result<(), WriteError> {
    let cal = opts.calibration;
    let dt = f64::from(opts.dt);
    // Sigma columns, then u and v in m/s when calibrated.
    let columns = |vectors: &[spiv_formats::Vector], sigma: &[(f64, f64)]| {
        let mut c = vec![
            col("sigma_u", sigma.iter().map(|s| s.0).collect(), 6),
            col("sigma_v", sigma.iter().map(|s| s.1).collect(), 6),
        ];
        if let Some(k) = cal {
            let ms = |f: fn(&spiv_formats::Vector) -> f64| {
                vectors.iter().map(|v| k.m_per_s(f(v), dt)).collect()
            };
            c.push(col("u_m_s", ms(|v| v.u), 6));
            c.push(col("v_m_s", ms(|v| v.v), 6));
        }
        c
    };
    for (i, p) in out.pairs.iter().enumerate() {
        let path = dir.join(format!("vectors_{i:05}.csv"));
        write_vectors_with(&path, &p.vectors, &columns(&p.vectors, &p.sigma))?;
    }
    if let Some(d) = &out.mean_dense {
        spiv_formats::dense::write_dense(&dir.join("mean_dense.flo"), d)?;
    }
    let mean = out.mean();
    let mut mean_columns = columns(&mean.vectors, &mean.sigma);
    mean_columns.push(col(
        "pairs",
        mean.pairs.iter().map(|&n| f64::from(n)).collect(),
        0,
    ));
    write_vectors_with(&dir.join("mean.csv"), &mean.vectors, &mean_columns)?;
    super::netcdf::write_flow_nc(&dir.join("flow.nc"), out, opts, info)?;
    let (w, h) = (u32::from(out.size.0), u32::from(out.size.1));
    for (name, f) in ["pair_a.png", "pair_b.png"].iter().zip(&out.first_frames) {
        write_levels(&dir.join(name), w, h, f, out.full_scale)?;
    }
    let base = &out.first_frames[0];
    plot::vectors(
        &dir.join("mean_field.png"),
        base,
        w,
        h,
        out.full_scale,
        &mean.vectors,
        1.0,
    )?;
    if let Some(p) = out.pairs.first() {
        plot::vectors(
            &dir.join("pair_vectors.png"),
            base,
            w,
            h,
            out.full_scale,
            &p.vectors,
            1.0,
        )?;
    }
    let path = dir.join("summary.json");
    let text = serde_json::to_string_pretty(&flow_summary(out, opts, info)).unwrap_or_default();
    std::fs::write(&path, text).map_err(|e| WriteError::Io(path.display().to_string(), e))
}

/// A CSV column of `values` printed with `decimals` decimals.
fn col(name: &'static str, values: Vec<f64>, decimals: usize) -> Column<'static> {
    Column {
        name,
        values,
        decimals,
    }
}

/// `summary.json` of a flow run: the settings, and per pair its ticks,
/// method, counts, how its motion-compensated field was measured and what
/// the core's tables lost.
pub fn flow_summary(out: &FlowOutcome, opts: &FlowOptions, info: RunInfo<'_>) -> serde_json::Value {
    let per_pair: Vec<_> = out
        .pairs
        .iter()
        .map(|p| {
            let (v, r, i) = p.counts();
            json!({
                "ticks": p.ticks,
                "method": p.method.name(),
                "measured": p.measured(),
                "valid": v, "replaced": r, "invalid": i,
                "bootstrapped": p.bootstrapped,
                "caps": p.caps,
                "rungs": p.rungs,
                "lost_to_full_tables": {"regions": p.lost.regions, "pixels": p.lost.pixels},
            })
        })
        .collect();
    let (w, h) = out.size;
    json!({
        "input": info.input.display().to_string(),
        "width": w, "height": h, "planes": info.planes,
        "method": opts.method.name(),
        "window": opts.window,
        "dwell_cap_px": opts.dwell_cap,
        "dt_ticks": opts.dt, "every_ticks": opts.every,
        "piv": opts.grid_settings(),
        "ladder_separations": opts.ladder.separations,
        "units": {"u": "px per pair", "v": "px per pair, down", "sigma": "px per pair",
                  "u_m_s": "m/s (when calibrated)", "v_m_s": "m/s, down (when calibrated)"},
        "calibration": opts.calibration,
        "seconds": info.seconds,
        "pairs": per_pair,
    })
}
