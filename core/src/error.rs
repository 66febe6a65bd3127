//! The one error type of the core, [`Error`]: a plain enum, no allocation,
//! no payload that needs formatting machinery. Its kinds
//! ([`ParamError`], [`WireError`], [`ConfigError`]) say which parameter,
//! which check of the bytes, or which setting of the sidecar was refused.
//!
//! The calls that hand bytes to the caller's [`crate::wire::sender::Link`]
//! return [`LinkError`]: the core's [`Error`], or the link's own error,
//! which the core does not own and passes through unchanged.

use crate::method::Method;

/// Everything a core function can refuse. No function in the core panics;
/// each refusal below is returned instead.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error {
    /// Width or height is zero, or `width * height` is not a multiple of 8
    /// (a Vidar plane is whole bytes).
    BadDimensions,
    /// A byte buffer does not hold exactly one plane of the given size.
    PlaneSize {
        /// bytes expected (`width * height / 8`)
        expected: usize,
        /// bytes given
        got: usize,
    },
    /// A caller-supplied buffer is smaller than the layout needs.
    BufferTooSmall {
        /// elements needed
        needed: usize,
        /// elements given
        got: usize,
    },
    /// The band of rows does not lie inside the plane.
    BadBand,
    /// A plane of another size than the history was made for.
    PlaneMismatch,
    /// The history holds no plane yet, or the requested tick is not in it.
    TickUnavailable,
    /// The tick counter would wrap (2^32 planes ingested).
    TickOverflow,
    /// A parameter is out of its documented range.
    BadParam(ParamError),
    /// Bytes that are not a message, or a message that cannot be written.
    Wire(WireError),
    /// A configuration the sidecar loop cannot run.
    Config(ConfigError),
}

/// Which parameter is out of range (see [`crate::params::Params`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamError {
    /// `n0` must be in `1..=n_max`.
    N0,
    /// `n_max` must be in `1..=255` and fit in the history depth.
    NMax,
    /// `n_fs` must be at least 1.
    NFs,
    /// `beta` must be positive.
    Beta,
    /// `k_sig` must be positive.
    KSig,
    /// `electrons_per_spike` must be at least 1.
    Gain,
    /// The window length of TFP must be in `1..=depth`.
    Window,
    /// `full_scale` must be at least 1.
    FullScale,
    /// `margin` must be at most [`crate::params::MAX_MARGIN`].
    Margin,
    /// A motion grid needs `cols` in `1..=`[`crate::motion::MAX_COLS`] and
    /// a tile that is a positive multiple of 64 px.
    Motion,
    /// The method makes no frame at a tick (the time ladder's frames are
    /// made by the live loop's pairs, [`crate::rungs`]).
    Method,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::BadDimensions => write!(f, "width*height must be a positive multiple of 8"),
            Error::PlaneSize { expected, got } => {
                write!(f, "plane holds {got} bytes, expected {expected}")
            }
            Error::BufferTooSmall { needed, got } => {
                write!(f, "buffer holds {got} elements, needs {needed}")
            }
            Error::BadBand => write!(f, "band of rows outside the plane"),
            Error::PlaneMismatch => write!(f, "plane size differs from the history's"),
            Error::TickUnavailable => write!(f, "tick not in the spike history"),
            Error::TickOverflow => write!(f, "tick counter would wrap"),
            Error::BadParam(p) => write!(f, "parameter out of range: {p:?}"),
            Error::Wire(e) => write!(f, "wire: {e}"),
            Error::Config(e) => write!(f, "configuration: {e}"),
        }
    }
}

impl From<ParamError> for Error {
    fn from(e: ParamError) -> Self {
        Error::BadParam(e)
    }
}

impl From<WireError> for Error {
    fn from(e: WireError) -> Self {
        Error::Wire(e)
    }
}

impl From<ConfigError> for Error {
    fn from(e: ConfigError) -> Self {
        Error::Config(e)
    }
}

/// Why bytes were not a message, or a message could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireError {
    /// More bytes than the receive buffer before a delimiter (dropped).
    Overflow,
    /// Not valid COBS.
    Cobs,
    /// Shorter than a header and a CRC, or `payload_len` disagrees with the
    /// message length.
    Length,
    /// The CRC does not match.
    Crc,
    /// Wrong magic.
    Magic,
    /// A version this code does not read.
    Version,
    /// Unknown kind or encoding.
    Field,
    /// A payload above [`crate::wire::MAX_PAYLOAD`], or an output buffer
    /// too small.
    TooLarge,
    /// A payload that does not decode to the rows its header names.
    Payload,
}

impl core::fmt::Display for WireError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            WireError::Overflow => "message longer than the receive buffer",
            WireError::Cobs => "invalid COBS framing",
            WireError::Length => "message length disagrees with its header",
            WireError::Crc => "CRC mismatch",
            WireError::Magic => "bad magic",
            WireError::Version => "unsupported protocol version",
            WireError::Field => "unknown message kind or encoding",
            WireError::TooLarge => "payload or buffer too large",
            WireError::Payload => "payload does not decode to its rows",
        })
    }
}

/// A configuration the sidecar loop cannot run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The frame window is outside `1..=255` ticks (`2..=255` for TFI).
    Window(u16),
    /// `every` below `dt`, or `dt` zero.
    Schedule {
        /// Ticks between pairs.
        every: u32,
        /// Ticks between the frames of a pair.
        dt: u32,
    },
    /// One row of this many pixels does not fit one payload.
    RowTooWide(u16),
    /// The frame loop does not make this method's frames (the time
    /// ladder's are made by the live loop's pairs, [`crate::rungs`]).
    Method(Method),
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ConfigError::Window(w) => write!(f, "window {w} out of range (1..=255)"),
            ConfigError::Schedule { every, dt } => {
                write!(f, "pair every {every} ticks must be at least dt = {dt} > 0")
            }
            ConfigError::RowTooWide(w) => {
                write!(f, "a row of {w} px does not fit one message's payload")
            }
            ConfigError::Method(m) => write!(
                f,
                "the frame loop does not make {} frames (the live loop of pairs does)",
                m.name()
            ),
        }
    }
}

/// Why a call that sends through the caller's link stopped: the core
/// refused, or the link (`E`, the link's own error) refused the bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkError<E> {
    /// The core refused (a plane of the wrong size, a frame the wire cannot
    /// carry, a configuration it cannot run, …).
    Core(Error),
    /// The link refused the bytes.
    Link(E),
}

impl<E> From<Error> for LinkError<E> {
    fn from(e: Error) -> Self {
        LinkError::Core(e)
    }
}

impl<E> From<WireError> for LinkError<E> {
    fn from(e: WireError) -> Self {
        LinkError::Core(Error::Wire(e))
    }
}

impl<E> From<ConfigError> for LinkError<E> {
    fn from(e: ConfigError) -> Self {
        LinkError::Core(Error::Config(e))
    }
}

impl<E: core::fmt::Display> core::fmt::Display for LinkError<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LinkError::Core(e) => write!(f, "{e}"),
            LinkError::Link(e) => write!(f, "link: {e}"),
        }
    }
}

#[cfg(feature = "std")]
extern crate std;
#[cfg(feature = "std")]
impl std::error::Error for Error {}
#[cfg(feature = "std")]
impl std::error::Error for WireError {}
#[cfg(feature = "std")]
impl std::error::Error for ConfigError {}
#[cfg(feature = "std")]
impl<E: core::fmt::Debug + core::fmt::Display> std::error::Error for LinkError<E> {}
