//! # spiv-formats — the files of spike-camera PIV
//!
//! Read and written by the simulator and the host alike; knows neither
//! (docs/formats.md):
//!
//! | module | owns |
//! |---|---|
//! | [`dat`] | Vidar `.dat` spike streams: bit-packed planes, flip, strip-head, streamed reads |
//! | [`npz`] | real captures as `.npz` (one byte per spike sample), packed plane by plane |
//! | [`grid`] | the window grid a vector field lives on, and its centres |
//! | [`capture`] | the layout half of `scene.json` (size, row order, clock, pair) |
//! | [`image`] | gray images (PNG, TIFF, BMP) at 8 or 16 bits |
//! | [`vectors`] | vector fields (`x,y,u,v,flag`, the flag as a [`vectors::State`]) and profiles as CSV |
//!
//! Every size that comes from a file is bounded ([`MAX_FRAME_PIXELS`],
//! [`MAX_NPZ_SAMPLES`]) before anything is allocated for it.
#![warn(missing_docs)]

pub mod capture;
pub mod dat;
pub mod dense;
pub mod grid;
pub mod image;
pub mod netcdf;
pub mod npz;
pub mod vectors;

pub use vectors::{State, Vector};

use std::path::PathBuf;

/// The largest frame or plane any reader accepts, px (8192 × 8192): sizes
/// from a file or a command line are checked against it before anything is
/// allocated for them.
pub const MAX_FRAME_PIXELS: u64 = 8192 * 8192;

/// The most spike samples (ticks × pixels) an unpacked `.npz` capture may
/// declare: 2^30, one byte each before packing (1 GiB).
pub const MAX_NPZ_SAMPLES: u64 = 1 << 30;

/// Everything reading or writing a file can refuse.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The OS said no.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
    /// A size beyond what the readers accept (see [`MAX_FRAME_PIXELS`]).
    #[error("{what}: {got} exceeds the limit of {limit}")]
    TooLarge {
        /// What is too large.
        what: String,
        /// Its size.
        got: u64,
        /// The limit.
        limit: u64,
    },
    /// A `.dat` with no bytes.
    #[error("{0}: empty file, no spike planes")]
    Empty(PathBuf),
    /// `W*H` not a multiple of 8.
    #[error("{width}x{height}: width*height must be a multiple of 8 (a plane is whole bytes)")]
    NotWholeBytes {
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
    },
    /// A size that is not a whole number of planes.
    #[error("{path}: truncated last plane: {planes} whole planes of {plane_bytes} bytes and {extra} bytes left over (wrong size, or pass --allow-truncated to read the whole planes)")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Whole planes.
        planes: u64,
        /// Bytes of one plane.
        plane_bytes: usize,
        /// Bytes beyond the last whole plane.
        extra: u64,
    },
    /// A head as wide as the image.
    #[error("cannot strip a head of {head} columns from a {width}-column file")]
    HeadTooWide {
        /// Columns to strip.
        head: u16,
        /// Columns in the file.
        width: u16,
    },
    /// No width/height given and no `scene.json` beside the file.
    #[error("{0}: width and height unknown: give the width and height, or keep scene.json beside the file")]
    NoSize(PathBuf),
    /// A file that is not a spike recording (by its name or its first bytes).
    #[error("{0}: not a spike recording (spiv reads .dat bit planes and .npz captures)")]
    NotRecording(PathBuf),
    /// A width and height that contradict the `scene.json` beside the file.
    #[error(
        "{path}: {given_w}x{given_h} px given, but scene.json beside it says {meta_w}x{meta_h} px"
    )]
    SizeAgainstMeta {
        /// The recording.
        path: PathBuf,
        /// Width given, px.
        given_w: u16,
        /// Height given, px.
        given_h: u16,
        /// Width in `scene.json`, px.
        meta_w: u16,
        /// Height in `scene.json`, px.
        meta_h: u16,
    },
    /// An image that cannot be read or written.
    #[error("{path}: {msg}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
    /// A malformed text file.
    #[error("{path}: {msg}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
}

/// The folder of the reference spike files (`spike/` inside it): `SPIV_DATA`
/// when set, else the repository's own `data/` (committed with its license,
/// `data/spike/README.md`), so a clone tests itself with nothing beside it.
pub fn reference_data_dir() -> PathBuf {
    std::env::var_os("SPIV_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../data")))
}

/// Maps an I/O error on `path` to [`FormatError::Io`].
pub fn io_err(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> FormatError + '_ {
    move |source| FormatError::Io {
        path: path.to_path_buf(),
        source,
    }
}
