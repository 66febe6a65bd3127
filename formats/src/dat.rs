//! Vidar `.dat` spike streams (docs/formats.md): no header, planes of `W*H/8`
//! bytes back to back, pixel `p = row*W + col` over the stored rows, LSB
//! first, stored rows upside down (image row r is stored row H−1−r).
//!
//! The reader streams: it holds one plane at a time (bounded memory), seeks
//! straight to the planes a caller needs, strips a head of columns (real
//! 416-column captures of the 400×250 camera), and hands planes over in the
//! stored row order the core works in. Images are flipped upright only at
//! the end ([`unpack_upright`]). A size that is not a whole number of planes
//! is an error unless the caller allows it — never dropped silently.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::{io_err, FormatError};

/// How to read a `.dat`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DatOptions {
    /// Rows are stored bottom-up (the camera's layout). `false` for the
    /// unflipped output of some public simulators.
    pub flip: bool,
    /// Columns to drop at the right of every row (16 for 416-wide captures).
    pub strip_head: u16,
    /// Read the whole planes of a file whose last plane is truncated (the
    /// remainder is reported by [`DatReader::truncated_bytes`]).
    pub allow_truncated: bool,
}

impl Default for DatOptions {
    fn default() -> Self {
        DatOptions {
            flip: true,
            strip_head: 0,
            allow_truncated: false,
        }
    }
}

/// Bytes of one plane, or the error for sizes that are not whole bytes or
/// exceed [`MAX_FRAME_PIXELS`](crate::MAX_FRAME_PIXELS).
pub fn plane_bytes(width: u16, height: u16) -> Result<usize, FormatError> {
    let px = usize::from(width) * usize::from(height);
    if px == 0 || px % 8 != 0 {
        return Err(FormatError::NotWholeBytes {
            width: u32::from(width),
            height: u32::from(height),
        });
    }
    if px as u64 > crate::MAX_FRAME_PIXELS {
        return Err(FormatError::TooLarge {
            what: format!("a {width}x{height} plane"),
            got: px as u64,
            limit: crate::MAX_FRAME_PIXELS,
        });
    }
    Ok(px / 8)
}

/// A streaming `.dat` reader over a file (or, with
/// [`DatReader::from_reader`], any seekable bytes).
#[derive(Debug)]
pub struct DatReader<R = BufReader<File>> {
    path: PathBuf,
    file: R,
    file_width: u16,
    width: u16,
    height: u16,
    planes: u64,
    next: u64,
    truncated: u64,
    flip: bool,
    raw: Vec<u8>,
}

impl DatReader {
    /// Opens `path` as planes of `width × height` (the file's own width,
    /// head included).
    pub fn open(
        path: &Path,
        width: u16,
        height: u16,
        opts: DatOptions,
    ) -> Result<DatReader, FormatError> {
        let file = File::open(path).map_err(io_err(path))?;
        DatReader::from_reader(
            BufReader::with_capacity(1 << 16, file),
            path,
            width,
            height,
            opts,
        )
    }
}

impl<R: Read + Seek> DatReader<R> {
    /// Reads planes of `width × height` from `source`; `name` names it in
    /// errors. Sizes are checked before the one plane buffer is allocated.
    pub fn from_reader(
        mut source: R,
        name: &Path,
        width: u16,
        height: u16,
        opts: DatOptions,
    ) -> Result<DatReader<R>, FormatError> {
        let pb = plane_bytes(width, height)?;
        if opts.strip_head >= width {
            return Err(FormatError::HeadTooWide {
                head: opts.strip_head,
                width,
            });
        }
        let out_w = width - opts.strip_head;
        if opts.strip_head > 0 {
            plane_bytes(out_w, height)?;
        }
        let len = source.seek(SeekFrom::End(0)).map_err(io_err(name))?;
        source.seek(SeekFrom::Start(0)).map_err(io_err(name))?;
        if len == 0 {
            return Err(FormatError::Empty(name.to_path_buf()));
        }
        let planes = len / pb as u64;
        let extra = len % pb as u64;
        if planes == 0 || (extra != 0 && !opts.allow_truncated) {
            return Err(FormatError::Truncated {
                path: name.to_path_buf(),
                planes,
                plane_bytes: pb,
                extra,
            });
        }
        Ok(DatReader {
            path: name.to_path_buf(),
            file: source,
            file_width: width,
            width: out_w,
            height,
            planes,
            next: 0,
            truncated: extra,
            flip: opts.flip,
            raw: vec![0; pb],
        })
    }

