//! The particle test of the segmentation (docs/spec.md §5): a count `c` over a
//! window is particle against the local background `b` when `c > b` and
//! `(c − b)² > k_sig²·var(b)`, with the count noise of an integrate-and-fire
//! pixel `var(b) = 1/4 + (σ_fpn·b)² + b/g`. Exact rationals in `u128`, and
//! per-frame tables that decide it without `u128` for almost every pixel.
//!
//! A motion-compensated count ([`crate::motion`]) adds the spikes of `S`
//! different pixels along the predicted path, so its noise is not one
//! pixel's: [`is_particle_compensated`].

use core::cell::Cell;

use crate::params::Params;
use crate::q::B_FRAC_BITS;

/// Both sides of the particle tests are multiplied by `2^SCALE·g`.
const SCALE: u32 = 88;
/// `(c − b)²` is in 1/2^20 counts² (counts in 1/2^[`B_FRAC_BITS`]): the
/// left side's remaining shift.
const LHS_SHIFT: u32 = SCALE - 2 * B_FRAC_BITS;
/// The variance is multiplied by `k²`, in 1/2^16 (`KSig` is `U8F8`): the
/// variance's own scale, `2^VAR_SHIFT·g`.
const VAR_SHIFT: u32 = SCALE - 2 * KSIG_FRAC;
const KSIG_FRAC: u32 = crate::q::KSig::FRAC_NBITS;
/// `σ_fpn`'s fractional bits (`U0F16`).
const SIGMA_FRAC: u32 = crate::q::Sigma::FRAC_NBITS;
/// The quantisation term `1/4` at the variance's scale.
const QUARTER_SHIFT: u32 = VAR_SHIFT - 2;
/// `σ²·b²` is in 1/2^(32 + 20): the fixed-pattern term's remaining shift.
const FPN_SHIFT: u32 = VAR_SHIFT - 2 * SIGMA_FRAC - 2 * B_FRAC_BITS;
/// `b/g` times `g`: `b` in 1/2^10 counts, the Poisson term's shift.
const POISSON_SHIFT: u32 = VAR_SHIFT - B_FRAC_BITS;

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
    let lhs = (d * d).saturating_mul(g << LHS_SHIFT);
    let var = (g << QUARTER_SHIFT)
        .saturating_add((g << FPN_SHIFT).saturating_mul(s * s).saturating_mul(b * b))
        .saturating_add(b << POISSON_SHIFT);
    lhs > var.saturating_mul(q * q)
}

/// The particle test of a motion-compensated count gathered from `segs`
/// distinct pixels along the path ([`crate::motion::positions`]), against
/// a background `b = b_q10 / 1024`: `c > b ∧ (c − b)² > k²·var` with
///
/// `var = max(1/4, S·h(b/S)) + (σ_fpn·b)²/S + b/g`,
/// `h(μ) = min(μ(1 − μ), 1/6)` for `μ < 1/2`, else `1/6`.
///
/// Each of the `S` pixels contributes a segment of about `b/S` counts,
/// `⌊φ + r·m⌋` with its own phase `φ`: variance `{μ}(1 − {μ})`, which is
/// `μ(1 − μ)` for a dim segment (`μ < 1`: a Bernoulli count, so a long
/// path through the dark has about Poisson noise `b`, not `1/4`) and
/// averages `1/6` over the fractional parts of brighter ones (the segment
/// lengths alternate and the phases are independent); the sum is never
/// taken below one pixel's bound `1/4`, so `S = 1` is exactly
/// [`is_particle`]. Fixed-pattern noise averages over the `S` thresholds.
/// On the paper's scenes (`spiv bench paper`, 10 seeds) this took the
/// compensated glare-row RMAE from 0.040 / 0.113 / 0.141 (one pixel's
/// model) to 0.027 / 0.100 / 0.102 and the other rows to the frame
/// camera's; the bound `1/4` per segment instead of `1/6` gave 0.033 /
/// 0.096 / 0.126 and lost the glare band's particles on the log profile.
/// Exact: both sides multiplied by `6·S·2^88·g`, saturating as
/// [`is_particle`].
#[inline]
pub fn is_particle_compensated(c: u8, b_q10: u32, p: &Params, segs: u32) -> bool {
    let cq = u128::from(c) << B_FRAC_BITS;
    let b = u128::from(b_q10);
    if cq <= b {
        return false;
    }
    let n = u128::from(segs.max(1));
    let d = cq - b;
    let g = u128::from(p.electrons_per_spike.max(1));
    let q = u128::from(p.k_sig.to_bits());
    let s = u128::from(p.sigma_fpn.to_bits());
    // 6·S·max(1/4, S·h(b/S)) in 1/2^20 counts².
    let sixth = (n * n) << 20;
    let quarter = (6 * n) << 18;
    let quant = if 2 * b < n << B_FRAC_BITS {
        (6 * ((b * n) << B_FRAC_BITS).saturating_sub(b * b)).min(sixth)
    } else {
        sixth
    };
    let lhs = (d * d).saturating_mul(g << LHS_SHIFT).saturating_mul(6 * n);
    let var = quant
        .max(quarter)
        .saturating_mul(g << (VAR_SHIFT - 2 * B_FRAC_BITS))
        .saturating_add(
            (6 * (g << FPN_SHIFT))
                .saturating_mul(s * s)
                .saturating_mul(b * b),
        )
        .saturating_add((b << POISSON_SHIFT).saturating_mul(6 * n));
    lhs > var.saturating_mul(q * q)
}

