//! The estimator's one error type.

use spiv_core::wire::WireError;
use spiv_piv::PivError;

/// Why a pair could not be measured or an ask not put on the wire.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// PIV of a rung refused its frames or settings.
    #[error(transparent)]
    Piv(#[from] PivError),
    /// An ask the wire cannot carry (a flow grid larger than an ask
    /// holds): the core's refusal.
    #[error("ask: {0}")]
    Ask(#[from] spiv_core::Error),
}

impl From<WireError> for Error {
    fn from(e: WireError) -> Self {
        Error::Ask(e.into())
    }
}
