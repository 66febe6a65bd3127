//! What `spiv flow` writes beside its recording's result: one vectors CSV
//! per pair and the mean field with their uncertainties, the first pair's
//! frames, the plots and `summary.json`.

use std::path::Path;

use serde_json::json;
use spiv_formats::grid::Grid;
use spiv_formats::image::write_levels;
use spiv_formats::vectors::{write_vectors_with, Column};
use spiv_formats::Vector;

use crate::flow::{FlowOptions, FlowOutcome};

use super::plot;
use crate::Error;

pub use super::RunInfo;

/// Writes every file of a run into `dir` (which must exist):
/// `vectors_NNNNN.csv` per pair and `mean.csv` (px per pair, and m/s in
/// `u_m_s`, `v_m_s` when calibrated), `flow.nc` (all of it in one netCDF
/// file, [`super::netcdf`]), `mean_dense.flo` (when the dense stage ran),
/// `pair_a.png`, `pair_b.png`, `mean_field.png`, `mean_speed.png` and
/// `mean_vorticity.png` (colour maps, glare marked), `pair_vectors.png`
/// and `summary.json`.
pub fn write_flow(
    dir: &Path,
    out: &FlowOutcome,
    opts: &FlowOptions,
    info: RunInfo<'_>,
) -> Result<(), Error> {
    let cal = opts.calibration;
    let dt = f64::from(opts.dt);
    // Sigma columns, then u and v in m/s when calibrated.
    let columns = |vectors: &[spiv_formats::Vector], sigma: &[(f64, f64)]| {
        let mut c = vec![
            col("sigma_u", sigma.iter().map(|s| s.0).collect(), 6),
            col("sigma_v", sigma.iter().map(|s| s.1).collect(), 6),
        ];
        if let Some(k) = cal {
            // NaN where nothing was measured: the flag says why.
            let ms = |f: fn(&spiv_formats::Vector) -> f64| {
                vectors
                    .iter()
                    .map(|v| {
                        if v.state.is_measured() {
                            k.m_per_s(f(v), dt)
                        } else {
                            f64::NAN
                        }
                    })
                    .collect()
            };
            c.push(col("u_m_s", ms(|v| v.u), 6));
            c.push(col("v_m_s", ms(|v| v.v), 6));
        }
        c
    };
    // The files in the orientation asked for (y up or down); the figures
    // draw the camera's image as it is and label their axes so.
    let shown = out.oriented(opts.y_up);
    for (i, p) in shown.pairs.iter().enumerate() {
        let path = dir.join(format!("vectors_{i:05}.csv"));
        write_vectors_with(&path, &p.vectors, &columns(&p.vectors, &p.sigma))?;
    }
    if let Some(d) = &out.mean_dense {
        spiv_formats::dense::write_dense(&dir.join("mean_dense.flo"), d)?;
    }
    let shown_mean = shown.mean();
    let mut mean_columns = columns(&shown_mean.vectors, &shown_mean.sigma);
    mean_columns.push(col(
        "pairs",
        shown_mean.pairs.iter().map(|&n| f64::from(n)).collect(),
        0,
    ));
    write_vectors_with(&dir.join("mean.csv"), &shown_mean.vectors, &mean_columns)?;
    super::netcdf::write_flow_nc(&dir.join("flow.nc"), &shown, opts, info)?;
    // The figures' mean is the camera's: the one just written unless it
    // was turned.
    let mean = if opts.y_up { out.mean() } else { shown_mean };
    let (w, h) = (u32::from(out.size.0), u32::from(out.size.1));
    for (name, f) in ["pair_a.png", "pair_b.png"].iter().zip(&out.first_frames) {
        write_levels(&dir.join(name), w, h, f, out.full_scale)?;
    }
    let base = &out.first_frames[0];
    let unit = cal.map(|c| (c.m_per_s(1.0, dt), "m/s"));
    plot::vectors(
        &dir.join("mean_field.png"),
        base,
        (w, h),
        out.full_scale,
        &mean.vectors,
        plot::arrow_scale(&mean.vectors, out.grid.step),
        plot::VectorCaption {
            title: "mean field (median over pairs)",
            unit,
        },
    )?;
    colour_maps(dir, out, opts, &mean)?;
    if let Some(p) = out.pairs.first() {
        plot::vectors(
            &dir.join("pair_vectors.png"),
            base,
            (w, h),
            out.full_scale,
            &p.vectors,
            plot::arrow_scale(&p.vectors, out.grid.step),
            plot::VectorCaption {
                title: "first pair",
                unit,
            },
        )?;
    }
    let path = dir.join("summary.json");
    let text = serde_json::to_string_pretty(&flow_summary(out, opts, info)).unwrap_or_default();
    std::fs::write(&path, text).map_err(|e| Error::io(path.display().to_string(), e))
}

