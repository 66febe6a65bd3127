//! The fixed-point formats of the core, in one place.
//!
//! | alias | format | range | resolution | used for |
//! |---|---|---|---|---|
//! | [`Sigma`] | `U0F16` (unsigned, 16 fractional bits) | [0, 1) | 1.5e-5 | threshold fixed-pattern spread σ_fpn (relative) |
//! | [`KSig`] | `U8F8` | [0, 256) | 1/256 | segmentation threshold k_sig (standard deviations) |
//! | [`Beta`] | `U8F8` | [0, 256) | 1/256 | background suppression weight β |
//!
//! Everything else is an exact integer: counts (spikes), windows (ticks),
//! backgrounds as multiples of 1/1024 count (`b_q10`, exact, since tile centres
//! are 16 px apart and pixel centres sit on half pixels), and the
//! segmentation, SNR and output formulas, which are evaluated as exact
//! rationals in `u128`/`i128` (see [`crate::segment::is_particle`],
//! [`crate::integrate::cmp_snr`]). So the core's integer decisions are the
//! mathematically exact ones for the quantised parameters; the host's `f64`
//! reference differs only where `f64` rounding meets an exact tie.

use fixed::types::{U0F16, U8F8};

/// σ_fpn: relative threshold spread, `U0F16`.
pub type Sigma = U0F16;
/// k_sig: detection threshold in standard deviations, `U8F8`.
pub type KSig = U8F8;
/// β: dimensionless background suppression weight, `U8F8`.
pub type Beta = U8F8;

/// Background counts are carried as exact multiples of 2^-10 count.
pub const B_FRAC_BITS: u32 = 10;
