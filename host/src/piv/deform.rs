//! Image deformation between passes: the displacement field of the previous
//! pass, interpolated to every pixel, moves image A back and image B forward
//! by half of it (central difference), so the next pass correlates what is
//! left.

use ndarray::{Array2, Axis};
use rayon::prelude::*;

use super::grid::Grid;

/// How a deformed image is resampled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interp {
    /// 2×2 taps.
    Bilinear,
    /// Keys' cubic convolution (a = −½), 4×4 taps.
    Bicubic,
    /// Cubic B-spline interpolation (Unser's prefilter, then 4×4 taps):
    /// the most accurate cubic for 4–6 px particle images.
    Bspline,
    /// Quintic B-spline (6×6 taps): smaller interpolation error on small
    /// particles, 2.25× the taps.
    Bspline5,
}

/// An image ready to be resampled: the gray values, or for
/// [`Interp::Bspline`] their B-spline coefficients (computed once).
#[derive(Debug, Clone)]
pub struct Resampler {
    img: Array2<f32>,
    /// The same values, row-major, for the unchecked-free fast path.
    data: Vec<f32>,
    w: usize,
    h: usize,
    interp: Interp,
}

impl Resampler {
    /// Prepares `img` for `interp`.
    pub fn new(img: &Array2<f32>, interp: Interp) -> Resampler {
        let img = match interp {
            Interp::Bspline => bspline_coefficients(img, &CUBIC_POLES),
            Interp::Bspline5 => bspline_coefficients(img, &QUINTIC_POLES),
            _ => img.clone(),
        };
        let (h, w) = img.dim();
        let data = img.iter().copied().collect();
        Resampler {
            img,
            data,
            w,
            h,
            interp,
        }
    }

    /// The value at (x right, y down) px, mirrored at the edges for
    /// B-splines, clamped otherwise.
    ///
    /// Hand-written fast path (the deformation's hot loop): where the 4×4
    /// taps lie inside the image, they are read straight from the row-major
    /// buffer in f32; elsewhere the general edge-handling path runs.
    #[inline]
    pub fn at(&self, x: f64, y: f64) -> f32 {
        let (x0, y0) = (x.floor(), y.floor());
        let inside = x0 >= 1.0 && y0 >= 1.0 && x0 + 2.0 < self.w as f64 && y0 + 2.0 < self.h as f64;
        if self.interp == Interp::Bspline5 {
            let inside5 =
                x0 >= 2.0 && y0 >= 2.0 && x0 + 3.0 < self.w as f64 && y0 + 3.0 < self.h as f64;
            if !inside5 {
                return sample(&self.img, x, y, self.interp);
            }
            let (wx, wy) = (quintic_weights(x - x0), quintic_weights(y - y0));
            let wx = wx.map(|v| v as f32);
            let base = (y0 as usize - 2) * self.w + x0 as usize - 2;
            let mut acc = 0.0f32;
            for (r, &wr) in wy.iter().enumerate() {
                let o = base + r * self.w;
                let row = &self.data[o..o + 6];
                let mut s = 0.0f32;
                for k in 0..6 {
                    s += wx[k] * row[k];
                }
                acc += wr as f32 * s;
            }
            return acc;
        }
        if !inside || self.interp == Interp::Bilinear {
            return sample(&self.img, x, y, self.interp);
        }
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (wx, wy) = match self.interp {
            Interp::Bicubic => (keys32(fx), keys32(fy)),
            _ => (bspline32(fx), bspline32(fy)),
        };
        let base = (y0 as usize - 1) * self.w + x0 as usize - 1;
        let mut acc = 0.0f32;
        for (r, wr) in wy.iter().enumerate() {
            let o = base + r * self.w;
            let row = &self.data[o..o + 4];
            acc += wr * (wx[0] * row[0] + wx[1] * row[1] + wx[2] * row[2] + wx[3] * row[3]);
        }
        acc
    }
}

/// Mirror index into 0..n (whole-sample symmetric).
fn mirror(k: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let p = 2 * (n - 1);
    let mut k = k.rem_euclid(p);
    if k >= n {
        k = p - k;
    }
    k as usize
}

fn bspline_at(c: &Array2<f32>, x: f64, y: f64) -> f32 {
    let (h, w) = c.dim();
    let (x0, y0) = (x.floor(), y.floor());
    let (wx, wy) = (bspline_weights(x - x0), bspline_weights(y - y0));
    let (xi, yi) = (x0 as isize, y0 as isize);
    let cols = [0, 1, 2, 3].map(|k| mirror(xi + k - 1, w));
    let mut acc = 0.0f64;
    for (r, wyr) in wy.iter().enumerate() {
        let row = mirror(yi + r as isize - 1, h);
        let mut s = 0.0f64;
        for (&col, wxc) in cols.iter().zip(&wx) {
            s += wxc * f64::from(c[[row, col]]);
        }
        acc += wyr * s;
    }
    acc as f32
}