/// `mean_speed.png` and `mean_vorticity.png` of the mean field `mean` of
/// `out` (the camera's orientation; the vorticity's sign and the axes as
/// `opts.y_up` says), per pair or per second when calibrated.
fn colour_maps(
    dir: &Path,
    out: &FlowOutcome,
    opts: &FlowOptions,
    mean: &crate::flow::MeanField,
) -> Result<(), Error> {
    let (cal, dt) = (opts.calibration, f64::from(opts.dt));
    let (w, h) = (u32::from(out.size.0), u32::from(out.size.1));
    let (speed, mut vorticity) = speed_and_vorticity(&mean.vectors, &out.grid);
    if opts.y_up {
        // dv/dx − du/dy with y and v up: the camera's, negated.
        vorticity.iter_mut().for_each(|w| *w = -*w);
    }
    // Per pair, or per second when calibrated.
    let (k_speed, k_w, units) = match cal {
        Some(c) => (c.m_per_s(1.0, dt), c.tick_hz / dt, ("m/s", "1/s")),
        None => (1.0, 1.0, ("px per pair", "1/pair")),
    };
    for (name, values, signed, title, unit) in [
        (
            "mean_speed.png",
            speed.iter().map(|v| v * k_speed).collect::<Vec<_>>(),
            false,
            "mean speed",
            units.0,
        ),
        (
            "mean_vorticity.png",
            vorticity.iter().map(|v| v * k_w).collect(),
            true,
            if opts.y_up {
                "mean vorticity (y up: + counterclockwise)"
            } else {
                "mean vorticity (y down: + clockwise)"
            },
            units.1,
        ),
    ] {
        let scalar = plot::NodeScalar {
            values: &values,
            name: title,
            unit,
            signed,
            top: None,
            mm_per_px: cal.map(|c| c.pixel_mm),
            y_up: opts.y_up,
        };
        plot::node_map(&dir.join(name), (w, h), &out.grid, scalar, &out.glare)?;
    }
    Ok(())
}

/// Per node of `grid`, the speed of `field` (px per pair) and its
/// vorticity ∂v/∂x − ∂u/∂y (per pair; x right, y down) by central
/// differences between measured neighbours (one-sided at an edge or a
/// hole); NaN where the node or both neighbours along an axis are
/// unmeasured.
pub fn speed_and_vorticity(field: &[Vector], grid: &Grid) -> (Vec<f64>, Vec<f64>) {
    let (nx, ny, h) = (grid.nx, grid.ny, grid.step as f64);
    let at = |r: usize, c: usize| field.get(r * nx + c).filter(|v| v.state.is_measured());
    // d/d(axis) of `f` at (r, c) from the measured neighbours.
    let diff = |r: usize, c: usize, along_x: bool, f: fn(&Vector) -> f64| -> f64 {
        let (n, i) = if along_x { (nx, c) } else { (ny, r) };
        let get = |j: usize| if along_x { at(r, j) } else { at(j, c) };
        let prev = i.checked_sub(1).and_then(get).map(|v| (f(v), 1.0));
        let next = (i + 1 < n)
            .then(|| get(i + 1))
            .flatten()
            .map(|v| (f(v), 1.0));
        let here = get(i).map(f);
        match (prev, here, next) {
            (Some((a, _)), _, Some((b, _))) => (b - a) / (2.0 * h),
            (Some((a, _)), Some(x), None) => (x - a) / h,
            (None, Some(x), Some((b, _))) => (b - x) / h,
            _ => f64::NAN,
        }
    };
    let mut speed = Vec::with_capacity(nx * ny);
    let mut w = Vec::with_capacity(nx * ny);
    for r in 0..ny {
        for c in 0..nx {
            match at(r, c) {
                Some(v) => {
                    speed.push(v.u.hypot(v.v));
                    w.push(diff(r, c, true, |v| v.v) - diff(r, c, false, |v| v.u));
                }
                None => {
                    speed.push(f64::NAN);
                    w.push(f64::NAN);
                }
            }
        }
    }
    (speed, w)
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

#[cfg(test)]
mod tests {
    use super::*;
    use spiv_formats::State;

    /// A linear field u = a·y, v = b·x has vorticity b − a at every node,
    /// edges (one-sided) and holes included; a node without neighbours
    /// along an axis has none.
    #[test]
    fn vorticity_of_a_linear_field() {
        let grid = Grid::new(128, 96, 32, 16).unwrap();
        let (a, b) = (0.03, -0.01);
        let mut field: Vec<Vector> = grid
            .centres()
            .into_iter()
            .map(|(x, y)| Vector {
                x,
                y,
                u: a * y,
                v: b * x,
                state: State::Valid,
            })
            .collect();
        field[grid.nx + 2].state = State::Invalid;
        let (speed, w) = speed_and_vorticity(&field, &grid);
        for (i, (s, w)) in speed.iter().zip(&w).enumerate() {
            if i == grid.nx + 2 {
                assert!(s.is_nan() && w.is_nan());
                continue;
            }
            if i == 2 {
                // The top edge above the hole: no neighbour down the
                // column, so no vorticity.
                assert!(w.is_nan() && s.is_finite());
                continue;
            }
            assert!((w - (b - a)).abs() < 1e-12, "node {i}: {w}");
            assert!((s - field[i].u.hypot(field[i].v)).abs() < 1e-12);
        }
        let one_row = Grid::new(128, 32, 32, 16).unwrap();
        let f: Vec<Vector> = one_row
            .centres()
            .into_iter()
            .map(|(x, y)| Vector {
                x,
                y,
                u: 1.0,
                v: 0.0,
                state: State::Valid,
            })
            .collect();
        assert!(speed_and_vorticity(&f, &one_row)
            .1
            .iter()
            .all(|w| w.is_nan()));
    }
}
