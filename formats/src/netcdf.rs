//! Vector fields over time as one self-describing netCDF file (CF
//! conventions), the form xarray, pivpy and the netCDF tools of the field
//! open directly.
//!
//! Two forms, one content ([`write_field_series`] picks by the build):
//! - netCDF-4 (HDF5), with the `netcdf4` feature: written by the `netcdf`
//!   crate over the system's libnetcdf (Debian: `libnetcdf-dev`), every
//!   data variable deflated (level 4, shuffled) in chunks of one time step,
//!   `NaN` as the `_FillValue` of the doubles ([`write_netcdf4`]);
//! - netCDF-3 in its 64-bit-offset form, without it: written by the
//!   pure-Rust `netcdf3` crate, so no C library is needed to build or run
//!   spiv ([`write_netcdf3`]).
//!
//! Every netCDF reader reads both (netCDF-C; xarray with its netCDF4 or
//! h5netcdf engines, and scipy for netCDF-3). Dimensions are `t` (time,
//! pivpy's name), `y` and `x`, each with its coordinate variable; the data
//! variables are `f64` (or `i32` for flags and counts) over `(t, y, x)`,
//! `(y, x)`, `(t,)`, `(y,)` or `(x,)` (auxiliary coordinates), with their
//! attributes.

use std::path::Path;

use netcdf3::{DataSet, FileWriter, Version};

use crate::FormatError;

/// The dimensions a variable spans.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dims {
    /// `(t, y, x)`: one field per time step.
    TimeYx,
    /// `(y, x)`: one field.
    Yx,
    /// `(t,)`.
    Time,
    /// `(y,)`: one value per node row (an auxiliary coordinate).
    Y,
    /// `(x,)`: one value per node column.
    X,
}

impl Dims {
    fn names(self) -> &'static [&'static str] {
        match self {
            Dims::TimeYx => &["t", "y", "x"],
            Dims::Yx => &["y", "x"],
            Dims::Time => &["t"],
            Dims::Y => &["y"],
            Dims::X => &["x"],
        }
    }

    /// Values a variable of these dimensions holds.
    fn len(self, (t, ny, nx): (usize, usize, usize)) -> usize {
        match self {
            Dims::TimeYx => t * ny * nx,
            Dims::Yx => ny * nx,
            Dims::Time => t,
            Dims::Y => ny,
            Dims::X => nx,
        }
    }
}

/// A variable's values, row-major over its dimensions.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// Doubles (NaN where missing, which every reader takes as missing; no
    /// `_FillValue` attribute: the writer compares variables, attributes
    /// included, by value, and a NaN attribute never equals itself).
    F64(Vec<f64>),
    /// Integers (flags).
    I32(Vec<i32>),
}

/// An attribute value.
#[derive(Debug, Clone, PartialEq)]
pub enum Attr {
    /// Text.
    Text(String),
    /// Numbers.
    F64(Vec<f64>),
    /// Integers (flag values). Integers, not bytes: the writer pads a
    /// byte attribute with fill bytes where readers expect zeros.
    I32(Vec<i32>),
}

/// One data variable.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    /// Its name.
    pub name: String,
    /// The dimensions it spans.
    pub dims: Dims,
    /// Its values.
    pub values: Values,
    /// Its attributes (`units`, `long_name`, …).
    pub attrs: Vec<(String, Attr)>,
}

/// A dataset of fields on one grid over time.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldSeries {
    /// The time coordinate, one per step, with its attributes.
    pub time: (Vec<f64>, Vec<(String, Attr)>),
    /// The node rows' coordinate (top to bottom).
    pub y: (Vec<f64>, Vec<(String, Attr)>),
    /// The node columns' coordinate (left to right).
    pub x: (Vec<f64>, Vec<(String, Attr)>),
    /// The data variables.
    pub variables: Vec<Variable>,
    /// Global attributes.
    pub globals: Vec<(String, Attr)>,
}

/// The form [`write_field_series`] writes: netCDF-4 when built with the
/// `netcdf4` feature, else netCDF-3 (64-bit offset).
pub const FORM: &str = if cfg!(feature = "netcdf4") {
    "netCDF-4"
} else {
    "netCDF-3 64-bit offset"
};

