//! The host's one error type: what every fallible public function of
//! `spiv-host` returns. The crates below keep their own (`FormatError`,
//! `PivError`, the core's `Error` and `WireError`, the simulator's
//! `spiv_firmware_sim::Error`); each converts into it with `?`.

use spiv_core::wire::WireError;
use spiv_formats::FormatError;
use spiv_piv::PivError;

use crate::units::{MAX_PIXEL_MM, MAX_TICK_HZ};

/// An error of `spiv-host`: the message is the one line the CLI prints.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a spike, image, vector or netCDF file.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// PIV.
    #[error(transparent)]
    Piv(#[from] PivError),
    /// The core refused its input or its memory.
    #[error("core: {0}")]
    Core(spiv_core::Error),
    /// A wire message, control message or ask that does not hold;
    /// `what` says which.
    #[error("{what}: {source}")]
    Wire {
        /// "wire", "control" or "ask".
        what: &'static str,
        /// What the core's decoder found.
        source: WireError,
    },
    /// The simulated camera or sidecar.
    #[cfg(feature = "sim")]
    #[error(transparent)]
    Sim(#[from] spiv_firmware_sim::Error),
    /// Reading or writing bytes: a source, a report file.
    #[error("{what}: {source}")]
    Io {
        /// Which source or file.
        what: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// Drawing a plot.
    #[error("{path}: {msg}")]
    Plot {
        /// The image file.
        path: String,
        /// What the plotting library said.
        msg: String,
    },
    /// libusb failed or no device matched.
    #[error("usb: {0}")]
    Usb(String),
    /// A `VID:PID` that is not two hex numbers.
    #[error("usb: `{0}` is not VID:PID in hex (e.g. c0de:cafe)")]
    BadId(String),
    /// A stream with no valid message.
    #[error("no valid message in the stream (not spiv wire format?)")]
    NotWire,
    /// The control link back to the sidecar.
    #[error("control: {0}")]
    Control(String),
    /// A frame tick past the recording.
    #[error("tick {tick} is not in the recording (planes 0..{planes})")]
    TickOutside {
        /// The tick asked for.
        tick: u64,
        /// Planes in the recording.
        planes: u64,
    },
    /// A window out of the core's range.
    #[error("window {0} out of range (1..=255)")]
    Window(u32),
    /// `mc` asked of a single frame.
    #[error(
        "method mc needs the host's predicted motion: it runs in the sidecar's loop (`spiv-firmware-sim --method mc`, `spiv run`)"
    )]
    NeedsMotion,
    /// `ladder` asked of a single frame.
    #[error("method ladder makes pairs along a measured flow, not one frame: `spiv flow` runs it")]
    Ladder,
    /// A schedule of pairs or a request that cannot run (the message says
    /// why).
    #[error("{0}")]
    Schedule(String),
    /// A value out of range, named as the CLI names it.
    #[error("{0}")]
    Request(String),
    /// The simulated link delivered no pair of a kind the job needs.
    #[error("the sidecar link delivered no {0} pair")]
    NoPair(&'static str),
    /// A pixel size out of range, mm.
    #[error("pixel size {0} mm: must be finite, above 0 and at most {MAX_PIXEL_MM}")]
    PixelSize(f64),
    /// A tick rate out of range, Hz.
    #[error("tick rate {0} Hz: must be finite, above 0 and at most {MAX_TICK_HZ}")]
    TickRate(f64),
    /// Half a calibration: a pixel size without a tick rate, or the other
    /// way round (the missing half is named).
    #[error("half a calibration: {0} is missing (give both the pixel size and the tick rate, or neither)")]
    Half(&'static str),
}

impl From<spiv_estimator::Error> for Error {
    fn from(e: spiv_estimator::Error) -> Error {
        match e {
            spiv_estimator::Error::Piv(p) => Error::Piv(p),
            spiv_estimator::Error::Ask(source) => Error::ask(source),
        }
    }
}

/// The core's refusals: those of the wire's decoders say they came from
/// the wire; the others are the core's.
impl From<spiv_core::Error> for Error {
    fn from(e: spiv_core::Error) -> Error {
        Error::from_core("wire", e)
    }
}

impl From<WireError> for Error {
    fn from(source: WireError) -> Error {
        Error::Wire {
            what: "wire",
            source,
        }
    }
}

impl Error {
    /// Reading or writing `what` failed.
    pub fn io(what: impl Into<String>, source: std::io::Error) -> Error {
        Error::Io {
            what: what.into(),
            source,
        }
    }

    /// A control message from the host that does not hold.
    pub fn control(source: impl Into<spiv_core::Error>) -> Error {
        Error::from_core("control", source.into())
    }

    /// An ask from the host that does not hold.
    pub fn ask(source: impl Into<spiv_core::Error>) -> Error {
        Error::from_core("ask", source.into())
    }

    /// The core's refusal; a wire refusal says which link (`what`) it
    /// came from.
    fn from_core(what: &'static str, e: spiv_core::Error) -> Error {
        match e {
            spiv_core::Error::Wire(source) => Error::Wire { what, source },
            e => Error::Core(e),
        }
    }

    /// Whether the error is the operating system's (a file or a device
    /// that could not be read or written) rather than a value refused.
    pub fn is_io(&self) -> bool {
        #[cfg(feature = "sim")]
        if let Error::Sim(e) = self {
            return e.is_io();
        }
        matches!(
            self,
            Error::Io { .. }
                | Error::Usb(_)
                | Error::Format(FormatError::Io { .. })
                | Error::Piv(PivError::Format(FormatError::Io { .. }))
        )
    }
}
