//! Dense displacement fields, one vector per pixel: Middlebury `.flo` (the
//! format of optical-flow benchmarks and of the spike-flow datasets) and
//! NumPy `.npy` (`float32`, shape `(height, width, 2)`). The extension picks
//! the format. Units: px per pair, `u` right, `v` down the rows (upright
//! rows, row 0 at the top), as the vector CSV. Sizes from a file are bounded
//! by [`MAX_FRAME_PIXELS`] before anything is allocated.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

use ndarray::Array3;
use ndarray_npy::WriteNpyExt;

use crate::npz::read_header;
use crate::{io_err, FormatError, MAX_FRAME_PIXELS};

/// A displacement per pixel, row-major, upright.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseField {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Displacement right, px per pair (`width × height`).
    pub u: Vec<f32>,
    /// Displacement down, px per pair.
    pub v: Vec<f32>,
}

/// `.flo`'s tag: the float 202021.25, "PIEH" in its bytes.
const FLO_TAG: f32 = 202_021.25;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Flo,
    Npy,
}

fn kind(path: &Path) -> Result<Kind, FormatError> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("flo") => Ok(Kind::Flo),
        Some("npy") => Ok(Kind::Npy),
        _ => Err(FormatError::Parse {
            path: path.to_path_buf(),
            msg: "a dense field is .flo or .npy".into(),
        }),
    }
}

impl DenseField {
    /// A zero field.
    pub fn zeros(width: usize, height: usize) -> DenseField {
        DenseField {
            width,
            height,
            u: vec![0.0; width * height],
            v: vec![0.0; width * height],
        }
    }

    /// Mean end-point error against `truth` over pixels where `keep` (if
    /// given) is true, px: the mean of |(u, v) − (u*, v*)|, as optical-flow
    /// benchmarks report it. `None` when the sizes differ or no pixel counts.
    pub fn epe(&self, truth: &DenseField, keep: Option<&[bool]>) -> Option<f64> {
        if (self.width, self.height) != (truth.width, truth.height) {
            return None;
        }
        let (mut s, mut n) = (0.0f64, 0usize);
        for i in 0..self.u.len() {
            if keep.is_some_and(|k| !k.get(i).copied().unwrap_or(false)) {
                continue;
            }
            let du = f64::from(self.u[i]) - f64::from(truth.u[i]);
            let dv = f64::from(self.v[i]) - f64::from(truth.v[i]);
            if du.is_finite() && dv.is_finite() {
                s += du.hypot(dv);
                n += 1;
            }
        }
        (n > 0).then(|| s / n as f64)
    }
}

