//! The camera's files (FORMATS.md): Vidar `.dat` spike streams, `scene.json`,
//! gray images, vector and profile CSVs, and the real-capture `.npz`.

pub mod csv;
pub mod dat;
pub mod image;
pub mod meta;
pub mod npz;

use std::path::PathBuf;

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
    /// No width/height on the command line and no `scene.json` beside the file.
    #[error("{0}: width and height unknown: give --width and --height, or keep scene.json beside the file")]
    NoSize(PathBuf),
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

pub(crate) fn io_err(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> FormatError + '_ {
    move |source| FormatError::Io {
        path: path.to_path_buf(),
        source,
    }
}
