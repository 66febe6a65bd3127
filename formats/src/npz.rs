//! Unpacked spike captures in NumPy archives, like
//! `data/spike/spikezoo_uhsr_real_250x250_200f.npz`: `spk.npy`, uint8
//! T×H×W of 0/1, upright, C order.
//!
//! The archive is untrusted input, so nothing is allocated from a size it
//! declares before that size is checked: the `.npy` header is at most
//! 64 KiB, each plane at most [`MAX_FRAME_PIXELS`], the whole array at most
//! [`MAX_NPZ_SAMPLES`] samples, and planes are read and packed one at a time
//! (memory grows with the data actually present, not with the shape the
//! header claims). The header itself is parsed by `ndarray-npy`; the zip
//! container by `zip`.

use std::fs::File;
use std::io::{Cursor, Read, Seek};
use std::path::Path;

use ndarray_npy::npy::header::{Header, Layout};

use crate::{io_err, FormatError, MAX_FRAME_PIXELS, MAX_NPZ_SAMPLES};

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

/// Longest `.npy` header accepted, bytes (NumPy writes about 128).
const MAX_HEADER: usize = 64 * 1024;

/// Reads `spk.npy` from an `.npz` file.
pub fn read_npz_spikes(path: &Path) -> Result<NpzSpikes, FormatError> {
    let file = File::open(path).map_err(io_err(path))?;
    read_npz_spikes_from(std::io::BufReader::new(file), path)
}

/// Reads `spk.npy` from `.npz` bytes in `source`; `name` names it in errors.
pub fn read_npz_spikes_from<R: Read + Seek>(
    source: R,
    name: &Path,
) -> Result<NpzSpikes, FormatError> {
    let parse = |msg: String| FormatError::Parse {
        path: name.to_path_buf(),
        msg,
    };
    let mut zip = zip::ZipArchive::new(source).map_err(|e| parse(format!("not an npz: {e}")))?;
    let entry = ["spk.npy", "spk"]
        .into_iter()
        .find(|n| zip.index_for_name(n).is_some())
        .ok_or_else(|| parse("no array named spk in the archive".into()))?;
    let mut npy = zip
        .by_name(entry)
        .map_err(|e| parse(format!("{entry}: {e}")))?;
    let header = read_header(&mut npy).map_err(|m| parse(format!("{entry}: {m}")))?;
    // The descriptor as its Python literal: a one-byte unsigned integer.
    if !["'|u1'", "'<u1'", "'>u1'"].contains(&header.type_descriptor.to_string().as_str()) {
        return Err(parse(format!(
            "{entry}: dtype {}, expected uint8",
            header.type_descriptor
        )));
    }
    if header.layout == Layout::Fortran {
        return Err(parse(format!(
            "{entry}: Fortran order is not supported (save it C-contiguous)"
        )));
    }
    let &[t, h, w] = header.shape.as_slice() else {
        return Err(parse(format!(
            "{entry}: shape {:?}, expected (ticks, height, width)",
            header.shape
        )));
    };
    let (width, height) = (
        u16::try_from(w).map_err(|_| parse(format!("width {w} over 65535")))?,
        u16::try_from(h).map_err(|_| parse(format!("height {h} over 65535")))?,
    );
    let px = w * h;
    if px as u64 > MAX_FRAME_PIXELS {
        return Err(FormatError::TooLarge {
            what: format!("{}: a {w}x{h} plane", name.display()),
            got: px as u64,
            limit: MAX_FRAME_PIXELS,
        });
    }
    let samples = (px as u64).saturating_mul(t as u64);
    if samples > MAX_NPZ_SAMPLES {
        return Err(FormatError::TooLarge {
            what: format!("{}: spike samples {t}x{h}x{w}", name.display()),
            got: samples,
            limit: MAX_NPZ_SAMPLES,
        });
    }
    let packed_width = if px % 8 == 0 {
        width
    } else {
        width.next_multiple_of(8)
    };
    let pw = usize::from(packed_width);
    let pb = crate::dat::plane_bytes(packed_width, height)?;
    let mut planes = Vec::new();
    let mut plane = vec![0u8; px];
    for k in 0..t {
        npy.read_exact(&mut plane)
            .map_err(|e| parse(format!("{entry}: plane {k} of {t}: {e}")))?;
        let base = planes.len();
        planes.resize(base + pb, 0);
        for (i, &v) in plane.iter().enumerate() {
            if v > 1 {
                let (r, c) = (i / w.max(1), i % w.max(1));
                return Err(parse(format!("spk[{k},{r},{c}] = {v}, not 0/1")));
            }
            if v == 1 {
                let p = (i / w) * pw + i % w;
                planes[base + p / 8] |= 1 << (p % 8);
            }
        }
    }
    let mut extra = [0u8; 1];
    if npy
        .read(&mut extra)
        .map_err(|e| parse(format!("{entry}: {e}")))?
        != 0
    {
        return Err(parse(format!(
            "{entry}: more data than its shape {:?}",
            header.shape
        )));
    }
    Ok(NpzSpikes {
        width,
        packed_width,
        height,
        planes,
        ticks: t,
    })
}

