//! `flow.nc`: a flow run as one netCDF file with CF conventions (t, y, x):
//! every pair's field, its flags and uncertainties, the robust mean field
//! with its pair counts, in px per pair and — calibrated — in m/s, with
//! the run's settings as attributes. xarray opens it as a Dataset, and
//! the CF checker (`compliance-checker --test cf:1.8`) passes it.
//!
//! Units are UDUNITS units: pixels and ticks are counts (`1`, the long
//! name says which). Calibrated, `x` and `y` are in m (with `x_px`, `y_px`
//! as auxiliary coordinates) and `t` in s since the recording's first
//! plane; uncalibrated, `x` and `y` are in px and `t` in ticks. Every
//! displacement names its flag and uncertainty in `ancillary_variables`;
//! NaN marks what was not measured (netCDF-4 also declares it as the
//! `_FillValue`).

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

/// The run as a [`FieldSeries`]: `t` is each pair's midpoint (s since
/// the recording's first plane when calibrated, else ticks), `y` and `x`
/// the PIV nodes' centres from the first pixel's centre (m when
/// calibrated, with `y_px`, `x_px` beside them; else px), y down.
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
                text("long_name", "time since the first plane"),
            ],
        ),
        None => (
            out.pairs.iter().map(|p| mid(p.ticks)).collect(),
            vec![
                text("units", "1"),
                text("long_name", "tick (pair midpoint)"),
            ],
        ),
    };
    let (up, top) = (opts.y_up, f64::from(out.size.1) - 1.0);
    let dir = if up { "up" } else { "down" };
    let ys: Vec<f64> = (0..grid.ny)
        .map(|r| grid.centre(r, 0).1)
        .map(|y| if up { top - y } else { y })
        .collect();
    let xs: Vec<f64> = (0..grid.nx).map(|c| grid.centre(0, c).0).collect();
    let mut variables = pair_variables(out, cal.map(|c| (c, dt)), dir);
    variables.extend(mean_variables(out, cal.map(|c| (c, dt)), dir));
    let y_long = format!("y, pixels ({dir})");
    let (y, x) = match cal {
        Some(c) => {
            let metres = |v: &[f64], axis: &str, name: &str, long: &str| {
                (
                    v.iter().map(|&p| c.metres(p)).collect(),
                    vec![
                        text("units", "m"),
                        text("standard_name", name),
                        text("long_name", long),
                        text("axis", axis),
                    ],
                )
            };
            for (name, dims, values, long) in [
                ("y_px", Dims::Y, ys.clone(), y_long.as_str()),
                ("x_px", Dims::X, xs.clone(), "x, pixels (right)"),
            ] {
                variables.push(variable(
                    name,
                    dims,
                    Values::F64(values),
                    vec![text("units", "1"), text("long_name", long)],
                ));
            }
            for v in variables
                .iter_mut()
                .filter(|v| matches!(v.dims, Dims::TimeYx | Dims::Yx))
            {
                v.attrs.push(text("coordinates", "y_px x_px"));
            }
            (
                metres(&ys, "Y", "projection_y_coordinate", &format!("y ({dir})")),
                metres(&xs, "X", "projection_x_coordinate", "x (right)"),
            )
        }
        None => {
            let px =
                |v: Vec<f64>, long: &str| (v, vec![text("units", "1"), text("long_name", long)]);
            (px(ys, &y_long), px(xs, "x, pixels (right)"))
        }
    };
    FieldSeries {
        time: (time, time_attrs),
        y,
        x,
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

/// The flag attributes (CF `status_flag`, `flag_values`, `flag_meanings`).
fn flag_attrs(what: &str) -> Vec<(String, Attr)> {
    vec![
        text("standard_name", "status_flag"),
        text("long_name", what),
        ("flag_values".into(), Attr::I32(vec![0, 1, 2])),
        text("flag_meanings", "valid replaced invalid"),
    ]
}

/// Displacement variables `{prefix}u`, `{prefix}v` (px per pair) and,
/// calibrated, `{prefix}u_m_s`, `{prefix}v_m_s`, over `dims`, each naming
/// `{prefix}flag` and, with `sigma`, `{prefix}sigma_u` or `_v` as its
/// ancillary variables.
fn displacement(
    prefix: &str,
    dims: Dims,
    (u, v): (Vec<f64>, Vec<f64>),
    cal: Option<(crate::units::Calibration, f64)>,
    sigma: bool,
    dir: &str,
) -> Vec<Variable> {
    // Short long names, which label a plot's axis.
    let what = if prefix.is_empty() { "" } else { "median " };
    let attrs = |comp: &str, long: String, units: &str| {
        let ancillary = if sigma {
            format!("{prefix}flag {prefix}sigma_{comp}")
        } else {
            format!("{prefix}flag")
        };
        vec![
            text("units", units),
            text("long_name", long),
            text("ancillary_variables", ancillary),
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
            attrs("u", format!("{what}u, px per pair"), "1"),
        ),
        variable(
            &format!("{prefix}v"),
            dims,
            Values::F64(v),
            attrs("v", format!("{what}v ({dir}), px per pair"), "1"),
        ),
    ];
    if let Some((um, vm)) = ms {
        vars.push(variable(
            &format!("{prefix}u_m_s"),
            dims,
            Values::F64(um),
            attrs("u", format!("{what}u"), "m s-1"),
        ));
        vars.push(variable(
            &format!("{prefix}v_m_s"),
            dims,
            Values::F64(vm),
            attrs("v", format!("{what}v ({dir})"), "m s-1"),
        ));
    }
    vars
}

/// Every pair's field: u, v, flag, sigma_u, sigma_v (and m/s).
fn pair_variables(
    out: &FlowOutcome,
    cal: Option<(crate::units::Calibration, f64)>,
    dir: &str,
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
    let mut vars = displacement("", Dims::TimeYx, (u, v), cal, true, dir);
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
                text("units", "1"),
                text("long_name", format!("{name}, px per pair")),
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
    dir: &str,
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
        true,
        dir,
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
                text("units", "1"),
                text("long_name", format!("{name}, px per pair")),
            ],
        ));
    }
    let pairs = (0..nodes)
        .map(|i| i32::try_from(mean.pairs.get(i).copied().unwrap_or(0)).unwrap_or(i32::MAX))
        .collect();
    vars.push(variable(
        "mean_pairs",
        Dims::Yx,
        Values::I32(pairs),
        vec![
            text("units", "1"),
            text("long_name", "valid pairs in the median"),
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
            if opts.y_up {
                "x right and y up from the image's bottom-left pixel centre; v is positive up"
            } else {
                "x right and y down from the image's top-left pixel centre; v is positive down"
            },
        ),
        text("y_axis", if opts.y_up { "up" } else { "down" }),
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
    let mut variables = displacement(
        "",
        Dims::TimeYx,
        (pick(|v| v.u), pick(|v| v.v)),
        None,
        false,
        "down",
    );
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
        |values: Vec<f64>, long: &str| (values, vec![text("units", "1"), text("long_name", long)]);
    FieldSeries {
        time: (
            vec![0.0],
            vec![text("units", "1"), text("long_name", "pair index")],
        ),
        y: axis(
            (0..grid.ny).map(|r| grid.centre(r, 0).1).collect(),
            "y, pixels (down)",
        ),
        x: axis(
            (0..grid.nx).map(|c| grid.centre(0, c).0).collect(),
            "x, pixels (right)",
        ),
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