/// Writes `f` to `path` (`.flo` or `.npy` by extension).
pub fn write_dense(path: &Path, f: &DenseField) -> Result<(), FormatError> {
    let k = kind(path)?;
    let n = f.width * f.height;
    if f.u.len() != n || f.v.len() != n {
        return Err(FormatError::Parse {
            path: path.to_path_buf(),
            msg: format!(
                "{} and {} samples for {}x{} px",
                f.u.len(),
                f.v.len(),
                f.width,
                f.height
            ),
        });
    }
    let file = File::create(path).map_err(io_err(path))?;
    let mut w = BufWriter::new(file);
    match k {
        Kind::Flo => {
            let dim = |d: usize| {
                i32::try_from(d).map_err(|_| FormatError::TooLarge {
                    what: format!("{}: a side of {d} px", path.display()),
                    got: d as u64,
                    limit: i32::MAX as u64,
                })
            };
            let mut bytes = Vec::with_capacity(12 + 8 * n);
            bytes.extend_from_slice(&FLO_TAG.to_le_bytes());
            bytes.extend_from_slice(&dim(f.width)?.to_le_bytes());
            bytes.extend_from_slice(&dim(f.height)?.to_le_bytes());
            for (u, v) in f.u.iter().zip(&f.v) {
                bytes.extend_from_slice(&u.to_le_bytes());
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            w.write_all(&bytes).map_err(io_err(path))?;
        }
        Kind::Npy => {
            let a = Array3::from_shape_fn((f.height, f.width, 2), |(r, c, k)| {
                let i = r * f.width + c;
                if k == 0 {
                    f.u[i]
                } else {
                    f.v[i]
                }
            });
            a.write_npy(&mut w).map_err(|e| FormatError::Parse {
                path: path.to_path_buf(),
                msg: e.to_string(),
            })?;
        }
    }
    w.flush().map_err(io_err(path))
}

/// Reads a dense field from `path` (`.flo` or `.npy` by extension).
pub fn read_dense(path: &Path) -> Result<DenseField, FormatError> {
    let k = kind(path)?;
    let file = File::open(path).map_err(io_err(path))?;
    read_dense_from(BufReader::new(file), path, k == Kind::Npy)
}

/// Reads a dense field from `r` (`npy`: NumPy, else `.flo`); `name` names
/// it in errors.
pub fn read_dense_from(
    mut r: impl Read,
    name: &Path,
    npy: bool,
) -> Result<DenseField, FormatError> {
    let parse = |msg: String| FormatError::Parse {
        path: name.to_path_buf(),
        msg,
    };
    let (w, h) = if npy {
        let header = read_header(&mut r).map_err(parse)?;
        if header.type_descriptor.to_string() != "'<f4'" {
            return Err(parse(format!(
                "dtype {}, expected little-endian float32",
                header.type_descriptor
            )));
        }
        if header.layout.is_fortran() {
            return Err(parse(
                "Fortran order is not supported (save it C-contiguous)".into(),
            ));
        }
        match header.shape.as_slice() {
            &[h, w, 2] => (w, h),
            s => return Err(parse(format!("shape {s:?}, expected (height, width, 2)"))),
        }
    } else {
        let mut head = [0u8; 12];
        r.read_exact(&mut head)
            .map_err(|e| parse(format!("header: {e}")))?;
        let word = |i: usize| [head[i], head[i + 1], head[i + 2], head[i + 3]];
        if f32::from_le_bytes(word(0)) != FLO_TAG {
            return Err(parse("not a .flo file (no PIEH tag)".into()));
        }
        let (w, h) = (i32::from_le_bytes(word(4)), i32::from_le_bytes(word(8)));
        let (Ok(w), Ok(h)) = (usize::try_from(w), usize::try_from(h)) else {
            return Err(parse(format!("size {w}x{h}")));
        };
        (w, h)
    };
    let px = (w as u64).saturating_mul(h as u64);
    if px == 0 {
        return Err(parse(format!("size {w}x{h}: empty")));
    }
    if px > MAX_FRAME_PIXELS {
        return Err(FormatError::TooLarge {
            what: format!("{}: a {w}x{h} field", name.display()),
            got: px,
            limit: MAX_FRAME_PIXELS,
        });
    }
    let n = px as usize;
    let mut bytes = vec![0u8; n * 8];
    r.read_exact(&mut bytes)
        .map_err(|e| parse(format!("{w}x{h} field: {e}")))?;
    let mut f = DenseField::zeros(w, h);
    for (i, s) in bytes.chunks_exact(8).enumerate() {
        f.u[i] = f32::from_le_bytes([s[0], s[1], s[2], s[3]]);
        f.v[i] = f32::from_le_bytes([s[4], s[5], s[6], s[7]]);
    }
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field() -> DenseField {
        let mut f = DenseField::zeros(5, 3);
        for i in 0..15 {
            f.u[i] = i as f32 * 0.5 - 2.0;
            f.v[i] = -(i as f32) * 0.25;
        }
        f
    }

    #[test]
    fn flo_and_npy_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["f.flo", "f.npy", "F.NPY"] {
            let p = dir.path().join(name);
            write_dense(&p, &field()).unwrap();
            assert_eq!(read_dense(&p).unwrap(), field());
        }
        let flo = std::fs::read(dir.path().join("f.flo")).unwrap();
        assert_eq!(&flo[..4], b"PIEH");
        assert_eq!(flo.len(), 12 + 15 * 8);
        assert!(write_dense(&dir.path().join("f.png"), &field()).is_err());
    }

    #[test]
    fn npy_written_by_numpy_layout_reads() {
        // What numpy.save writes for a (1, 2, 2) float32 array.
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        let mut h = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2), }".to_string();
        while !(10 + h.len() + 1).is_multiple_of(64) {
            h.push(' ');
        }
        h.push('\n');
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        for v in [1.0f32, 2.0, 3.0, 4.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let f = read_dense_from(&b[..], Path::new("x.npy"), true).unwrap();
        assert_eq!((f.u, f.v), (vec![1.0, 3.0], vec![2.0, 4.0]));
    }

    #[test]
    fn bad_files_are_refused_before_allocating() {
        let huge = [
            FLO_TAG.to_le_bytes(),
            100_000i32.to_le_bytes(),
            100_000i32.to_le_bytes(),
        ]
        .concat();
        assert!(matches!(
            read_dense_from(&huge[..], Path::new("x.flo"), false),
            Err(FormatError::TooLarge { .. })
        ));
        let neg = [
            FLO_TAG.to_le_bytes(),
            (-1i32).to_le_bytes(),
            4i32.to_le_bytes(),
        ]
        .concat();
        assert!(read_dense_from(&neg[..], Path::new("x.flo"), false).is_err());
        let short = [
            FLO_TAG.to_le_bytes(),
            4i32.to_le_bytes(),
            4i32.to_le_bytes(),
        ]
        .concat();
        assert!(read_dense_from(&short[..], Path::new("x.flo"), false).is_err());
        assert!(read_dense_from(&b"PIEX"[..], Path::new("x.flo"), false).is_err());
    }

    #[test]
    fn epe_is_the_mean_vector_distance() {
        let t = DenseField::zeros(2, 1);
        let mut f = DenseField::zeros(2, 1);
        f.u = vec![3.0, 0.0];
        f.v = vec![4.0, 1.0];
        assert_eq!(f.epe(&t, None), Some(3.0));
        assert_eq!(f.epe(&t, Some(&[false, true])), Some(1.0));
        assert_eq!(f.epe(&DenseField::zeros(1, 1), None), None);
    }
}