fn bspline32(t: f32) -> [f32; 4] {
    const SIXTH: f32 = 1.0 / 6.0;
    let t2 = t * t;
    let t3 = t2 * t;
    let u = 1.0 - t;
    let w3 = t3 * SIXTH;
    let w0 = u * u * u * SIXTH;
    // w1 = (3t³ − 6t² + 4)/6; w2 = 1 − w0 − w1 − w3 (partition of unity).
    let w1 = 0.5 * t3 - t2 + 2.0 / 3.0;
    [w0, w1, 1.0 - w0 - w1 - w3, w3]
}

fn keys32(t: f32) -> [f32; 4] {
    let k = keys(f64::from(t));
    k.map(|v| v as f32)
}

fn bspline_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let u = 1.0 - t;
    [
        u * u * u / 6.0,
        (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
        t3 / 6.0,
    ]
}

/// Cubic B-spline coefficients of an image (separable recursive prefilter,
/// mirror boundaries; Unser 1999, Thévenaz et al. 2000).
pub fn bspline_coefficients(img: &Array2<f32>, poles: &[f64]) -> Array2<f32> {
    // Rows, transpose, rows again (= columns), transpose back; rows in
    // parallel.
    let filter_rows = |m: &mut Array2<f32>| {
        m.axis_iter_mut(Axis(0))
            .into_par_iter()
            .for_each(|mut row| {
                let mut line: Vec<f64> = row.iter().map(|&v| f64::from(v)).collect();
                prefilter(&mut line, poles);
                for (o, v) in row.iter_mut().zip(line) {
                    *o = v as f32;
                }
            });
    };
    let mut c = img.to_owned();
    filter_rows(&mut c);
    let mut t = c.t().as_standard_layout().into_owned();
    filter_rows(&mut t);
    t.t().as_standard_layout().into_owned()
}

const CUBIC_POLES: [f64; 1] = [-0.267_949_192_431_122_7];
const QUINTIC_POLES: [f64; 2] = [-0.430_575_347_099_973, -0.043_096_288_203_264_7];

fn prefilter(c: &mut [f64], poles: &[f64]) {
    let n = c.len();
    if n < 2 {
        return;
    }
    let gain: f64 = poles.iter().map(|&z| (1.0 - z) * (1.0 - 1.0 / z)).product();
    for v in c.iter_mut() {
        *v *= gain;
    }
    for &z in poles {
        // Causal initialisation, mirror boundary, exact.
        let iz = 1.0 / z;
        let mut zn = z;
        let mut z2n = z.powi(n as i32 - 1);
        let mut sum = c[0] + z2n * c[n - 1];
        z2n = z2n * z2n * iz;
        for &v in &c[1..n - 1] {
            sum += (zn + z2n) * v;
            zn *= z;
            z2n *= iz;
        }
        c[0] = sum / (1.0 - zn * zn);
        for k in 1..n {
            c[k] += z * c[k - 1];
        }
        c[n - 1] = (z / (z * z - 1.0)) * (z * c[n - 2] + c[n - 1]);
        for k in (0..n - 1).rev() {
            c[k] = z * (c[k + 1] - c[k]);
        }
    }
}

/// Quintic B-spline weights for the taps at −2..=3 (Thévenaz et al.).
fn quintic_weights(t: f64) -> [f64; 6] {
    let mut w = t;
    let mut w2 = w * w;
    let w5 = (1.0 / 120.0) * w * w2 * w2;
    w2 -= w;
    let w4 = w2 * w2;
    w -= 0.5;
    let t3 = w2 * (w2 - 3.0);
    let w0 = (1.0 / 24.0) * (1.0 / 5.0 + w2 + w4) - w5;
    let t0 = (1.0 / 24.0) * (w2 * (w2 - 5.0) + 46.0 / 5.0);
    let t1 = (-1.0 / 12.0) * w * (t3 + 4.0);
    let (x2, x3) = (t0 + t1, t0 - t1);
    let t0 = (1.0 / 16.0) * (9.0 / 5.0 - t3);
    let t1 = (1.0 / 24.0) * w * (w4 - w2 - 5.0);
    [w0, t0 + t1, x2, x3, t0 - t1, w5]
}

fn quintic_at(c: &Array2<f32>, x: f64, y: f64) -> f32 {
    let (h, w) = c.dim();
    let (x0, y0) = (x.floor(), y.floor());
    let (wx, wy) = (quintic_weights(x - x0), quintic_weights(y - y0));
    let (xi, yi) = (x0 as isize, y0 as isize);
    let cols = [0, 1, 2, 3, 4, 5].map(|k| mirror(xi + k - 2, w));
    let mut acc = 0.0f64;
    for (r, wyr) in wy.iter().enumerate() {
        let row = mirror(yi + r as isize - 2, h);
        let mut s = 0.0f64;
        for (&col, wxc) in cols.iter().zip(&wx) {
            s += wxc * f64::from(c[[row, col]]);
        }
        acc += wyr * s;
    }
    acc as f32
}