/// The `.npy` header, its length checked before it is read.
pub(crate) fn read_header(r: &mut impl Read) -> Result<Header, String> {
    // Magic (6), version (2), header length (2 in version 1, else 4).
    let mut pre = [0u8; 12];
    r.read_exact(&mut pre[..10]).map_err(|e| e.to_string())?;
    let (len, pre_len) = if pre[6] == 1 {
        (usize::from(u16::from_le_bytes([pre[8], pre[9]])), 10)
    } else {
        r.read_exact(&mut pre[10..]).map_err(|e| e.to_string())?;
        let n = u32::from_le_bytes([pre[8], pre[9], pre[10], pre[11]]);
        (usize::try_from(n).unwrap_or(usize::MAX), 12)
    };
    if len > MAX_HEADER {
        return Err(format!("npy header of {len} bytes (at most {MAX_HEADER})"));
    }
    Header::from_reader(&mut Cursor::new(&pre[..pre_len]).chain(r)).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// An `.npz` with one stored (uncompressed) `spk.npy` of `header` and `data`.
    fn npz(header: &str, data: &[u8]) -> Vec<u8> {
        let mut npy = b"\x93NUMPY\x01\x00".to_vec();
        let mut h = header.to_string();
        while !(10 + h.len() + 1).is_multiple_of(64) {
            h.push(' ');
        }
        h.push('\n');
        npy.extend((h.len() as u16).to_le_bytes());
        npy.extend(h.as_bytes());
        npy.extend(data);
        let mut z = zip::ZipWriter::new(Cursor::new(Vec::new()));
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored);
        z.start_file("spk.npy", opts).unwrap();
        z.write_all(&npy).unwrap();
        z.finish().unwrap().into_inner()
    }

    fn read(bytes: Vec<u8>) -> Result<NpzSpikes, FormatError> {
        read_npz_spikes_from(Cursor::new(bytes), Path::new("test.npz"))
    }

    #[test]
    fn packs_a_small_capture_upright() {
        // 2 ticks of 2 x 4: a diagonal, then all ones.
        let mut data = vec![1, 0, 0, 0, 0, 1, 0, 0];
        data.extend([1u8; 8]);
        let s = read(npz(
            "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 2, 4), }",
            &data,
        ))
        .unwrap();
        assert_eq!((s.width, s.height, s.ticks, s.packed_width), (4, 2, 2, 4));
        assert_eq!(s.planes, vec![0b0010_0001, 0xff]);
    }

    #[test]
    fn declared_sizes_are_checked_before_allocation() {
        // A shape of 2^60 samples with 8 bytes of data: refused by the bound.
        let e = read(npz(
            "{'descr': '|u1', 'fortran_order': False, 'shape': (1073741824, 1024, 1024), }",
            &[0; 8],
        ))
        .unwrap_err();
        assert!(matches!(e, FormatError::TooLarge { .. }), "{e}");
        // A plane over the frame limit.
        let e = read(npz(
            "{'descr': '|u1', 'fortran_order': False, 'shape': (1, 65535, 65535), }",
            &[0; 8],
        ))
        .unwrap_err();
        assert!(matches!(e, FormatError::TooLarge { .. }), "{e}");
        // Less data than the shape: an error, after reading what is there.
        let e = read(npz(
            "{'descr': '|u1', 'fortran_order': False, 'shape': (100, 64, 64), }",
            &[0; 8],
        ))
        .unwrap_err();
        assert!(e.to_string().contains("plane 0 of 100"), "{e}");
        // More data than the shape.
        let e = read(npz(
            "{'descr': '|u1', 'fortran_order': False, 'shape': (1, 2, 4), }",
            &[0; 9],
        ))
        .unwrap_err();
        assert!(e.to_string().contains("more data"), "{e}");
    }

    #[test]
    fn wrong_types_and_layouts_are_refused() {
        for (header, what) in [
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 2, 4), }",
                "dtype",
            ),
            (
                "{'descr': '|u1', 'fortran_order': True, 'shape': (1, 2, 4), }",
                "Fortran",
            ),
            (
                "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 4), }",
                "shape",
            ),
        ] {
            let e = read(npz(header, &[0; 64])).unwrap_err();
            assert!(e.to_string().contains(what), "{header}: {e}");
        }
        let e = read(npz(
            "{'descr': '|u1', 'fortran_order': False, 'shape': (1, 2, 4), }",
            &[0, 0, 2, 0, 0, 0, 0, 0],
        ))
        .unwrap_err();
        assert!(e.to_string().contains("spk[0,0,2] = 2"), "{e}");
        let e = read(b"PK not a zip".to_vec()).unwrap_err();
        assert!(e.to_string().contains("not an npz"), "{e}");
        // A version-2 header claiming 4 GB.
        let mut npy = b"\x93NUMPY\x02\x00\xff\xff\xff\xff".to_vec();
        npy.extend([b' '; 16]);
        let mut z = zip::ZipWriter::new(Cursor::new(Vec::new()));
        z.start_file("spk.npy", zip::write::SimpleFileOptions::default())
            .unwrap();
        z.write_all(&npy).unwrap();
        let e = read(z.finish().unwrap().into_inner()).unwrap_err();
        assert!(e.to_string().contains("npy header of"), "{e}");
    }
}
