//! `flow.nc`: a flow run as one netCDF file with CF conventions (time, y,
//! x): every pair's field, its flags and uncertainties, the robust mean
//! field with its pair counts, in px per pair and — calibrated — in m/s,
//! with the run's settings as attributes. xarray opens it as a Dataset.

use std::path::Path;

use spiv_formats::netcdf::{
    number, text, write_field_series, Attr, Dims, FieldSeries, Values, Variable,
};
use spiv_formats::vectors::Vector;
use spiv_formats::FormatError;

use crate::flow::{FlowOptions, FlowOutcome};

use super::RunInfo;

/// Writes `flow.nc` of a run to `path`.
pub fn write_flow_nc(
    path: &Path,
    out: &FlowOutcome,
    opts: &FlowOptions,
    info: RunInfo<'_>,
) -> Result<(), FormatError> {
    write_field_series(path, &flow_series(out, opts, info))
}

/// The run as a [`FieldSeries`]: `time` is each pair's midpoint (s since
/// the recording's first plane when calibrated, else ticks), `y` and `x`
/// the PIV nodes' centres (px from the top-left corner, y down).
pub fn flow_series(out: &FlowOutcome, opts: &FlowOptions, info: RunInfo<'_>) -> FieldSeries {
    let cal = opts.calibration;
    let dt = f64::from(opts.dt);
    let grid = &out.grid;
    let mid = |t: [u64; 2]| (t[0] + t[1]) as f64 / 2.0;
    let (time, time_attrs) = match cal {
        Some(c) => (
            out.pairs.iter().map(|p| c.seconds(mid(p.ticks))).collect(),
            vec![
                text("units", "s"),
                text(
                    "long_name",
                    "time of the pair's midpoint since the first plane",
                ),
                text("axis", "T"),
            ],
        ),
        None => (
            out.pairs.iter().map(|p| mid(p.ticks)).collect(),
            vec![
                text("units", "ticks"),
                text("long_name", "tick of the pair's midpoint (uncalibrated)"),
                text("axis", "T"),
            ],
        ),
    };
    let coord = |values: Vec<f64>, axis: &str, what: &str| -> (Vec<f64>, Vec<(String, Attr)>) {
        (
            values,
            vec![
                text("units", "px"),
                text(
                    "long_name",
                    format!("{what} of the window centre, px from the first pixel's centre"),
                ),
                text("axis", axis),
            ],
        )
    };
    let ys = (0..grid.ny).map(|r| grid.centre(r, 0).1).collect();
    let xs = (0..grid.nx).map(|c| grid.centre(0, c).0).collect();
    let mut variables = pair_variables(out, cal.map(|c| (c, dt)));
    variables.extend(mean_variables(out, cal.map(|c| (c, dt))));
    FieldSeries {
        time: (time, time_attrs),
        y: coord(ys, "Y", "row (down)"),
        x: coord(xs, "X", "column (right)"),
        variables,
        globals: globals(out, opts, info),
    }
}

/// A displacement of a vector where it was measured (NaN where invalid).
fn measured(v: &Vector, f: fn(&Vector) -> f64) -> f64 {
    if v.state.is_measured() {
        f(v)
    } else {
        f64::NAN
    }
}

/// A finite uncertainty, NaN for an infinite one.
fn finite(s: f64) -> f64 {
    if s.is_finite() {
        s
    } else {
        f64::NAN
    }
}

fn variable(name: &str, dims: Dims, values: Values, attrs: Vec<(String, Attr)>) -> Variable {
    Variable {
        name: name.into(),
        dims,
        values,
        attrs,
    }
}

/// The flag attributes (CF `flag_values`, `flag_meanings`).
fn flag_attrs(what: &str) -> Vec<(String, Attr)> {
    vec![
        text("long_name", what),
        ("flag_values".into(), Attr::I32(vec![0, 1, 2])),
        text("flag_meanings", "valid replaced invalid"),
    ]
}

