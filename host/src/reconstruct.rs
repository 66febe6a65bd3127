//! Frames from spike files through the core: TFP, TFI or adaptive at any
//! tick of a `.dat` (streamed: only the planes the window needs are read) or
//! of an in-memory recording.

use std::path::Path;

use spiv_core::window::{tfi, tfp};
pub use spiv_core::Method;
use spiv_core::{reconstruct_adaptive, FrameStats, History, Params, PlaneView};
use spiv_formats::capture::Capture;
use spiv_formats::dat::{DatOptions, DatReader};
use spiv_formats::npz::read_npz_spikes;
use spiv_formats::FormatError;

use crate::Error;
use spiv_core::buffers::{HistoryBuf, WorkspaceBuf};

/// A reconstructed frame, upright (row 0 at the top).
#[derive(Debug, Clone)]
pub struct Frame {
    /// Width, px.
    pub width: u16,
    /// Height, px.
    pub height: u16,
    /// Gray levels `0..=full_scale`.
    pub data: Vec<u16>,
    /// The core's counts (adaptive only).
    pub stats: Option<FrameStats>,
}

/// Planes of a recording in the core's stored row order.
#[derive(Debug, Clone)]
pub struct Planes {
    /// Width, px.
    pub width: u16,
    /// Height, px.
    pub height: u16,
    /// Stored rows are bottom-up.
    pub flip: bool,
    /// Columns of the output (≤ `width`; padding columns are cropped).
    pub crop_width: u16,
    /// Tick of the first plane held.
    pub first: u64,
    /// Planes back to back.
    pub data: Vec<u8>,
}

impl Planes {
    /// Planes of a simulation held in memory (`simulate_planes`): stored
    /// bottom-up like the sensor's file, from tick 0, no padding columns.
    pub fn simulated(width: u16, height: u16, data: Vec<u8>) -> Planes {
        Planes {
            width,
            height,
            flip: true,
            crop_width: width,
            first: 0,
            data,
        }
    }
}

/// Runs `method` at file tick `at` over `planes` (which must hold the window).
pub fn frame_from_planes(
    planes: &Planes,
    at: u64,
    method: Method,
    window: u16,
    p: &Params,
) -> Result<Frame, Error> {
    let (w, h) = (planes.width, planes.height);
    let pb = usize::from(w) * usize::from(h) / 8;
    let n = (planes.data.len() / pb.max(1)) as u64;
    if at < planes.first || at >= planes.first + n {
        return Err(Error::TickOutside {
            tick: at,
            planes: planes.first + n,
        });
    }
    let mut ring = planes.ring(at, window)?;
    let k = ring.tick;
    let hist = ring.history()?;
    let px = usize::from(w) * usize::from(h);
    let mut out = vec![0u16; px];
    let fs = p.full_scale;
    let stats = match method {
        Method::Mc => return Err(Error::NeedsMotion),
        Method::Ladder => return Err(Error::Ladder),
        Method::Tfp => {
            let mut counts = vec![0u8; px];
            tfp(&hist, k, window, fs, &mut counts, &mut out)?;
            None
        }
        Method::Tfi => {
            tfi(&hist, k, window, fs, &mut out)?;
            None
        }
        Method::Adaptive => {
            let rows = spiv_core::state::strip_rows(w, h, p.margin);
            let mut ws = WorkspaceBuf::new(spiv_core::WorkspaceSizes::for_strip(w, rows));
            let p = Params {
                n_max: window,
                ..*p
            };
            Some(reconstruct_adaptive(
                &hist,
                k,
                &p,
                &mut ws.workspace()?,
                &mut out,
            )?)
        }
    };
    Ok(Frame {
        width: planes.crop_width.min(w),
        height: h,
        data: planes.output(&out),
        stats,
    })
}

/// Planes in a core history ring, and where a file tick falls in it.
#[derive(Debug)]
pub struct Ring {
    buf: HistoryBuf,
    pushed: u32,
    /// The ring tick of the file tick asked for.
    pub tick: u32,
}

impl Ring {
    /// The history over the planes pushed.
    pub fn history(&mut self) -> Result<History<'_>, spiv_core::Error> {
        self.buf.resume(self.pushed)
    }
}

