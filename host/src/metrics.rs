//! The paper's metrics (docs/spec.md §7): PIV vectors averaged along x for
//! each row of vectors give a profile u(y) in pixels per pair; over the rows
//! (and pairs) of a region, `RMAE = Σ|v − v̂| / Σ|v|` and
//! `RMSE = sqrt(mean((v − v̂)²))`, separately for the glare band and the
//! rest, with the mean and 95 % confidence half-width over seeds.

use serde::Serialize;
use spiv_formats::vectors::Vector;

/// One row of vectors: its height above the wall, the measured mean u (None
/// when every vector of the row is flagged 2) and the true mean u, px/pair.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ProfileRow {
    /// Height of the row's centre above the wall, px.
    pub y_wall: f64,
    /// Measured mean u over vectors with flag < 2, px per pair.
    pub measured: Option<f64>,
    /// True mean u over the same row, px per pair.
    pub truth: f64,
    /// Vectors used.
    pub used: usize,
}

/// Row profiles of a field against the truth on the same grid (the truth
/// is matched by position; both row-major). `height` is the image height.
pub fn row_profile(field: &[Vector], truth: &[Vector], height: f64) -> Vec<ProfileRow> {
    let mut rows: Vec<(f64, f64, usize, f64, usize)> = Vec::new(); // y, sum, n, tsum, tn
    for (v, t) in field.iter().zip(truth) {
        let k = match rows.iter().position(|r| (r.0 - v.y).abs() < 1e-9) {
            Some(k) => k,
            None => {
                rows.push((v.y, 0.0, 0, 0.0, 0));
                rows.len() - 1
            }
        };
        let r = &mut rows[k];
        if v.state.is_measured() {
            r.1 += v.u;
            r.2 += 1;
        }
        r.3 += t.u;
        r.4 += 1;
    }
    rows.into_iter()
        .map(|(y, s, n, ts, tn)| ProfileRow {
            y_wall: height - 0.5 - y,
            measured: (n > 0).then(|| s / n as f64),
            truth: ts / tn.max(1) as f64,
            used: n,
        })
        .collect()
}

/// Errors over the rows of one region.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RegionError {
    /// Σ|v − v̂| / Σ|v|; NaN (undefined) when Σ|v| = 0.
    pub rmae: f64,
    /// sqrt(mean((v − v̂)²)), px per pair.
    pub rmse: f64,
    /// Rows counted.
    pub rows: usize,
    /// Rows with no usable vector (counted as v̂ = 0: the measurement was lost).
    pub lost: usize,
}

/// RMAE and RMSE over the rows for which `select(y_wall)` holds. A row
/// without a usable vector counts as a measured 0 (the flow was not seen).
pub fn region_error(rows: &[ProfileRow], select: impl Fn(f64) -> bool) -> RegionError {
    let (mut abs, mut norm, mut sq, mut n, mut lost) = (0.0, 0.0, 0.0, 0usize, 0usize);
    for r in rows.iter().filter(|r| select(r.y_wall)) {
        let m = r.measured.unwrap_or_else(|| {
            lost += 1;
            0.0
        });
        abs += (m - r.truth).abs();
        norm += r.truth.abs();
        sq += (m - r.truth).powi(2);
        n += 1;
    }
    RegionError {
        // Undefined, not perfect, where the truth is all zero (or no row
        // was selected): NaN, printed as NaN and written to JSON as null.
        rmae: if norm > 0.0 { abs / norm } else { f64::NAN },
        rmse: (sq / n.max(1) as f64).sqrt(),
        rows: n,
        lost,
    }
}

/// `a / b` for two RMAEs (frame / spike): infinite when `b` is 0 (a perfect
/// spike measurement), NaN when either is undefined.
pub fn rmae_ratio(a: f64, b: f64) -> f64 {
    if b.is_nan() || a.is_nan() {
        f64::NAN
    } else if b > 0.0 {
        a / b
    } else {
        f64::INFINITY
    }
}

/// Mean and 95 % confidence half-width (Student t) of samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeanCi {
    /// Mean.
    pub mean: f64,
    /// Half-width of the 95 % interval (0 for one sample).
    pub ci95: f64,
    /// Samples.
    pub n: usize,
}

