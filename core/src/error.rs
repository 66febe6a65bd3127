//! The one error type of the core: a plain enum, no allocation, no payload
//! that needs formatting machinery.

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
        }
    }
}

#[cfg(feature = "std")]
extern crate std;
#[cfg(feature = "std")]
impl std::error::Error for Error {}
