//! Vector fields over time as one self-describing netCDF file (CF
//! conventions), the form xarray, pivpy and the netCDF tools of the field
//! open directly.
//!
//! The file is netCDF-3 in its 64-bit-offset form, written by the pure-Rust
//! `netcdf3` crate: no C library is needed to build or run spiv, and every
//! netCDF reader (netCDF-C, xarray with its netCDF4, h5netcdf or scipy
//! engines) reads it. Dimensions are `time`, `y` and `x`, each with its
//! coordinate variable; the data variables are `f64` (or `i32` for flags)
//! over `(time, y, x)` or `(y, x)`, with their attributes.

use std::path::Path;

use netcdf3::{DataSet, FileWriter, Version};

use crate::FormatError;

/// The dimensions a variable spans.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dims {
    /// `(time, y, x)`: one field per time step.
    TimeYx,
    /// `(y, x)`: one field.
    Yx,
    /// `(time,)`.
    Time,
}

impl Dims {
    fn names(self) -> &'static [&'static str] {
        match self {
            Dims::TimeYx => &["time", "y", "x"],
            Dims::Yx => &["y", "x"],
            Dims::Time => &["time"],
        }
    }

    /// Values a variable of these dimensions holds.
    fn len(self, (t, ny, nx): (usize, usize, usize)) -> usize {
        match self {
            Dims::TimeYx => t * ny * nx,
            Dims::Yx => ny * nx,
            Dims::Time => t,
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

/// Writes `s` to `path` (replacing it). Refused before anything is
/// written: a variable whose length does not match its dimensions, a
/// name netCDF does not accept, twice the same name.
pub fn write_field_series(path: &Path, s: &FieldSeries) -> Result<(), FormatError> {
    let bad = |msg: String| FormatError::Parse {
        path: path.to_path_buf(),
        msg,
    };
    let shape = (s.time.0.len(), s.y.0.len(), s.x.0.len());
    for v in &s.variables {
        let n = match &v.values {
            Values::F64(d) => d.len(),
            Values::I32(d) => d.len(),
        };
        if n != v.dims.len(shape) {
            return Err(bad(format!(
                "variable {}: {n} values for dimensions {:?} of {shape:?}",
                v.name,
                v.dims.names()
            )));
        }
    }
    let ds = definition(s).map_err(|e| bad(format!("netCDF definition: {e:?}")))?;
    let write = || -> Result<(), netcdf3::error::WriteError> {
        let mut w = FileWriter::open(path)?;
        w.set_def(&ds, Version::Offset64Bit, 0)?;
        w.write_var_f64("time", &s.time.0)?;
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
    ds.add_fixed_dim("time", s.time.0.len())?;
    ds.add_fixed_dim("y", s.y.0.len())?;
    ds.add_fixed_dim("x", s.x.0.len())?;
    for (name, (_, attrs)) in [("time", &s.time), ("y", &s.y), ("x", &s.x)] {
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
        write_field_series(&path, &s).unwrap();
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
        assert_eq!(ds.dim_size("time"), Some(2));
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
        let e = write_field_series(&path, &s).unwrap_err();
        assert!(e.to_string().contains("11 values"), "{e}");
        assert!(!path.exists());
        let mut s = series();
        s.variables[1].name = "u".into();
        assert!(write_field_series(&path, &s).is_err());
    }
}