/// Writes `s` to `path` (replacing it) in this build's [`FORM`].
pub fn write_field_series(path: &Path, s: &FieldSeries) -> Result<(), FormatError> {
    #[cfg(feature = "netcdf4")]
    return write_netcdf4(path, s);
    #[cfg(not(feature = "netcdf4"))]
    write_netcdf3(path, s)
}

/// Refuses, before anything is written, a variable whose length does not
/// match its dimensions.
fn check_lengths(path: &Path, s: &FieldSeries) -> Result<(), FormatError> {
    let shape = (s.time.0.len(), s.y.0.len(), s.x.0.len());
    for v in &s.variables {
        let n = match &v.values {
            Values::F64(d) => d.len(),
            Values::I32(d) => d.len(),
        };
        if n != v.dims.len(shape) {
            return Err(FormatError::Parse {
                path: path.to_path_buf(),
                msg: format!(
                    "variable {}: {n} values for dimensions {:?} of {shape:?}",
                    v.name,
                    v.dims.names()
                ),
            });
        }
    }
    Ok(())
}

/// Writes `s` to `path` as netCDF-4 (HDF5; replacing it): the data
/// variables deflated in chunks of one time step, `NaN` the doubles'
/// `_FillValue`. Refused before anything is written: a variable whose
/// length does not match its dimensions; a name netCDF does not accept or
/// twice the same name fails while writing, and the file is removed.
#[cfg(feature = "netcdf4")]
pub fn write_netcdf4(path: &Path, s: &FieldSeries) -> Result<(), FormatError> {
    check_lengths(path, s)?;
    let write = || -> Result<(), netcdf::Error> {
        let mut f = netcdf::create(path)?;
        for (name, (values, _)) in [("t", &s.time), ("y", &s.y), ("x", &s.x)] {
            f.add_dimension(name, values.len())?;
        }
        for (name, (values, attrs)) in [("t", &s.time), ("y", &s.y), ("x", &s.x)] {
            let mut v = f.add_variable::<f64>(name, &[name])?;
            nc4_attrs(attrs, |k, a| v.put_attribute(k, a).map(|_| ()))?;
            v.put_values(values, ..)?;
        }
        for var in &s.variables {
            let dims = var.dims.names();
            let chunk: Vec<usize> = dims
                .iter()
                .map(|&d| match d {
                    "t" => 1,
                    "y" => s.y.0.len().max(1),
                    _ => s.x.0.len().max(1),
                })
                .collect();
            match &var.values {
                Values::F64(d) => {
                    let mut v = f.add_variable::<f64>(&var.name, dims)?;
                    v.set_compression(4, true)?;
                    v.set_chunking(&chunk)?;
                    v.set_fill_value(f64::NAN)?;
                    nc4_attrs(&var.attrs, |k, a| v.put_attribute(k, a).map(|_| ()))?;
                    v.put_values(d, ..)?;
                }
                Values::I32(d) => {
                    let mut v = f.add_variable::<i32>(&var.name, dims)?;
                    v.set_compression(4, true)?;
                    v.set_chunking(&chunk)?;
                    nc4_attrs(&var.attrs, |k, a| v.put_attribute(k, a).map(|_| ()))?;
                    v.put_values(d, ..)?;
                }
            }
        }
        nc4_attrs(&s.globals, |k, a| f.add_attribute(k, a).map(|_| ()))?;
        f.close()
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(path);
        FormatError::Parse {
            path: path.to_path_buf(),
            msg: format!("netCDF-4: {e}"),
        }
    })
}

/// Puts `attrs` through `put` as netCDF attribute values.
#[cfg(feature = "netcdf4")]
fn nc4_attrs(
    attrs: &[(String, Attr)],
    mut put: impl FnMut(&str, netcdf::AttributeValue) -> Result<(), netcdf::Error>,
) -> Result<(), netcdf::Error> {
    for (name, a) in attrs {
        let value = match a {
            Attr::Text(t) => netcdf::AttributeValue::from(t.as_str()),
            Attr::F64(x) => x.clone().into(),
            Attr::I32(x) => x.clone().into(),
        };
        put(name, value)?;
    }
    Ok(())
}

