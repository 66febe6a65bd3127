//! Vector fields (`x,y,u,v,flag`) and profiles (`y,u`) as CSV (docs/formats.md).

use std::fmt::Write as _;
use std::path::Path;

use crate::{io_err, FormatError};

/// What validation made of a vector (the CSV `flag` column in brackets).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// Passed every test (0).
    Valid,
    /// Not validated on its own (1): rejected and replaced from its
    /// neighbours, a weak peak only its neighbours confirm, or a value of
    /// the dense stage or a coarser pass where correlation failed.
    Replaced,
    /// Masked, without signal, or rejected with nothing to replace it (2;
    /// then u = v = 0).
    Invalid,
}

impl State {
    /// The CSV flag: 0, 1 or 2.
    pub const fn flag(self) -> u8 {
        match self {
            State::Valid => 0,
            State::Replaced => 1,
            State::Invalid => 2,
        }
    }

    /// The state of a CSV flag, `None` beyond 2.
    pub const fn from_flag(flag: u8) -> Option<State> {
        match flag {
            0 => Some(State::Valid),
            1 => Some(State::Replaced),
            2 => Some(State::Invalid),
            _ => None,
        }
    }

    /// A measurement (valid or replaced), not a hole.
    pub const fn is_measured(self) -> bool {
        !matches!(self, State::Invalid)
    }
}

/// One vector: window centre (px, origin top-left, y down), displacement
/// (px, u right, v down), and its [`State`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vector {
    /// Column of the centre, px.
    pub x: f64,
    /// Row of the centre, px.
    pub y: f64,
    /// Displacement right, px.
    pub u: f64,
    /// Displacement down, px.
    pub v: f64,
    /// Valid, replaced, or invalid (then u = v = 0).
    pub state: State,
}

/// Writes a vector field.
pub fn write_vectors(path: &Path, vectors: &[Vector]) -> Result<(), FormatError> {
    let mut s = String::from("x,y,u,v,flag\n");
    for v in vectors {
        let (u, vv) = if v.state.is_measured() {
            (v.u, v.v)
        } else {
            (0.0, 0.0)
        };
        let _ = writeln!(s, "{},{},{:.6},{:.6},{}", v.x, v.y, u, vv, v.state.flag());
    }
    std::fs::write(path, s).map_err(io_err(path))
}

/// An extra column of a vector field: its header name, one value per
/// vector, and the decimals it is written with (non-finite values are
/// written `inf`, `-inf` or `nan`).
#[derive(Debug, Clone, PartialEq)]
pub struct Column<'a> {
    /// Header name.
    pub name: &'a str,
    /// One value per vector.
    pub values: Vec<f64>,
    /// Decimals written.
    pub decimals: usize,
}