/// Samples `img` at (x right, y down) px; edges are clamped (mirrored for
/// B-splines, where `img` holds the coefficients).
fn sample(img: &Array2<f32>, x: f64, y: f64, interp: Interp) -> f32 {
    let (h, w) = img.dim();
    let clamp = |k: isize, n: usize| k.clamp(0, n as isize - 1) as usize;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (xi, yi) = (x0 as isize, y0 as isize);
    match interp {
        Interp::Bspline => bspline_at(img, x, y),
        Interp::Bspline5 => quintic_at(img, x, y),
        Interp::Bilinear => {
            let p = |dy: isize, dx: isize| f64::from(img[[clamp(yi + dy, h), clamp(xi + dx, w)]]);
            let top = p(0, 0) * (1.0 - fx) + p(0, 1) * fx;
            let bot = p(1, 0) * (1.0 - fx) + p(1, 1) * fx;
            (top * (1.0 - fy) + bot * fy) as f32
        }
        Interp::Bicubic => {
            let wx = keys(fx);
            let wy = keys(fy);
            let mut acc = 0.0f64;
            for (r, wyr) in wy.iter().enumerate() {
                let row = clamp(yi + r as isize - 1, h);
                let mut s = 0.0f64;
                for (c, wxc) in wx.iter().enumerate() {
                    s += wxc * f64::from(img[[row, clamp(xi + c as isize - 1, w)]]);
                }
                acc += wyr * s;
            }
            acc as f32
        }
    }
}

/// Keys' cubic convolution weights for the taps at −1, 0, 1, 2.
fn keys(t: f64) -> [f64; 4] {
    const A: f64 = -0.5;
    let f1 = |d: f64| ((A + 2.0) * d - (A + 3.0)) * d * d + 1.0;
    let f2 = |d: f64| ((A * d - 5.0 * A) * d + 8.0 * A) * d - 4.0 * A;
    [f2(1.0 + t), f1(t), f1(1.0 - t), f2(2.0 - t)]
}

/// The field of `grid` (`u`, `v` at window centres) at every pixel of an
/// `h × w` image: bilinear between centres, constant beyond the outer ones.
pub fn dense(
    grid: &Grid,
    u: &Array2<f64>,
    v: &Array2<f64>,
    h: usize,
    w: usize,
) -> (Array2<f32>, Array2<f32>) {
    let (first, step) = ((grid.size as f64 - 1.0) / 2.0, grid.step as f64);
    let pos = |p: f64, n: usize| ((p - first) / step).clamp(-1.0, n as f64);
    // Every pixel column's four taps into the extended grid row (two
    // linearly extrapolated nodes on each side) and their weights: the same
    // for every row, so computed once.
    let taps: Vec<(usize, [f64; 4])> = (0..w)
        .map(|j| {
            let p = pos(j as f64, grid.nx);
            let k = p.floor();
            ((k as isize + 1) as usize, catmull_rom(p - k))
        })
        .collect();
    let mut du = Array2::<f32>::zeros((h, w));
    let mut dv = Array2::<f32>::zeros((h, w));
    du.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(dv.axis_iter_mut(Axis(0)))
        .enumerate()
        .for_each(|(i, (mut ru, mut rv))| {
            // Along y for every grid column, then along x.
            let fy = pos(i as f64, grid.ny);
            let blend = |f: &Array2<f64>| -> Vec<f64> {
                let row: Vec<f64> = f
                    .columns()
                    .into_iter()
                    .map(|col| cubic(|k| col[k], grid.ny, fy))
                    .collect();
                extend(&row)
            };
            let (bu, bv) = (blend(u), blend(v));
            for (j, (k, wt)) in taps.iter().enumerate() {
                let (a, b) = (&bu[*k..*k + 4], &bv[*k..*k + 4]);
                ru[j] = (wt[0] * a[0] + wt[1] * a[1] + wt[2] * a[2] + wt[3] * a[3]) as f32;
                rv[j] = (wt[0] * b[0] + wt[1] * b[1] + wt[2] * b[2] + wt[3] * b[3]) as f32;
            }
        });
    (du, dv)
}

/// `row` with two linearly extrapolated values on each side (index 2 is
/// node 0).
fn extend(row: &[f64]) -> Vec<f64> {
    let n = row.len();
    let (d0, d1) = if n >= 2 {
        (row[1] - row[0], row[n - 1] - row[n - 2])
    } else {
        (0.0, 0.0)
    };
    let mut e = Vec::with_capacity(n + 5);
    e.extend([row[0] - 2.0 * d0, row[0] - d0]);
    e.extend_from_slice(row);
    e.extend([
        row[n - 1] + d1,
        row[n - 1] + 2.0 * d1,
        row[n - 1] + 3.0 * d1,
    ]);
    e
}