/// Writes `s` to `path` as netCDF-3, 64-bit offset (replacing it). Refused
/// before anything is written: a variable whose length does not match its
/// dimensions, a name netCDF does not accept, twice the same name.
pub fn write_netcdf3(path: &Path, s: &FieldSeries) -> Result<(), FormatError> {
    let bad = |msg: String| FormatError::Parse {
        path: path.to_path_buf(),
        msg,
    };
    check_lengths(path, s)?;
    let ds = definition(s).map_err(|e| bad(format!("netCDF definition: {e:?}")))?;
    let write = || -> Result<(), netcdf3::error::WriteError> {
        let mut w = FileWriter::open(path)?;
        w.set_def(&ds, Version::Offset64Bit, 0)?;
        w.write_var_f64("t", &s.time.0)?;
        w.write_var_f64("y", &s.y.0)?;
        w.write_var_f64("x", &s.x.0)?;
        for v in &s.variables {
            match &v.values {
                Values::F64(d) => w.write_var_f64(&v.name, d)?,
                Values::I32(d) => w.write_var_i32(&v.name, d)?,
            }
        }
        w.close()
    };
    write().map_err(|e| match e {
        netcdf3::error::WriteError::IOErrorKind(kind) => FormatError::Io {
            path: path.to_path_buf(),
            source: kind.into(),
        },
        e => bad(format!("netCDF: {e:?}")),
    })
}

/// The netCDF header of `s`.
fn definition(s: &FieldSeries) -> Result<DataSet, netcdf3::InvalidDataSet> {
    let mut ds = DataSet::new();
    ds.add_fixed_dim("t", s.time.0.len())?;
    ds.add_fixed_dim("y", s.y.0.len())?;
    ds.add_fixed_dim("x", s.x.0.len())?;
    for (name, (_, attrs)) in [("t", &s.time), ("y", &s.y), ("x", &s.x)] {
        ds.add_var_f64(name, &[name])?;
        add_attrs(&mut ds, Some(name), attrs)?;
    }
    for v in &s.variables {
        match v.values {
            Values::F64(_) => ds.add_var_f64(&v.name, v.dims.names())?,
            Values::I32(_) => ds.add_var_i32(&v.name, v.dims.names())?,
        }
        add_attrs(&mut ds, Some(&v.name), &v.attrs)?;
    }
    add_attrs(&mut ds, None, &s.globals)?;
    Ok(ds)
}

/// Adds `attrs` to variable `var` (global attributes for `None`).
fn add_attrs(
    ds: &mut DataSet,
    var: Option<&str>,
    attrs: &[(String, Attr)],
) -> Result<(), netcdf3::InvalidDataSet> {
    for (name, a) in attrs {
        match (var, a) {
            (Some(v), Attr::Text(t)) => ds.add_var_attr_string(v, name, t)?,
            (Some(v), Attr::F64(x)) => ds.add_var_attr_f64(v, name, x.clone())?,
            (Some(v), Attr::I32(x)) => ds.add_var_attr_i32(v, name, x.clone())?,
            (None, Attr::Text(t)) => ds.add_global_attr_string(name, t)?,
            (None, Attr::F64(x)) => ds.add_global_attr_f64(name, x.clone())?,
            (None, Attr::I32(x)) => ds.add_global_attr_i32(name, x.clone())?,
        }
    }
    Ok(())
}

/// A text attribute.
pub fn text(name: &str, value: impl Into<String>) -> (String, Attr) {
    (name.to_string(), Attr::Text(value.into()))
}

