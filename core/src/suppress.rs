//! Background suppression (paper eq. 3; SPEC section 5):
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
}