/// Per-frame tables that decide the particle test without `u128` for almost
/// every pixel. The test is monotone: harder as `b` grows, easier as `c`
/// grows. So for `b` in `[1024·f, 1024·f + 1024)`, `c < lo[f]` is never a
/// particle and `c ≥ hi[f]` always is (`lo` also bounds a word's
/// candidates, [`Thresholds::min_count`]). And each count `c` is particle
/// exactly below one background, `bound[c]`: found once per count the
/// frame asks about (the last bin whose start it passes, from `lo`, then
/// ten exact tests by bisection when it fails at that bin's end) and kept,
/// after which the test is one load and one comparison (on the default
/// scene the frame asks about 34,000 pixels and a few dozen counts; the
/// exact test is a few 128-bit products). Exact, not an approximation.
/// 2 KiB.
#[derive(Debug, Clone)]
pub struct Thresholds {
    lo: [u16; 256],
    hi: [u16; 256],
    /// Per count, the background (1/1024 count) it is particle below,
    /// once a query has needed it; [`UNKNOWN`] before.
    bound: [Cell<u32>; 256],
}

/// A [`Thresholds::bound`] not found yet. Bounds are at most
/// [`ALWAYS`].
const UNKNOWN: u32 = u32::MAX;

/// The bound of a count that is particle against every background in the
/// tables' range (and any the core makes: they are below 2^18).
const ALWAYS: u32 = u32::MAX - 1;

impl Thresholds {
    /// Builds the tables for `p` (about 800 exact tests).
    pub fn new(p: &Params) -> Thresholds {
        // The smallest passing count only grows with the background, so
        // one upward scan finds every bin's bounds: about 800 exact tests
        // instead of a binary search's 4096 (each a few 128-bit products,
        // library calls on a Cortex-M4).
        let mut t = Thresholds {
            lo: [256; 256],
            hi: [256; 256],
            bound: core::array::from_fn(|_| Cell::new(UNKNOWN)),
        };
        let mut c = 0u16;
        let mut smallest = |b_q10: u32| -> u16 {
            while c < 256 && !is_particle(c as u8, b_q10, p) {
                c += 1;
            }
            c
        };
        for f in 0..256u32 {
            t.lo[f as usize] = smallest(f << B_FRAC_BITS);
            t.hi[f as usize] = smallest((f << B_FRAC_BITS) + (1 << B_FRAC_BITS) - 1);
        }
        t
    }

    /// The smallest count that can be particle against any background of
    /// at least `b_q10` (1/1024 count; 256: none): the test is harder as
    /// the background grows.
    #[inline]
    pub fn min_count(&self, b_q10: u32) -> u16 {
        self.lo[((b_q10 >> B_FRAC_BITS) as usize).min(255)]
    }

    /// Same answer as [`is_particle`] (for backgrounds below 2^18, 256
    /// counts: every one the core makes).
    #[inline]
    pub fn is_particle(&self, c: u8, b_q10: u32, p: &Params) -> bool {
        b_q10 < self.bound(c, p)
    }

    /// The background (1/1024 count) count `c` is particle below:
    /// [`Thresholds::is_particle`]`(c, b)` ⟺ `b < bound(c)`. Found on first
    /// use, then kept.
    #[inline]
    pub fn bound(&self, c: u8, p: &Params) -> u32 {
        let cell = &self.bound[usize::from(c)];
        let mut bound = cell.get();
        if bound == UNKNOWN {
            bound = self.find_bound(c, p);
            cell.set(bound);
        }
        bound
    }

    /// The background count `c` is particle below: it passes at the start
    /// of the last bin `f` with `lo[f] ≤ c` (so at every smaller
    /// background) and fails from the next bin on; within bin `f` it
    /// passes to the end when `c ≥ hi[f]`, else up to where
    /// [`last_passing`] finds.
    #[cold]
    fn find_bound(&self, c: u8, p: &Params) -> u32 {
        let c16 = u16::from(c);
        let bins = self.lo.partition_point(|&lo| lo <= c16);
        let Some(f) = bins.checked_sub(1) else {
            return 0;
        };
        if c16 < self.hi[f] {
            last_passing(c, f as u32, p) + 1
        } else if f == 255 {
            ALWAYS
        } else {
            ((f + 1) as u32) << B_FRAC_BITS
        }
    }
}

