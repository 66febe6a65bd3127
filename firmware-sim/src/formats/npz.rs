//! The real capture of `shared/data/spike/` (`.npz` with `spk.npy`, uint8
//! T×H×W of 0/1, already upright and unpacked).

use std::fs::File;
use std::path::Path;

use ndarray::Array3;
use ndarray_npy::NpzReader;

use super::{io_err, FormatError};

/// A spike recording held unpacked in memory.
#[derive(Debug, Clone)]
pub struct NpzSpikes {
    /// Width of the capture, px.
    pub width: u16,
    /// Width of the packed planes, px: `width`, or the next multiple of 8
    /// when `width × height` is not whole bytes (the extra columns are
    /// zero; crop them from any output).
    pub packed_width: u16,
    /// Height, px.
    pub height: u16,
    /// Planes packed LSB first in **upright** row order (read them with
    /// `flip = false`), back to back.
    pub planes: Vec<u8>,
    /// Planes.
    pub ticks: usize,
}

/// Reads `spk.npy` from an `.npz`.
pub fn read_npz_spikes(path: &Path) -> Result<NpzSpikes, FormatError> {
    let parse = |msg: String| FormatError::Parse {
        path: path.to_path_buf(),
        msg,
    };
    let file = File::open(path).map_err(io_err(path))?;
    let mut npz = NpzReader::new(file).map_err(|e| parse(e.to_string()))?;
    let spk: Array3<u8> = npz
        .by_name("spk")
        .or_else(|_| npz.by_name("spk.npy"))
        .map_err(|e| parse(e.to_string()))?;
    let (t, h, w) = spk.dim();
    let (width, height) = (
        u16::try_from(w).map_err(|_| parse("too wide".into()))?,
        u16::try_from(h).map_err(|_| parse("too tall".into()))?,
    );
    let packed_width = if (w * h) % 8 == 0 {
        width
    } else {
        width.next_multiple_of(8)
    };
    let pw = usize::from(packed_width);
    let pb = super::dat::plane_bytes(packed_width, height)?;
    let mut planes = vec![0u8; pb * t];
    for ((k, r, c), &v) in spk.indexed_iter() {
        if v > 1 {
            return Err(parse(format!("spk[{k},{r},{c}] = {v}, not 0/1")));
        }
        if v == 1 {
            let p = r * pw + c;
            planes[k * pb + p / 8] |= 1 << (p % 8);
        }
    }
    Ok(NpzSpikes {
        width,
        packed_width,
        height,
        planes,
        ticks: t,
    })
}
