//! Background suppression (paper eq. 3; docs/spec.md §5):
//! `alpha = beta / t_bgmax`, and a background pixel shows its rate over the
//! window t_bgmax divided by alpha:
//! `bg = FS·(c_t/t)·t/(beta·N_fs) = FS·c_t/(beta·N_fs)` with t = t_bgmax.
//! Computed as one product over one divisor — never as a reciprocal — so a
//! saturated pixel (c_t ≈ N_fs) lands near FS/β whatever its brightness: the
//! glare stops being white and the background becomes uniform.

use crate::params::Params;

/// Gray level of a background pixel that counted `c_t` spikes over a window
/// of nominal length `t` (its `t_bgmax`, ticks) of which `len` ticks were
/// held: `FS·(c_t/len)·t/(β·N_fs)`, rounded and clamped to `[0, FS]`.
#[inline]
pub fn background_gray(c_t: u8, t: u16, len: u16, p: &Params, full_scale: u16) -> u16 {
    let num = u64::from(full_scale) * u64::from(c_t) * u64::from(t) * 256;
    let den = u64::from(len) * u64::from(p.beta.to_bits()) * u64::from(p.n_fs);
    if den == 0 {
        return 0;
    }
    ((num + den / 2) / den).min(u64::from(full_scale)) as u16
}

/// [`background_gray`] of every count 0..=255 for one window (`t`, `len`),
/// into `out`: `⌊(A·c + D/2)/D⌋` clamped, with `A = FS·t·256` and
/// `D = len·β·N_fs`, stepped from count to count with a running remainder
/// (one division per window instead of one per pixel: the same values).
pub fn background_table(t: u16, len: u16, p: &Params, full_scale: u16, out: &mut [u16; 256]) {
    let a = u64::from(full_scale) * u64::from(t) * 256;
    let d = u64::from(len) * u64::from(p.beta.to_bits()) * u64::from(p.n_fs);
    if d == 0 {
        out.fill(0);
        return;
    }
    let (q, r) = (a / d, a % d);
    // Count 0: ⌊(D/2)/D⌋ = 0 with remainder D/2.
    let (mut v, mut rem) = (0u64, d / 2);
    let fs = u64::from(full_scale);
    for o in out.iter_mut() {
        *o = v.min(fs) as u16;
        v += q;
        rem += r;
        if rem >= d {
            v += 1;
            rem -= d;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturated_background_goes_to_fs_over_beta() {
        let p = Params::default();
        assert_eq!(background_gray(32, 64, 64, &p, 255), 26); // 25.5
        assert_eq!(background_gray(32, 4, 4, &p, 255), 26); // brighter, same gray
        assert_eq!(background_gray(2, 128, 128, &p, 255), 2); // dark: 1.59
        assert_eq!(background_gray(16, 128, 64, &p, 255), 26); // clipped window: rate
        assert_eq!(background_gray(255, 255, 1, &p, 255), 255);
        assert_eq!(background_gray(9, 9, 0, &p, 255), 0);
    }

    #[test]
    fn tables_equal_the_formula() {
        let mut t = [0u16; 256];
        for p in [
            Params::default(),
            Params {
                n_fs: 7,
                ..Params::default()
            },
        ] {
            for fs in [1u16, 255, 4095, 65535] {
                for (n, len) in [
                    (2u16, 2u16),
                    (128, 128),
                    (128, 64),
                    (255, 1),
                    (5, 0),
                    (64, 33),
                ] {
                    background_table(n, len, &p, fs, &mut t);
                    for c in 0..=255u8 {
                        assert_eq!(
                            t[usize::from(c)],
                            background_gray(c, n, len, &p, fs),
                            "{n} {len} {c}"
                        );
                    }
                }
            }
        }
    }
}
