//! The particle test of the segmentation (SPEC 5): a count `c` over a
//! window is particle against the local background `b` when `c > b` and
//! `(c − b)² > k_sig²·var(b)`, with the count noise of an integrate-and-fire
//! pixel `var(b) = 1/4 + (σ_fpn·b)² + b/g`. Exact rationals in `u128`, and
//! per-frame tables that decide it without `u128` for almost every pixel.

use crate::params::Params;
use crate::q::B_FRAC_BITS;

/// The exact particle test `c > b ∧ (c − b)² > k²·(1/4 + σ²b² + b/g)` for a
/// count `c` and a background `b = b_q10 / 1024`, evaluated in `u128` after
/// multiplying both sides by `2^88·g` (saturating: a saturated right side is
/// larger than any left side, which stays below 2^120).
#[inline]
pub fn is_particle(c: u8, b_q10: u32, p: &Params) -> bool {
    let cq = u128::from(c) << B_FRAC_BITS;
    let b = u128::from(b_q10);
    if cq <= b {
        return false;
    }
    let d = cq - b;
    let g = u128::from(p.electrons_per_spike.max(1));
    let q = u128::from(p.k_sig.to_bits());
    let s = u128::from(p.sigma_fpn.to_bits());
    let lhs = (d * d).saturating_mul(g << 68);
    let var = (g << 70)
        .saturating_add((g << 20).saturating_mul(s * s).saturating_mul(b * b))
        .saturating_add(b << 62);
    lhs > var.saturating_mul(q * q)
}

/// Per-frame tables that decide the particle test without `u128` for almost
/// every pixel. The test is monotone: harder as `b` grows, easier as `c`
/// grows. So for `b` in `[1024·f, 1024·f + 1024)`, `c < lo[f]` is never a
/// particle and `c ≥ hi[f]` always is; only `lo[f] ≤ c < hi[f]` needs the
/// exact test. Exact, not an approximation. 1 KiB.
#[derive(Debug, Clone)]
pub struct Thresholds {
    lo: [u16; 256],
    hi: [u16; 256],
}

impl Thresholds {
    /// Builds the tables for `p` (about 4000 exact tests).
    pub fn new(p: &Params) -> Thresholds {
        let cmin = |b_q10: u32| -> u16 {
            // Smallest c in 0..=255 that passes (256: none); monotone in c.
            let (mut lo, mut hi) = (0u16, 256u16);
            while lo < hi {
                let mid = (lo + hi) / 2;
                if is_particle(mid as u8, b_q10, p) {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            lo
        };
        let mut t = Thresholds {
            lo: [256; 256],
            hi: [256; 256],
        };
        for f in 0..256u32 {
            t.lo[f as usize] = cmin(f << B_FRAC_BITS);
            t.hi[f as usize] = cmin((f << B_FRAC_BITS) + (1 << B_FRAC_BITS) - 1);
        }
        t
    }

    /// Same answer as [`is_particle`].
    #[inline]
    pub fn is_particle(&self, c: u8, b_q10: u32, p: &Params) -> bool {
        let f = ((b_q10 >> B_FRAC_BITS) as usize).min(255);
        let c16 = u16::from(c);
        if c16 < self.lo[f] {
            false
        } else if c16 >= self.hi[f] {
            true
        } else {
            is_particle(c, b_q10, p)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_f64(c: u8, b_q10: u32, p: &Params) -> bool {
        let b = f64::from(b_q10) / 1024.0;
        let c = f64::from(c);
        let k = p.k_sig.to_num::<f64>();
        let s = p.sigma_fpn.to_num::<f64>();
        let g = f64::from(p.electrons_per_spike);
        c > b && (c - b).powi(2) > k * k * (0.25 + (s * b).powi(2) + b / g)
    }

    #[test]
    fn particle_test_matches_f64() {
        let p = Params::default();
        for c in 0..=255u8 {
            for b_q10 in (0..255 * 1024).step_by(97) {
                assert_eq!(
                    is_particle(c, b_q10, &p),
                    test_f64(c, b_q10, &p),
                    "c={c} b={b_q10}"
                );
            }
        }
        // Poisson would call c = 3 over b = 1 a 2-sigma event; here it is 4 sigma.
        assert!(is_particle(3, 1024, &p));
        assert!(!is_particle(2, 1024, &p));
    }
}