/// The mean ± 95 % CI half-width of `xs`.
pub fn mean_ci(xs: &[f64]) -> MeanCi {
    let n = xs.len();
    if n == 0 {
        return MeanCi {
            mean: f64::NAN,
            ci95: f64::NAN,
            n,
        };
    }
    let mean = xs.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return MeanCi { mean, ci95: 0.0, n };
    }
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    MeanCi {
        mean,
        ci95: t95(n - 1) * (var / n as f64).sqrt(),
        n,
    }
}

/// Two-sided 95 % Student t quantile for `df` degrees of freedom.
fn t95(df: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => f64::NAN,
        d if d <= 30 => T[d - 1],
        d if d <= 60 => 2.042 - (d - 30) as f64 * (2.042 - 2.000) / 30.0,
        d if d <= 120 => 2.000 - (d - 60) as f64 * (2.000 - 1.980) / 60.0,
        _ => 1.960,
    }
}

/// RMS of the vector error |(u, v) − truth| over the vectors not rejected
/// (flag < 2), px per pair, and how many were used. Rejected vectors are
/// left out; a field with none gives `NaN`.
pub fn vector_rmse(field: &[Vector], truth: &[Vector]) -> (f64, usize) {
    let (mut sq, mut n) = (0.0, 0usize);
    for (v, t) in field.iter().zip(truth) {
        if v.state.is_measured() {
            sq += (v.u - t.u).powi(2) + (v.v - t.v).powi(2);
            n += 1;
        }
    }
    ((sq / n as f64).sqrt(), n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, u: f64, flag: u8) -> Vector {
        Vector {
            x,
            y,
            u,
            v: 0.0,
            state: spiv_formats::State::from_flag(flag).unwrap(),
        }
    }

    #[test]
    fn profile_and_errors() {
        let truth = [
            v(0.0, 10.0, 2.0, 0),
            v(1.0, 10.0, 2.0, 0),
            v(0.0, 20.0, 1.0, 0),
            v(1.0, 20.0, 1.0, 0),
        ];
        let field = [
            v(0.0, 10.0, 2.2, 0),
            v(1.0, 10.0, 9.0, 2),
            v(0.0, 20.0, 0.0, 2),
            v(1.0, 20.0, 0.0, 2),
        ];
        let rows = row_profile(&field, &truth, 30.0);
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].y_wall, 19.5);
        assert!((rows[0].measured.unwrap() - 2.2).abs() < 1e-12);
        assert_eq!(rows[1].measured, None);
        let all = region_error(&rows, |_| true);
        assert_eq!((all.rows, all.lost), (2, 1));
        assert!((all.rmae - (0.2 + 1.0) / 3.0).abs() < 1e-12);
        assert!((all.rmse - ((0.04 + 1.0) / 2.0f64).sqrt()).abs() < 1e-12);
        let low = region_error(&rows, |y| y < 15.0);
        assert_eq!(low.rows, 1);
        assert!((low.rmae - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rmae_of_an_all_zero_truth_is_undefined_not_perfect() {
        let truth = [v(0.0, 10.0, 0.0, 0), v(1.0, 10.0, 0.0, 0)];
        let field = [v(0.0, 10.0, 0.5, 0), v(1.0, 10.0, 0.3, 0)];
        let e = region_error(&row_profile(&field, &truth, 30.0), |_| true);
        assert!(e.rmae.is_nan(), "{e:?}");
        assert!((e.rmse - 0.4).abs() < 1e-12);
        // No row selected at all: undefined too.
        assert!(region_error(&[], |_| true).rmae.is_nan());
        // Ratios carry the undefined value instead of hiding it.
        assert!(rmae_ratio(0.5, f64::NAN).is_nan());
        assert!(rmae_ratio(f64::NAN, 0.5).is_nan());
        assert_eq!(rmae_ratio(0.5, 0.0), f64::INFINITY);
        assert_eq!(rmae_ratio(0.5, 0.25), 2.0);
        // JSON has no NaN: it is written as null.
        assert_eq!(serde_json::to_string(&e.rmae).unwrap(), "null");
    }

    #[test]
    fn confidence_interval() {
        let m = mean_ci(&[1.0, 2.0, 3.0]);
        assert!((m.mean - 2.0).abs() < 1e-12);
        assert!((m.ci95 - 4.303 * (1.0f64 / 3.0).sqrt()).abs() < 1e-9);
        assert_eq!(mean_ci(&[5.0]).ci95, 0.0);
    }
}