    /// Whole planes in the file.
    pub fn planes(&self) -> u64 {
        self.planes
    }
    /// Width of the planes handed out (head stripped), px.
    pub fn width(&self) -> u16 {
        self.width
    }
    /// Height, px.
    pub fn height(&self) -> u16 {
        self.height
    }
    /// Whether stored rows are bottom-up.
    pub fn flip(&self) -> bool {
        self.flip
    }
    /// Bytes after the last whole plane (0 unless truncated reading was allowed).
    pub fn truncated_bytes(&self) -> u64 {
        self.truncated
    }
    /// Bytes of a plane handed out.
    pub fn out_plane_bytes(&self) -> usize {
        usize::from(self.width) * usize::from(self.height) / 8
    }

    /// Moves to plane `i` (the next read returns it).
    pub fn seek_plane(&mut self, i: u64) -> Result<(), FormatError> {
        let i = i.min(self.planes);
        self.file
            .seek(SeekFrom::Start(i * self.raw.len() as u64))
            .map_err(io_err(&self.path))?;
        self.next = i;
        Ok(())
    }

    /// Reads the next plane into `out` (stored row order, head stripped,
    /// `out_plane_bytes()` bytes). `Ok(false)` after the last plane.
    pub fn read_plane(&mut self, out: &mut [u8]) -> Result<bool, FormatError> {
        if out.len() != self.out_plane_bytes() {
            return Err(FormatError::Parse {
                path: self.path.clone(),
                msg: format!(
                    "a plane buffer of {} bytes, expected {}",
                    out.len(),
                    self.out_plane_bytes()
                ),
            });
        }
        if self.next >= self.planes {
            return Ok(false);
        }
        if self.width == self.file_width {
            // The plane as stored: read straight into `out` (through `raw`
            // it was copied twice, 3 % of the firmware simulator's run).
            self.file
                .read_exact(&mut out[..self.raw.len()])
                .map_err(io_err(&self.path))?;
        } else {
            self.file
                .read_exact(&mut self.raw)
                .map_err(io_err(&self.path))?;
            repack(&self.raw, self.file_width, self.width, self.height, out);
        }
        self.next += 1;
        Ok(true)
    }

    /// Reads planes `first..first+n` (clipped to the file) back to back.
    pub fn read_range(&mut self, first: u64, n: u64) -> Result<Vec<u8>, FormatError> {
        self.seek_plane(first)?;
        let pb = self.out_plane_bytes();
        let n = n.min(self.planes.saturating_sub(first)) as usize;
        let mut out = vec![0u8; pb * n];
        for chunk in out.chunks_exact_mut(pb) {
            self.read_plane(chunk)?;
        }
        Ok(out)
    }
}

/// Drops the columns past `out_w` of every row of a plane.
fn repack(raw: &[u8], in_w: u16, out_w: u16, h: u16, out: &mut [u8]) {
    out.fill(0);
    let (in_w, out_w) = (usize::from(in_w), usize::from(out_w));
    for r in 0..usize::from(h) {
        for c in 0..out_w {
            let p = r * in_w + c;
            if (raw[p / 8] >> (p % 8)) & 1 == 1 {
                let q = r * out_w + c;
                out[q / 8] |= 1 << (q % 8);
            }
        }
    }
}

/// Writes the bits of one row (bit `j % 64` of word `j / 64` = column j)
/// into stored row `row` of a packed plane of width `w`.
pub fn pack_row(bits: &[u64], row: usize, w: usize, plane: &mut [u8]) {
    let bit0 = row * w;
    if bit0.is_multiple_of(8) {
        let base = bit0 / 8;
        for (b, out) in plane[base..base + w.div_ceil(8)].iter_mut().enumerate() {
            let word = bits.get(b / 8).copied().unwrap_or(0);
            let mut v = (word >> (8 * (b % 8))) as u8;
            if 8 * b + 8 > w {
                v &= (1u16 << (w - 8 * b)).wrapping_sub(1) as u8;
                *out |= v;
            } else {
                *out = v;
            }
        }
    } else {
        for j in 0..w {
            if (bits.get(j / 64).copied().unwrap_or(0) >> (j % 64)) & 1 == 1 {
                let p = bit0 + j;
                plane[p / 8] |= 1 << (p % 8);
            }
        }
    }
}