/// Catmull-Rom weights of the nodes at −1, 0, 1, 2 for fraction `t`.
fn catmull_rom(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t + 2.0 * t2 - t3),
        0.5 * (2.0 - 5.0 * t2 + 3.0 * t3),
        0.5 * (t + 4.0 * t2 - 3.0 * t3),
        0.5 * (-t2 + t3),
    ]
}

/// Catmull-Rom interpolation of the sequence `f(0..n)` at position `p`
/// (−1 ≤ p ≤ n): values beyond the ends are extended linearly, so a linear
/// field is reproduced everywhere, and the curve passes through every node.
fn cubic(f: impl Fn(usize) -> f64, n: usize, p: f64) -> f64 {
    if n == 1 {
        return f(0);
    }
    let at = |k: isize| -> f64 {
        if k < 0 {
            f(0) + k as f64 * (f(1) - f(0))
        } else if k as usize >= n {
            f(n - 1) + (k as f64 - (n - 1) as f64) * (f(n - 1) - f(n - 2))
        } else {
            f(k as usize)
        }
    };
    let k0 = p.floor();
    let t = p - k0;
    let k = k0 as isize;
    let (p0, p1, p2, p3) = (at(k - 1), at(k), at(k + 1), at(k + 2));
    let t2 = t * t;
    let t3 = t2 * t;
    0.5 * (2.0 * p1
        + (p2 - p0) * t
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * t3)
}

/// Deforms the pair by the dense field: A at x − d/2, B at x + d/2.
/// Also returns where either sample fell outside the image (no data: the
/// correlation leaves those pixels out).
pub fn deform(
    a: &Resampler,
    b: &Resampler,
    du: &Array2<f32>,
    dv: &Array2<f32>,
) -> (Array2<f32>, Array2<f32>, Array2<bool>) {
    let (h, w) = du.dim();
    let (xmax, ymax) = ((w - 1) as f64 + 0.5, (h - 1) as f64 + 0.5);
    let mut oa = Array2::<f32>::zeros((h, w));
    let mut ob = Array2::<f32>::zeros((h, w));
    let mut out = Array2::from_elem((h, w), false);
    oa.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(ob.axis_iter_mut(Axis(0)))
        .zip(out.axis_iter_mut(Axis(0)))
        .enumerate()
        .for_each(|(i, ((mut ra, mut rb), mut ro))| {
            let (ru, rv) = (du.row(i), dv.row(i));
            let y = i as f64;
            for j in 0..w {
                let (hx, hy) = (0.5 * f64::from(ru[j]), 0.5 * f64::from(rv[j]));
                let x = j as f64;
                let (xa, ya, xb, yb) = (x - hx, y - hy, x + hx, y + hy);
                ra[j] = a.at(xa, ya);
                rb[j] = b.at(xb, yb);
                let inside =
                    |x: f64, y: f64| (-0.5..=xmax).contains(&x) && (-0.5..=ymax).contains(&y);
                ro[j] = !(inside(xa, ya) && inside(xb, yb));
            }
        });
    (oa, ob, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolators_are_exact_at_nodes_and_on_linear_ramps() {
        let img = Array2::from_shape_fn((8, 9), |(i, j)| (2 * i + 3 * j) as f32);
        for interp in [Interp::Bilinear, Interp::Bicubic] {
            assert_eq!(sample(&img, 4.0, 3.0, interp), 18.0);
            let v = sample(&img, 4.25, 3.5, interp);
            assert!((v - (7.0 + 12.75)).abs() < 1e-4, "{interp:?} {v}");
        }
        // B-splines interpolate (exact at nodes) and reproduce a ramp away
        // from the mirrored edges.
        let big = Array2::from_shape_fn((32, 32), |(i, j)| (2 * i + 3 * j) as f32);
        let r = Resampler::new(&big, Interp::Bspline);
        for (i, j) in [(0, 0), (3, 4), (31, 31), (17, 9)] {
            assert!((r.at(j as f64, i as f64) - big[[i, j]]).abs() < 1e-3);
        }
        let v = r.at(15.25, 16.5);
        assert!((v - (33.0 + 45.75)).abs() < 1e-3, "{v}");
        // Clamped outside.
        assert_eq!(sample(&img, -5.0, -5.0, Interp::Bilinear), 0.0);
    }

    #[test]
    fn keys_weights_sum_to_one() {
        for t in [0.0, 0.1, 0.5, 0.9] {
            let s: f64 = keys(t).iter().sum();
            assert!((s - 1.0).abs() < 1e-12);
        }
    }
}
