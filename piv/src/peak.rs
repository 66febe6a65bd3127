//! Sub-pixel peak location: the 3-point Gaussian and parabolic estimators
//! along each axis, and the 9-point 2-D Gaussian regression (Nobach &
//! Honkanen 2005). Every estimator returns an offset in (−1, 1) or falls
//! back; none returns a non-finite value.

/// The 3-point sub-pixel estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Subpixel {
    /// Gaussian fit (parabola where a value is not positive).
    Gaussian,
    /// Parabola.
    Parabolic,
    /// Least-squares 2-D Gaussian over the 3×3 around the peak (Nobach &
    /// Honkanen 2005); the 3-point Gaussian where a value is not positive.
    Gaussian2d,
}

/// 9-point 2-D Gaussian regression; `v[row][col]` around the peak. Returns
/// (dx, dy) in (−1, 1) or `None`.
pub fn gaussian2d(v: &[[f64; 3]; 3]) -> Option<(f64, f64)> {
    let (mut c10, mut c01, mut c11, mut c20, mut c02) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (r, row) in v.iter().enumerate() {
        for (k, &x) in row.iter().enumerate() {
            if x.is_nan() || x <= 0.0 {
                return None;
            }
            let l = x.ln();
            let (i, j) = (k as f64 - 1.0, r as f64 - 1.0);
            c10 += i * l;
            c01 += j * l;
            c11 += i * j * l;
            c20 += (3.0 * i * i - 2.0) * l;
            c02 += (3.0 * j * j - 2.0) * l;
        }
    }
    let (c10, c01, c11, c20, c02) = (c10 / 6.0, c01 / 6.0, c11 / 4.0, c20 / 6.0, c02 / 6.0);
    let den = 4.0 * c20 * c02 - c11 * c11;
    let dx = (c11 * c01 - 2.0 * c10 * c02) / den;
    let dy = (c11 * c10 - 2.0 * c01 * c20) / den;
    (dx.is_finite() && dy.is_finite() && dx.abs() < 1.0 && dy.abs() < 1.0).then_some((dx, dy))
}

/// Parabolic sub-pixel offset in (−1, 1), 0 without a maximum.
pub fn parabolic(cm: f64, c0: f64, cp: f64) -> f64 {
    let den = 2.0 * cm - 4.0 * c0 + 2.0 * cp;
    if den < 0.0 {
        let d = (cm - cp) / den;
        if d.is_finite() && d.abs() < 1.0 {
            return d;
        }
    }
    0.0
}

/// Sub-pixel offset of a peak `c0` between `cm` (at −1) and `cp` (at +1),
/// in (−1, 1): Gaussian fit, else parabola, else 0.
pub fn subpixel(cm: f64, c0: f64, cp: f64) -> f64 {
    if cm > 0.0 && c0 > 0.0 && cp > 0.0 {
        let (lm, l0, lp) = (cm.ln(), c0.ln(), cp.ln());
        let den = 2.0 * lm - 4.0 * l0 + 2.0 * lp;
        if den < 0.0 {
            let d = (lm - lp) / den;
            if d.is_finite() && d.abs() < 1.0 {
                return d;
            }
        }
    }
    parabolic(cm, c0, cp)
}

/// The width of a peak `c0` between `cm` (at −1) and `cp` (at +1): the σ,
/// px, of the Gaussian with the same relative second difference
/// (2·c0 − cm − cp)/c0; infinite where the three values are flat or not a
/// maximum (a ridge: a streak's correlation, or no peak at all).
pub fn width(cm: f64, c0: f64, cp: f64) -> f64 {
    let s = (2.0 * c0 - cm - cp) / c0;
    if !(c0 > 0.0 && s > 0.0 && s.is_finite()) {
        return f64::INFINITY;
    }
    if s >= 2.0 {
        // Sharper than a Gaussian can be at ±1 px: below a pixel.
        return 0.0;
    }
    (-1.0 / (2.0 * (1.0 - 0.5 * s).ln())).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_width_of_a_gaussian_peak_is_its_sigma() {
        for sigma in [0.8f64, 1.4, 2.0, 4.0, 9.0] {
            let g = |x: f64| (-x * x / (2.0 * sigma * sigma)).exp();
            let w = width(g(-1.0), g(0.0), g(1.0));
            assert!((w - sigma).abs() < 1e-9 * sigma.max(1.0), "{sigma}: {w}");
        }
        // A plateau (a streak's ridge) and a minimum have no width.
        assert_eq!(width(1.0, 1.0, 1.0), f64::INFINITY);
        assert_eq!(width(2.0, 1.0, 2.0), f64::INFINITY);
        assert_eq!(width(0.0, 0.0, 0.0), f64::INFINITY);
        assert!(width(f64::NAN, 1.0, 0.5).is_infinite());
        // A one-pixel spike is narrower than any Gaussian can say.
        assert_eq!(width(-0.5, 1.0, -0.5), 0.0);
    }

    #[test]
    fn subpixel_fallbacks_stay_finite() {
        assert_eq!(subpixel(0.0, 0.0, 0.0), 0.0);
        assert!((subpixel(-0.2, 0.5, 0.1)).abs() < 1.0);
        assert!((subpixel(0.5, 1.0, 0.5)).abs() < 1e-12);
        assert_eq!(subpixel(1.0, 0.5, 1.0), 0.0);
    }

    #[test]
    fn gaussian2d_finds_a_sampled_gaussian_and_refuses_flat_data() {
        let (x0, y0) = (0.3, -0.2);
        let v: [[f64; 3]; 3] = core::array::from_fn(|r| {
            core::array::from_fn(|k| {
                let (x, y) = (k as f64 - 1.0 - x0, r as f64 - 1.0 - y0);
                (-(x * x + y * y) / 1.5).exp()
            })
        });
        let (dx, dy) = gaussian2d(&v).unwrap();
        assert!((dx - x0).abs() < 1e-9 && (dy - y0).abs() < 1e-9);
        assert_eq!(gaussian2d(&[[1.0; 3]; 3]), None);
        assert_eq!(gaussian2d(&[[0.0; 3]; 3]), None);
    }
}
