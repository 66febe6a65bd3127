//! The simulator's one error type: what every fallible public function of
//! `spiv-firmware-sim` returns (the scene, the simulation's files, the
//! simulated sidecar and its drivers).

use spiv_core::error::LinkError;
use spiv_formats::FormatError;

use crate::scene::SceneKind;

/// Why a simulation or a simulated sidecar stopped.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The core refused: a plane, a frame the wire cannot carry, a
    /// configuration the sidecar cannot run.
    #[error("core: {0}")]
    Core(#[from] spiv_core::Error),
    /// The link.
    #[error("link: {0}")]
    Link(#[from] std::io::Error),
    /// A live-loop schedule the firmware cannot run.
    #[error("schedule: {0}")]
    Schedule(&'static str),
    /// Reading or writing a recording, its metadata or its frames.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// A scene name that is none of [`SceneKind::ALL`].
    #[error("unknown scene '{0}' (one of: {names})", names = SceneKind::ALL.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", "))]
    UnknownScene(String),
}

impl From<LinkError<std::io::Error>> for Error {
    fn from(e: LinkError<std::io::Error>) -> Self {
        match e {
            LinkError::Core(c) => Error::Core(c),
            LinkError::Link(l) => Error::Link(l),
        }
    }
}

impl Error {
    /// Whether the error is the operating system's (a file or a link that
    /// could not be read or written) rather than a value refused.
    pub fn is_io(&self) -> bool {
        matches!(self, Error::Link(_) | Error::Format(FormatError::Io { .. }))
    }
}