/// Displacement variables `{prefix}u`, `{prefix}v` (px per pair) and,
/// calibrated, `{prefix}u_m_s`, `{prefix}v_m_s`, over `dims`.
fn displacement(
    prefix: &str,
    dims: Dims,
    (u, v): (Vec<f64>, Vec<f64>),
    cal: Option<(crate::units::Calibration, f64)>,
) -> Vec<Variable> {
    let attrs = |comp: &str, units: &str| {
        vec![
            text("units", units),
            text(
                "long_name",
                format!(
                    "{comp} of the particles' motion{}",
                    if prefix.is_empty() {
                        ""
                    } else {
                        ", median over pairs"
                    }
                ),
            ),
        ]
    };
    let ms = cal.map(|(c, dt)| {
        let to = |d: &[f64]| d.iter().map(|&x| c.m_per_s(x, dt)).collect();
        (to(&u), to(&v))
    });
    let mut vars = vec![
        variable(
            &format!("{prefix}u"),
            dims,
            Values::F64(u),
            attrs("displacement right per pair", "px"),
        ),
        variable(
            &format!("{prefix}v"),
            dims,
            Values::F64(v),
            attrs("displacement down per pair", "px"),
        ),
    ];
    if let Some((um, vm)) = ms {
        vars.push(variable(
            &format!("{prefix}u_m_s"),
            dims,
            Values::F64(um),
            attrs("velocity right", "m s-1"),
        ));
        vars.push(variable(
            &format!("{prefix}v_m_s"),
            dims,
            Values::F64(vm),
            attrs("velocity down", "m s-1"),
        ));
    }
    vars
}

/// Every pair's field: u, v, flag, sigma_u, sigma_v (and m/s).
fn pair_variables(
    out: &FlowOutcome,
    cal: Option<(crate::units::Calibration, f64)>,
) -> Vec<Variable> {
    let nodes = out.grid.nx * out.grid.ny;
    let stack = |f: &dyn Fn(&crate::flow::PairResult, usize) -> f64| -> Vec<f64> {
        out.pairs
            .iter()
            .flat_map(|p| (0..nodes).map(move |i| f(p, i)))
            .collect()
    };
    let at = |p: &crate::flow::PairResult, i: usize, g: fn(&Vector) -> f64| {
        p.vectors.get(i).map_or(f64::NAN, |v| measured(v, g))
    };
    let u = stack(&|p, i| at(p, i, |v| v.u));
    let v = stack(&|p, i| at(p, i, |v| v.v));
    let mut vars = displacement("", Dims::TimeYx, (u, v), cal);
    let flags = out
        .pairs
        .iter()
        .flat_map(|p| (0..nodes).map(move |i| p.vectors.get(i).map_or(2, |v| v.state.flag())))
        .map(i32::from)
        .collect();
    vars.push(variable(
        "flag",
        Dims::TimeYx,
        Values::I32(flags),
        flag_attrs("vector state"),
    ));
    for (name, pick) in [("sigma_u", 0), ("sigma_v", 1)] {
        let s = stack(&|p, i| {
            p.sigma
                .get(i)
                .map_or(f64::NAN, |s| finite(if pick == 0 { s.0 } else { s.1 }))
        });
        vars.push(variable(
            name,
            Dims::TimeYx,
            Values::F64(s),
            vec![
                text("units", "px"),
                text(
                    "long_name",
                    "standard uncertainty of the displacement per pair",
                ),
            ],
        ));
    }
    vars
}

/// The robust mean field: mean_u, mean_v, mean_flag, mean_sigma_u,
/// mean_sigma_v, mean_pairs (and m/s).
fn mean_variables(
    out: &FlowOutcome,
    cal: Option<(crate::units::Calibration, f64)>,
) -> Vec<Variable> {
    let mean = out.mean();
    let nodes = out.grid.nx * out.grid.ny;
    let col = |f: &dyn Fn(usize) -> f64| -> Vec<f64> { (0..nodes).map(f).collect() };
    let pick =
        |i: usize, g: fn(&Vector) -> f64| mean.vectors.get(i).map_or(f64::NAN, |v| measured(v, g));
    let mut vars = displacement(
        "mean_",
        Dims::Yx,
        (col(&|i| pick(i, |v| v.u)), col(&|i| pick(i, |v| v.v))),
        cal,
    );
    let flags = (0..nodes)
        .map(|i| i32::from(mean.vectors.get(i).map_or(2, |v| v.state.flag())))
        .collect();
    vars.push(variable(
        "mean_flag",
        Dims::Yx,
        Values::I32(flags),
        flag_attrs("state of the median"),
    ));
    for (name, first) in [("mean_sigma_u", true), ("mean_sigma_v", false)] {
        let s = col(&|i| {
            mean.sigma
                .get(i)
                .map_or(f64::NAN, |s| finite(if first { s.0 } else { s.1 }))
        });
        vars.push(variable(
            name,
            Dims::Yx,
            Values::F64(s),
            vec![
                text("units", "px"),
                text("long_name", "standard uncertainty of the median per pair"),
            ],
        ));
    }
    let pairs = col(&|i| f64::from(mean.pairs.get(i).copied().unwrap_or(0)));
    vars.push(variable(
        "mean_pairs",
        Dims::Yx,
        Values::F64(pairs),
        vec![
            text("units", "1"),
            text("long_name", "pairs whose valid vector entered the median"),
        ],
    ));
    vars
}

