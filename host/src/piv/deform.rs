//! Image deformation between passes: the displacement field of the previous
//! pass, interpolated to every pixel, moves image A back and image B forward
//! by half of it (central difference), so the next pass correlates what is
//! left.

use ndarray::{Array2, Zip};

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
    /// the most accurate of the three for 4–6 px particle images.
    Bspline,
}

/// An image ready to be resampled: the gray values, or for
/// [`Interp::Bspline`] their B-spline coefficients (computed once).
#[derive(Debug, Clone)]
pub struct Resampler {
    img: Array2<f32>,
    interp: Interp,
}

impl Resampler {
    /// Prepares `img` for `interp`.
    pub fn new(img: &Array2<f32>, interp: Interp) -> Resampler {
        let img = match interp {
            Interp::Bspline => bspline_coefficients(img),
            _ => img.clone(),
        };
        Resampler { img, interp }
    }

    /// The value at (x right, y down) px, mirrored at the edges for
    /// B-splines, clamped otherwise.
    pub fn at(&self, x: f64, y: f64) -> f32 {
        sample(&self.img, x, y, self.interp)
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
pub fn bspline_coefficients(img: &Array2<f32>) -> Array2<f32> {
    let (h, w) = img.dim();
    let mut c = img.mapv(f64::from);
    let mut line = vec![0.0f64; w.max(h)];
    for i in 0..h {
        for j in 0..w {
            line[j] = c[[i, j]];
        }
        prefilter(&mut line[..w]);
        for j in 0..w {
            c[[i, j]] = line[j];
        }
    }
    for j in 0..w {
        for i in 0..h {
            line[i] = c[[i, j]];
        }
        prefilter(&mut line[..h]);
        for i in 0..h {
            c[[i, j]] = line[i];
        }
    }
    c.mapv(|v| v as f32)
}

fn prefilter(c: &mut [f64]) {
    let n = c.len();
    if n < 2 {
        return;
    }
    let z = 3f64.sqrt() - 2.0;
    for v in c.iter_mut() {
        *v *= 6.0;
    }
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
    let cols: Vec<(usize, usize, f64)> = (0..w).map(|j| grid.locate_x(j as f64)).collect();
    let rows: Vec<(usize, usize, f64)> = (0..h).map(|i| grid.locate_y(i as f64)).collect();
    let mut du = Array2::<f32>::zeros((h, w));
    let mut dv = Array2::<f32>::zeros((h, w));
    Zip::indexed(&mut du)
        .and(&mut dv)
        .par_for_each(|(i, j), du, dv| {
            let (r0, r1, fy) = rows[i];
            let (c0, c1, fx) = cols[j];
            let bl = |f: &Array2<f64>| {
                let top = f[[r0, c0]] * (1.0 - fx) + f[[r0, c1]] * fx;
                let bot = f[[r1, c0]] * (1.0 - fx) + f[[r1, c1]] * fx;
                top * (1.0 - fy) + bot * fy
            };
            *du = bl(u) as f32;
            *dv = bl(v) as f32;
        });
    (du, dv)
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
    Zip::indexed(&mut oa)
        .and(&mut ob)
        .and(&mut out)
        .par_for_each(|(i, j), pa, pb, o| {
            let (hx, hy) = (0.5 * f64::from(du[[i, j]]), 0.5 * f64::from(dv[[i, j]]));
            let (xa, ya, xb, yb) = (j as f64 - hx, i as f64 - hy, j as f64 + hx, i as f64 + hy);
            *pa = a.at(xa, ya);
            *pb = b.at(xb, yb);
            let inside = |x: f64, y: f64| (-0.5..=xmax).contains(&x) && (-0.5..=ymax).contains(&y);
            *o = !(inside(xa, ya) && inside(xb, yb));
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