/// Writes a vector field with extra columns after `flag` (readers of
/// `x,y,u,v,flag` ignore them); each column holds one value per vector.
pub fn write_vectors_with(
    path: &Path,
    vectors: &[Vector],
    extra: &[Column<'_>],
) -> Result<(), FormatError> {
    if let Some(c) = extra.iter().find(|c| c.values.len() != vectors.len()) {
        return Err(FormatError::Parse {
            path: path.to_path_buf(),
            msg: format!(
                "{} {} values for {} vectors",
                c.values.len(),
                c.name,
                vectors.len()
            ),
        });
    }
    let mut s = String::from("x,y,u,v,flag");
    for c in extra {
        let _ = write!(s, ",{}", c.name);
    }
    s.push('\n');
    for (i, v) in vectors.iter().enumerate() {
        let (u, vv) = if v.state.is_measured() {
            (v.u, v.v)
        } else {
            (0.0, 0.0)
        };
        let _ = write!(s, "{},{},{:.6},{:.6},{}", v.x, v.y, u, vv, v.state.flag());
        for c in extra {
            let _ = write!(s, ",{:.*}", c.decimals, c.values[i]);
        }
        s.push('\n');
    }
    std::fs::write(path, s).map_err(io_err(path))
}

/// Writes a vector field with each vector's confidence after `flag`:
/// `peak_ratio` (the correlation peak over the next highest, 0 where no
/// peak) and `correlation` (the normalised correlation at the peak, −1..1,
/// 0 where none), one `(peak_ratio, correlation)` per vector.
pub fn write_vectors_scored(
    path: &Path,
    vectors: &[Vector],
    scores: &[(f64, f64)],
) -> Result<(), FormatError> {
    let col = |name, f: fn(&(f64, f64)) -> f64| Column {
        name,
        values: scores.iter().map(f).collect(),
        decimals: 4,
    };
    write_vectors_with(
        path,
        vectors,
        &[col("peak_ratio", |s| s.0), col("correlation", |s| s.1)],
    )
}

/// Writes a vector field with each vector's standard uncertainty after
/// `flag`: `sigma_u`, `sigma_v` in the units of `u` and `v` (`inf` where
/// the vector was not measured).
pub fn write_vectors_uncertain(
    path: &Path,
    vectors: &[Vector],
    sigma: &[(f64, f64)],
) -> Result<(), FormatError> {
    let col = |name, f: fn(&(f64, f64)) -> f64| Column {
        name,
        values: sigma.iter().map(f).collect(),
        decimals: 6,
    };
    write_vectors_with(
        path,
        vectors,
        &[col("sigma_u", |s| s.0), col("sigma_v", |s| s.1)],
    )
}

/// Reads a vector field (extra columns after `flag` are ignored).
pub fn read_vectors(path: &Path) -> Result<Vec<Vector>, FormatError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    let bad = |line: usize, msg: &str| FormatError::Parse {
        path: path.to_path_buf(),
        msg: format!("line {line}: {msg}"),
    };
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim().starts_with("x,y,u,v,flag") => {}
        _ => return Err(bad(1, "header must start with x,y,u,v,flag")),
    }
    let mut out = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        if f.len() < 5 {
            return Err(bad(i + 1, "fewer than 5 columns"));
        }
        let num = |k: usize| {
            f[k].trim()
                .parse::<f64>()
                .map_err(|_| bad(i + 1, "not a number"))
        };
        let state = f[4]
            .trim()
            .parse::<u8>()
            .ok()
            .and_then(State::from_flag)
            .ok_or_else(|| bad(i + 1, "flag must be 0, 1 or 2"))?;
        out.push(Vector {
            x: num(0)?,
            y: num(1)?,
            u: num(2)?,
            v: num(3)?,
            state,
        });
    }
    Ok(out)
}

/// Writes a profile: `y` px up from the wall, `u` px per pair.
pub fn write_profile(path: &Path, profile: &[(f64, f64)]) -> Result<(), FormatError> {
    let mut s = String::from("y,u\n");
    for (y, u) in profile {
        let _ = writeln!(s, "{y},{u:.6}");
    }
    std::fs::write(path, s).map_err(io_err(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scored_fields_read_back_as_plain_fields() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.csv");
        let vs = [
            Vector {
                x: 16.0,
                y: 8.0,
                u: 1.25,
                v: -0.5,
                state: State::Valid,
            },
            Vector {
                x: 32.0,
                y: 8.0,
                u: 9.0,
                v: 9.0,
                state: State::Invalid,
            },
        ];
        write_vectors_scored(&p, &vs, &[(1.8, 0.61), (0.0, 0.0)]).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.starts_with("x,y,u,v,flag,peak_ratio,correlation\n"));
        assert!(text.contains(",0,1.8000,0.6100\n"));
        let back = read_vectors(&p).unwrap();
        assert_eq!(back[0], vs[0]);
        assert_eq!(
            (back[1].u, back[1].v, back[1].state),
            (0.0, 0.0, State::Invalid)
        );
        assert!(write_vectors_scored(&p, &vs, &[(1.0, 1.0)]).is_err());
        write_vectors_uncertain(&p, &vs, &[(0.05, 0.07), (f64::INFINITY, f64::INFINITY)]).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.starts_with("x,y,u,v,flag,sigma_u,sigma_v\n"), "{text}");
        assert!(text.contains(",0,0.050000,0.070000\n"), "{text}");
        assert!(text.contains(",2,inf,inf\n"), "{text}");
        assert_eq!(read_vectors(&p).unwrap()[0], vs[0]);
    }
}
