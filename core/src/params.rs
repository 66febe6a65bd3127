//! Algorithm parameters (docs/spec.md §5) with their defaults and ranges.

use crate::error::{Error, ParamError};
use crate::q::{Beta, KSig, Sigma};

/// Parameters of segmentation, suppression and adaptive integration.
///
/// Defaults: `n0 = 2`, `n_max = 128`, `n_fs = 32`, `k_sig = 3`, `beta = 10`,
/// `sigma_fpn = 0.03`, `electrons_per_spike = 1000`, `full_scale = 255`,
/// `margin = 16`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Params {
    /// First segmentation window, ticks, `1..=n_max`.
    pub n0: u16,
    /// Longest window, ticks, `1..=255` (counts fit a byte) and at most the
    /// history depth. A frame at tick k needs ⌊n_max/2⌋ ticks of look-ahead.
    pub n_max: u16,
    /// Spikes that make full scale (`N_fs`), `>= 1`.
    pub n_fs: u16,
    /// Detection threshold in standard deviations of the count noise, `> 0`.
    pub k_sig: KSig,
    /// Background suppression weight β, `> 0` (`alpha = beta / t_bgmax`).
    pub beta: Beta,
    /// Threshold fixed-pattern spread σ_fpn, relative.
    pub sigma_fpn: Sigma,
    /// Photoelectrons per spike `g` (shot-noise term `b/g`), `>= 1`.
    pub electrons_per_spike: u16,
    /// Full-scale gray level of the output, `1..=65535` (255 for 8-bit).
    pub full_scale: u16,
    /// Rows computed beyond each side of a strip so regions crossing the
    /// strip's edge are whole (only used when the workspace is smaller than
    /// the band), `0..=MAX_MARGIN`.
    pub margin: u16,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            n0: 2,
            n_max: 128,
            n_fs: 32,
            k_sig: KSig::from_num(3),
            beta: Beta::from_num(10),
            sigma_fpn: Sigma::from_bits(1966), // 0.03 (0.029999)
            electrons_per_spike: 1000,
            full_scale: 255,
            margin: 16,
        }
    }
}

/// Most segmentation levels: n0 = 1 gives 1, 2, 4, …, 128, 255.
pub const MAX_LEVELS: usize = 9;

/// Largest strip margin, rows: a strip is `2·margin + 1` rows at least, and
/// that must fit a `u16` row count.
pub const MAX_MARGIN: u16 = (u16::MAX - 1) / 2;

impl Params {
    /// Checks every range above; `depth` is the history depth in planes.
    /// Whatever passes is safe for every computation of the core (the
    /// property tests draw each field from its type's whole range).
    pub fn validate(&self, depth: u16) -> Result<(), Error> {
        let bad = |p| Err(Error::BadParam(p));
        if self.n_max == 0 || self.n_max > 255 || self.n_max > depth {
            return bad(ParamError::NMax);
        }
        if self.n0 == 0 || self.n0 > self.n_max {
            return bad(ParamError::N0);
        }
        if self.n_fs == 0 {
            return bad(ParamError::NFs);
        }
        if self.beta.to_bits() == 0 {
            return bad(ParamError::Beta);
        }
        if self.k_sig.to_bits() == 0 {
            return bad(ParamError::KSig);
        }
        if self.electrons_per_spike == 0 {
            return bad(ParamError::Gain);
        }
        if self.full_scale == 0 {
            return bad(ParamError::FullScale);
        }
        if self.margin > MAX_MARGIN {
            return bad(ParamError::Margin);
        }
        Ok(())
    }

    /// The segmentation windows n0, 2·n0, 4·n0, …, n_max (ticks), and how many.
    pub fn levels(&self) -> ([u16; MAX_LEVELS], usize) {
        let mut out = [0u16; MAX_LEVELS];
        let mut len = 0;
        let mut n = self.n0.max(1);
        while len < MAX_LEVELS {
            if n >= self.n_max {
                out[len] = self.n_max;
                len += 1;
                break;
            }
            out[len] = n;
            len += 1;
            n = n.saturating_mul(2);
        }
        (out, len)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_levels() {
        let (l, n) = Params::default().levels();
        assert_eq!(&l[..n], &[2, 4, 8, 16, 32, 64, 128]);
        let p = Params {
            n0: 1,
            n_max: 255,
            ..Params::default()
        };
        let (l, n) = p.levels();
        assert_eq!(&l[..n], &[1, 2, 4, 8, 16, 32, 64, 128, 255]);
        let p = Params {
            n0: 3,
            n_max: 20,
            ..Params::default()
        };
        let (l, n) = p.levels();
        assert_eq!(&l[..n], &[3, 6, 12, 20]);
    }

    #[test]
    fn validate_ranges() {
        assert!(Params::default().validate(128).is_ok());
        assert!(Params::default().validate(127).is_err());
        assert!(Params {
            n0: 0,
            ..Params::default()
        }
        .validate(255)
        .is_err());
        assert!(Params {
            n_max: 256,
            ..Params::default()
        }
        .validate(256)
        .is_err());
        assert!(Params {
            beta: Beta::ZERO,
            ..Params::default()
        }
        .validate(255)
        .is_err());
        for (p, e) in [
            (
                Params {
                    margin: 40000,
                    ..Params::default()
                },
                ParamError::Margin,
            ),
            (
                Params {
                    full_scale: 0,
                    ..Params::default()
                },
                ParamError::FullScale,
            ),
        ] {
            assert_eq!(p.validate(255), Err(Error::BadParam(e)));
        }
        assert!(Params {
            margin: MAX_MARGIN,
            ..Params::default()
        }
        .validate(255)
        .is_ok());
    }
}