/// The run's settings: CF conventions, what made the file and from what.
fn globals(out: &FlowOutcome, opts: &FlowOptions, info: RunInfo<'_>) -> Vec<(String, Attr)> {
    let mut g = vec![
        text("Conventions", "CF-1.8"),
        text(
            "title",
            "spiv flow: particle image velocimetry of a spike recording",
        ),
        text("source", format!("spiv {}", env!("CARGO_PKG_VERSION"))),
        text("history", info.command.to_string()),
        text("input", info.input.display().to_string()),
        text("method", opts.method.name()),
        number("dt_ticks", f64::from(opts.dt)),
        number("every_ticks", f64::from(opts.every)),
        number("width_px", f64::from(out.size.0)),
        number("height_px", f64::from(out.size.1)),
        number("window_px", out.grid.size as f64),
        number("step_px", out.grid.step as f64),
        text(
            "coordinates_note",
            "x right and y down from the image's top-left corner; v is positive down",
        ),
    ];
    if let Some(c) = opts.calibration {
        g.push(number("pixel_size_mm", c.pixel_mm));
        g.push(number("tick_hz", c.tick_hz));
        g.push(number("dt_s", c.seconds(f64::from(opts.dt))));
    }
    g
}

/// One PIV field (`spiv piv -o F.nc`) as a [`FieldSeries`] of one time
/// step: `u`, `v` (px per pair, NaN where invalid), `flag`, and each
/// vector's `peak_ratio` and `correlation`, on the nodes of `grid`.
pub fn piv_series(
    grid: &spiv_formats::grid::Grid,
    vectors: &[Vector],
    scores: &[(f64, f64)],
    command: &str,
) -> FieldSeries {
    let pick =
        |g: fn(&Vector) -> f64| -> Vec<f64> { vectors.iter().map(|v| measured(v, g)).collect() };
    let mut variables = displacement("", Dims::TimeYx, (pick(|v| v.u), pick(|v| v.v)), None);
    variables.push(variable(
        "flag",
        Dims::TimeYx,
        Values::I32(vectors.iter().map(|v| i32::from(v.state.flag())).collect()),
        flag_attrs("vector state"),
    ));
    for (name, first, what) in [
        (
            "peak_ratio",
            true,
            "highest over second-highest correlation peak",
        ),
        ("correlation", false, "normalised correlation at the peak"),
    ] {
        let values = scores
            .iter()
            .map(|s| if first { s.0 } else { s.1 })
            .collect();
        variables.push(variable(
            name,
            Dims::TimeYx,
            Values::F64(values),
            vec![text("units", "1"), text("long_name", what)],
        ));
    }
    let axis =
        |values: Vec<f64>, axis: &str| (values, vec![text("units", "px"), text("axis", axis)]);
    FieldSeries {
        time: (
            vec![0.0],
            vec![text("units", "1"), text("long_name", "pair index")],
        ),
        y: axis((0..grid.ny).map(|r| grid.centre(r, 0).1).collect(), "Y"),
        x: axis((0..grid.nx).map(|c| grid.centre(0, c).0).collect(), "X"),
        variables,
        globals: vec![
            text("Conventions", "CF-1.8"),
            text("title", "spiv piv: one image pair"),
            text("source", format!("spiv {}", env!("CARGO_PKG_VERSION"))),
            text("history", command),
            number("window_px", grid.size as f64),
            number("step_px", grid.step as f64),
        ],
    }
}