impl Planes {
    /// The planes in a ring at least `window` deep (at most the 256 the
    /// core holds: the last ones), with the ring tick of file tick `k`.
    pub fn ring(&self, k: u64, window: u16) -> Result<Ring, Error> {
        let (w, h) = (self.width, self.height);
        let pb = usize::from(w) * usize::from(h) / 8;
        let n = self.data.len() / pb.max(1);
        // `max` then `min`: the bounds cross for a window above 256, which
        // the core then refuses.
        let depth = n.max(usize::from(window.max(2))).min(256) as u16;
        let mut buf = HistoryBuf::new(w, h, depth)?;
        let mut hist = buf.history()?;
        // Ring ticks count from 0 at the first plane pushed: the last `depth`.
        let skip = n.saturating_sub(usize::from(depth));
        for chunk in self.data.chunks_exact(pb).skip(skip) {
            hist.push(&PlaneView::new(chunk, w, h)?)?;
        }
        let pushed = hist.next_tick();
        let tick = k
            .checked_sub(self.first + skip as u64)
            .and_then(|t| u32::try_from(t).ok())
            .ok_or(Error::TickOutside {
                tick: k,
                planes: self.first + n as u64,
            })?;
        Ok(Ring { buf, pushed, tick })
    }

    /// A frame the core made from these planes (stored row order, `width`
    /// wide) as the user sees it: upright, padding columns cropped
    /// (`crop_width` wide).
    pub fn output(&self, stored: &[u16]) -> Vec<u16> {
        let w = self.width;
        let up = upright(stored, w, self.flip);
        let cw = self.crop_width.min(w);
        if cw == w {
            up
        } else {
            up.chunks_exact(usize::from(w))
                .flat_map(|r| r[..usize::from(cw)].iter().copied())
                .collect()
        }
    }
}

/// Stored row order to upright.
pub fn upright<T: Copy>(stored: &[T], w: u16, flip: bool) -> Vec<T> {
    if !flip {
        return stored.to_vec();
    }
    let w = usize::from(w);
    stored
        .chunks_exact(w)
        .rev()
        .flat_map(|r| r.iter().copied())
        .collect()
}

/// Options of [`frame_from_file`].
#[derive(Debug, Clone, Copy)]
pub struct FileOptions {
    /// Width, px (else from `scene.json`).
    pub width: Option<u16>,
    /// Height, px (else from `scene.json`).
    pub height: Option<u16>,
    /// `.dat` reading options.
    pub dat: DatOptions,
}

/// Reads only the planes a window of `window` ticks centred on `at` needs
/// from a `.dat` (or a `.npz` capture) and makes the frame.
pub fn frame_from_file(
    path: &Path,
    at: u64,
    method: Method,
    window: u16,
    p: &Params,
    opts: FileOptions,
) -> Result<Frame, Error> {
    if !(1..=255).contains(&window) {
        return Err(Error::Window(u32::from(window)));
    }
    let is_npz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let planes = if is_npz {
        let s = read_npz_spikes(path)?;
        Planes {
            width: s.packed_width,
            height: s.height,
            flip: false,
            crop_width: s.width,
            first: 0,
            data: s.planes,
        }
    } else {
        let meta = Capture::beside(path)?;
        let (w, h) = match (opts.width, opts.height, &meta) {
            (Some(w), Some(h), _) => (w, h),
            (None, None, Some(m)) => (m.width, m.height),
            _ => return Err(FormatError::NoSize(path.to_path_buf()).into()),
        };
        let mut r = DatReader::open(path, w, h, opts.dat)?;
        if at >= r.planes() {
            return Err(Error::TickOutside {
                tick: at,
                planes: r.planes(),
            });
        }
        let first = at.saturating_sub(u64::from(window / 2));
        let data = r.read_range(first, u64::from(window))?;
        Planes {
            width: r.width(),
            height: r.height(),
            flip: r.flip(),
            crop_width: r.width(),
            first,
            data,
        }
    };
    frame_from_planes(&planes, at, method, window, p)
}