/// A numeric attribute.
pub fn number(name: &str, value: f64) -> (String, Attr) {
    (name.to_string(), Attr::F64(vec![value]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series() -> FieldSeries {
        FieldSeries {
            time: (vec![0.5, 1.5], vec![text("units", "s")]),
            y: (vec![16.0, 32.0, 48.0], vec![text("units", "px")]),
            x: (vec![16.0, 32.0], vec![text("units", "px")]),
            variables: vec![
                Variable {
                    name: "u".into(),
                    dims: Dims::TimeYx,
                    values: Values::F64((0..12).map(|i| i as f64 * 0.25).collect()),
                    attrs: vec![text("units", "px")],
                },
                Variable {
                    name: "flag".into(),
                    dims: Dims::Yx,
                    values: Values::I32(vec![0, 1, 2, 0, 0, 2]),
                    attrs: vec![("flag_values".into(), Attr::I32(vec![0, 1, 2]))],
                },
            ],
            globals: vec![text("Conventions", "CF-1.8"), number("dt", 13.0)],
        }
    }

    /// What is written reads back, values, dimensions and attributes, by
    /// the crate's own reader (xarray's reading is tested in Python).
    #[test]
    fn a_series_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.nc");
        let s = series();
        write_netcdf3(&path, &s).unwrap();
        let mut r = netcdf3::FileReader::open(&path).unwrap();
        assert_eq!(
            r.read_var_f64("u").unwrap(),
            match &s.variables[0].values {
                Values::F64(d) => d.clone(),
                _ => unreachable!(),
            }
        );
        assert_eq!(r.read_var_i32("flag").unwrap(), vec![0, 1, 2, 0, 0, 2]);
        assert_eq!(r.read_var_f64("y").unwrap(), vec![16.0, 32.0, 48.0]);
        let ds = r.data_set();
        assert_eq!(ds.dim_size("t"), Some(2));
        assert_eq!(
            ds.get_var_attr_as_string("u", "units").as_deref(),
            Some("px")
        );
        assert_eq!(ds.get_global_attr_f64("dt"), Some(&[13.0][..]));
    }

    /// A variable whose length does not match its dimensions, or a bad
    /// name, is refused with one error and no file.
    #[test]
    fn mismatched_variables_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.nc");
        let mut s = series();
        s.variables[0].values = Values::F64(vec![0.0; 11]);
        for write in [write_netcdf3, write_field_series] {
            let e = write(&path, &s).unwrap_err();
            assert!(e.to_string().contains("11 values"), "{e}");
            assert!(!path.exists());
        }
        let mut s = series();
        s.variables[1].name = "u".into();
        assert!(write_netcdf3(&path, &s).is_err());
        assert!(write_field_series(&path, &s).is_err());
        assert!(!path.exists());
    }

    /// netCDF-4: what is written reads back through libnetcdf itself
    /// (the library xarray's netCDF4 engine uses), values, fill, chunks,
    /// compression and attributes.
    #[cfg(feature = "netcdf4")]
    #[test]
    fn a_series_reads_back_as_netcdf4() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.nc");
        let mut s = series();
        if let Values::F64(d) = &mut s.variables[0].values {
            d[5] = f64::NAN;
        }
        write_field_series(&path, &s).unwrap();
        let f = netcdf::open(&path).unwrap();
        let u = f.variable("u").unwrap();
        let got: Vec<f64> = u.get_values(..).unwrap();
        let Values::F64(want) = &s.variables[0].values else {
            unreachable!()
        };
        assert_eq!(got.len(), 12);
        for (g, w) in got.iter().zip(want) {
            assert!(g == w || (g.is_nan() && w.is_nan()), "{g} {w}");
        }
        assert_eq!(
            u.dimensions().iter().map(|d| d.name()).collect::<Vec<_>>(),
            ["t", "y", "x"]
        );
        assert!(u.fill_value::<f64>().unwrap().is_some_and(f64::is_nan));
        assert_eq!(
            u.attribute_value("units").unwrap().unwrap(),
            netcdf::AttributeValue::Str("px".into())
        );
        let flag: Vec<i32> = f.variable("flag").unwrap().get_values(..).unwrap();
        assert_eq!(flag, vec![0, 1, 2, 0, 0, 2]);
        let y: Vec<f64> = f.variable("y").unwrap().get_values(..).unwrap();
        assert_eq!(y, vec![16.0, 32.0, 48.0]);
        assert_eq!(
            f.attribute("dt").unwrap().value().unwrap(),
            netcdf::AttributeValue::Double(13.0)
        );
        // HDF5 underneath: the file starts with HDF5's signature.
        let head = std::fs::read(&path).unwrap();
        assert_eq!(&head[..8], b"\x89HDF\r\n\x1a\n");
    }
}