/// One plane as 0/1 bytes, upright (row 0 at the top): flipped when the
/// file's rows are bottom-up.
pub fn unpack_upright(plane: &[u8], w: u16, h: u16, flip: bool) -> Vec<u8> {
    let (w, h) = (usize::from(w), usize::from(h));
    let mut out = vec![0u8; w * h];
    for r in 0..h {
        let stored = if flip { h - 1 - r } else { r };
        for c in 0..w {
            let p = stored * w + c;
            out[r * w + c] = (plane[p / 8] >> (p % 8)) & 1;
        }
    }
    out
}

/// Spike counts per pixel over planes, upright; `planes` back to back.
pub fn count_upright(planes: &[u8], w: u16, h: u16, flip: bool) -> Vec<u32> {
    let pb = usize::from(w) * usize::from(h) / 8;
    let mut counts = vec![0u32; usize::from(w) * usize::from(h)];
    for plane in planes.chunks_exact(pb) {
        for (c, b) in counts.iter_mut().zip(unpack_upright(plane, w, h, flip)) {
            *c += u32::from(b);
        }
    }
    counts
}

/// A `.dat` writer: planes must already be in the camera's layout.
#[derive(Debug)]
pub struct DatWriter {
    path: PathBuf,
    file: BufWriter<File>,
    plane_bytes: usize,
    planes: u64,
}

impl DatWriter {
    /// Creates `path` for planes of `width × height`.
    pub fn create(path: &Path, width: u16, height: u16) -> Result<DatWriter, FormatError> {
        let plane_bytes = plane_bytes(width, height)?;
        let file = File::create(path).map_err(io_err(path))?;
        Ok(DatWriter {
            path: path.to_path_buf(),
            file: BufWriter::new(file),
            plane_bytes,
            planes: 0,
        })
    }

    /// Appends planes (a whole number of them).
    pub fn write_planes(&mut self, planes: &[u8]) -> Result<(), FormatError> {
        if !planes.len().is_multiple_of(self.plane_bytes) {
            return Err(FormatError::Parse {
                path: self.path.clone(),
                msg: format!(
                    "{} bytes are not whole planes of {}",
                    planes.len(),
                    self.plane_bytes
                ),
            });
        }
        self.file.write_all(planes).map_err(io_err(&self.path))?;
        self.planes += (planes.len() / self.plane_bytes) as u64;
        Ok(())
    }

    /// Flushes; returns the planes written.
    pub fn finish(mut self) -> Result<u64, FormatError> {
        self.file.flush().map_err(io_err(&self.path))?;
        Ok(self.planes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn reader(bytes: Vec<u8>, w: u16, h: u16) -> Result<DatReader<Cursor<Vec<u8>>>, FormatError> {
        DatReader::from_reader(
            Cursor::new(bytes),
            Path::new("t.dat"),
            w,
            h,
            DatOptions::default(),
        )
    }

    #[test]
    fn sizes_are_bounded_before_the_plane_buffer_is_allocated() {
        let e = reader(vec![0; 8], 65535, 65528).unwrap_err();
        assert!(matches!(e, FormatError::TooLarge { .. }), "{e}");
        assert!(plane_bytes(8192, 8192).is_ok());
        assert!(plane_bytes(8200, 8192).is_err());
        assert!(matches!(
            reader(Vec::new(), 8, 8).unwrap_err(),
            FormatError::Empty(_)
        ));
        assert!(matches!(
            reader(vec![0; 7], 8, 8).unwrap_err(),
            FormatError::Truncated { .. }
        ));
    }

    #[test]
    fn a_plane_buffer_of_the_wrong_size_is_an_error_not_a_panic() {
        let mut r = reader(vec![0xff; 16], 8, 8).unwrap();
        assert_eq!(r.planes(), 2);
        assert!(r.read_plane(&mut [0u8; 3]).is_err());
        let mut p = [0u8; 8];
        assert!(r.read_plane(&mut p).unwrap());
        assert_eq!(p, [0xff; 8]);
    }
}