/// The largest background of bin `f` that count `c` is particle against,
/// given that it is at the bin's start and is not at its end.
#[cold]
fn last_passing(c: u8, f: u32, p: &Params) -> u32 {
    let (mut pass, mut fail) = (
        f << B_FRAC_BITS,
        (f << B_FRAC_BITS) + (1 << B_FRAC_BITS) - 1,
    );
    while fail - pass > 1 {
        let mid = pass + (fail - pass) / 2;
        if is_particle(c, mid, p) {
            pass = mid;
        } else {
            fail = mid;
        }
    }
    pass
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

    fn compensated_f64(c: u8, b_q10: u32, p: &Params, segs: u32) -> bool {
        let b = f64::from(b_q10) / 1024.0;
        let (c, s) = (f64::from(c), f64::from(segs));
        let k = p.k_sig.to_num::<f64>();
        let sig = p.sigma_fpn.to_num::<f64>();
        let g = f64::from(p.electrons_per_spike);
        let mu = b / s;
        let h = if mu < 0.5 {
            (mu * (1.0 - mu)).min(1.0 / 6.0)
        } else {
            1.0 / 6.0
        };
        let var = (s * h).max(0.25) + (sig * b).powi(2) / s + b / g;
        c > b && (c - b).powi(2) > k * k * var
    }

    #[test]
    fn compensated_test_matches_f64_and_one_pixel_is_the_plain_test() {
        let p = Params::default();
        for segs in [1u32, 2, 3, 7, 40, 255] {
            for c in 0..=255u8 {
                for b_q10 in (0..255 * 1024).step_by(211) {
                    let want = compensated_f64(c, b_q10, &p, segs);
                    assert_eq!(
                        is_particle_compensated(c, b_q10, &p, segs),
                        want,
                        "c={c} b={b_q10} S={segs}"
                    );
                    if segs == 1 {
                        assert_eq!(want, is_particle(c, b_q10, &p));
                    }
                }
            }
        }
        // A long path through the dark: 8 counts where 1.5 are expected is
        // a particle for one pixel (σ = 0.5) and, with Bernoulli segments
        // (σ ≈ 1.2), still is; 4 is for one pixel only.
        let b = 1536;
        assert!(is_particle(4, b, &p) && !is_particle_compensated(4, b, &p, 90));
        assert!(is_particle_compensated(8, b, &p, 90));
        // Bright glare swept over 90 px: σ ≈ 3.9 counts, not 1.9.
        let b = 50 * 1024;
        assert!(is_particle(58, b, &p) && !is_particle_compensated(58, b, &p, 90));
        assert!(is_particle_compensated(63, b, &p, 90));
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

    /// The tables decide as the exact test does, and their bounds are the
    /// smallest passing counts at each bin's ends (by brute force).
    #[test]
    fn tables_are_exact() {
        use crate::q::{KSig, Sigma};
        let params = [
            Params::default(),
            Params {
                k_sig: KSig::from_num(0.5),
                sigma_fpn: Sigma::from_bits(u16::MAX),
                electrons_per_spike: 1,
                ..Params::default()
            },
            Params {
                k_sig: KSig::from_num(40),
                sigma_fpn: Sigma::from_bits(0),
                electrons_per_spike: u16::MAX,
                ..Params::default()
            },
        ];
        for p in &params {
            let th = Thresholds::new(p);
            let smallest = |b: u32| {
                (0..256u16)
                    .find(|&c| is_particle(c as u8, b, p))
                    .unwrap_or(256)
            };
            for f in 0..256u32 {
                assert_eq!(th.lo[f as usize], smallest(f << B_FRAC_BITS), "lo {f}");
                assert_eq!(
                    th.hi[f as usize],
                    smallest((f << B_FRAC_BITS) + 1023),
                    "hi {f}"
                );
            }
            for c in 0..=255u8 {
                for b_q10 in (0..256 * 1024).step_by(389) {
                    assert_eq!(th.is_particle(c, b_q10, p), is_particle(c, b_q10, p));
                }
                // Each count's bound is where the exact test turns.
                let bound = th.bound[usize::from(c)].get();
                assert!(bound <= ALWAYS, "{c}");
                if bound > 0 {
                    assert!(is_particle(c, (bound - 1).min(256 * 1024 - 1), p), "{c}");
                }
                if bound < 256 * 1024 {
                    assert!(!is_particle(c, bound, p), "{c} {bound}");
                }
            }
            // Every background of the bins where a count turns, asked in
            // a scrambled order (the first question fixes the kept bound),
            // on fresh tables.
            let th = Thresholds::new(p);
            let mut rng = crate::testing::rng(7);
            for f in 0..256u32 {
                let (lo, hi) = (th.lo[f as usize], th.hi[f as usize]);
                for c in lo..hi.min(256) {
                    let start = rng(1024) as u32;
                    for q in 0..1024u32 {
                        let b_q10 = (f << B_FRAC_BITS) + (start + q * 389) % 1024;
                        assert_eq!(
                            th.is_particle(c as u8, b_q10, p),
                            is_particle(c as u8, b_q10, p),
                            "c {c} b {b_q10}"
                        );
                    }
                }
            }
        }
    }
}
