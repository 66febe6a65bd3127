//! FFT cross-correlation of one pair of interrogation windows, with the
//! sub-pixel peak and the peak ratio.
//!
//! Both windows go through one complex FFT (`a + i·b`, separated by the
//! conjugate symmetry of real signals), so a window pair costs one forward
//! and one inverse 2-D transform. Plans are made once per window size and
//! shared by all threads; each thread owns a [`Scratch`].

use std::sync::Arc;

use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

/// FFT plans for square windows of one size.
pub struct Plan {
    n: usize,
    fwd: Arc<dyn Fft<f32>>,
    inv: Arc<dyn Fft<f32>>,
}

impl std::fmt::Debug for Plan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Plan({}x{})", self.n, self.n)
    }
}

impl Plan {
    /// Plans for `n × n` windows (any n ≥ 4; powers of two are fastest).
    pub fn new(n: usize) -> Plan {
        let mut planner = FftPlanner::new();
        Plan {
            n,
            fwd: planner.plan_fft_forward(n),
            inv: planner.plan_fft_inverse(n),
        }
    }

    /// Window side, px.
    pub fn size(&self) -> usize {
        self.n
    }
}

/// Per-thread buffers for one window size.
#[derive(Debug)]
pub struct Scratch {
    z: Vec<Complex32>,
    t: Vec<Complex32>,
    fft: Vec<Complex32>,
    /// The window of image A, then of B, zero-mean (row-major n×n).
    pub a: Vec<f32>,
    /// The window of image B.
    pub b: Vec<f32>,
    /// Pixels excluded by the mask (`true` = masked), or empty.
    pub masked: Vec<bool>,
}

impl Scratch {
    /// Buffers for `plan`'s size.
    pub fn new(plan: &Plan) -> Scratch {
        let n2 = plan.n * plan.n;
        let len = plan
            .fwd
            .get_inplace_scratch_len()
            .max(plan.inv.get_inplace_scratch_len());
        Scratch {
            z: vec![Complex32::default(); n2],
            t: vec![Complex32::default(); n2],
            fft: vec![Complex32::default(); len],
            a: vec![0.0; n2],
            b: vec![0.0; n2],
            masked: Vec::new(),
        }
    }
}

/// Why a window gave no displacement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoPeak {
    /// A window has (almost) zero variance: all-zero, all-saturated or masked.
    NoSignal,
    /// The correlation has no positive maximum.
    NoPeak,
}

/// The correlation peak of one window pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    /// Displacement of B relative to A, px (right).
    pub dx: f64,
    /// Displacement, px (down).
    pub dy: f64,
    /// Normalised correlation at the peak, in [−1, 1].
    pub height: f64,
    /// Highest peak / second highest outside its 5×5 neighbourhood (≥ 1;
    /// 1000 when there is no positive second peak).
    pub ratio: f64,
}

/// A window is flat (no signal: all-zero, clipped, masked) when its
/// standard deviation is below this fraction of its mean level (or of 1 gray
/// in the dark): interpolation ripple and rounding are not particles.
const FLAT: f64 = 1e-3;

/// Correlates the windows already in `s.a` and `s.b` (raw gray values).
///
/// Each window is made zero-mean over its unmasked pixels (masked pixels are
/// set to the mean, so they add nothing); the correlation is normalised by
/// both energies. Sub-pixel: 3-point Gaussian per axis, the 3-point parabola
/// where a value is not positive, 0 where neither has a maximum.
pub fn correlate(plan: &Plan, s: &mut Scratch, method: Subpixel) -> Result<Peak, NoPeak> {
    let n = plan.n;
    let (ea, ma, ka) = zero_mean(&mut s.a, &s.masked);
    let (eb, mb, kb) = zero_mean(&mut s.b, &s.masked);
    let n2 = (n * n) as f64;
    // Too few pixels left (an eighth of the window) or no contrast.
    let flat = |e: f64, m: f64, k: usize| {
        k < (n * n / 8).max(2) || e / k as f64 <= (FLAT * m.abs().max(1.0)).powi(2)
    };
    if flat(ea, ma, ka) || flat(eb, mb, kb) {
        return Err(NoPeak::NoSignal);
    }
    for ((z, &a), &b) in s.z.iter_mut().zip(&s.a).zip(&s.b) {
        *z = Complex32::new(a, b);
    }
    // Forward 2-D FFT; the result is left transposed (rows = frequency kx).
    plan.fwd.process_with_scratch(&mut s.z, &mut s.fft);
    transpose(&s.z, &mut s.t, n);
    plan.fwd.process_with_scratch(&mut s.t, &mut s.fft);
    // Separate A and B and form conj(A)·B (the layout is symmetric under -k).
    // (Index arithmetic without `%`: an integer division per sample cost
    // more than the spectrum product itself.)
    let mirror = |k: usize| if k == 0 { 0 } else { n - k };
    for p in 0..n {
        let row = &s.t[p * n..(p + 1) * n];
        let row_m = &s.t[mirror(p) * n..(mirror(p) + 1) * n];
        let out = &mut s.z[p * n..(p + 1) * n];
        for (q, (o, &zk)) in out.iter_mut().zip(row).enumerate() {
            let zm = row_m[mirror(q)].conj();
            let a = (zk + zm) * 0.5;
            let b = (zk - zm) * Complex32::new(0.0, -0.5);
            *o = a.conj() * b;
        }
    }
    // Inverse: columns (rows of the transposed layout), transpose, rows.
    plan.inv.process_with_scratch(&mut s.z, &mut s.fft);
    transpose(&s.z, &mut s.t, n);
    plan.inv.process_with_scratch(&mut s.t, &mut s.fft);
    let norm = 1.0 / (n2 * (ea * eb).sqrt());
    let (mut best_k, mut best_raw) = (0usize, f32::NEG_INFINITY);
    for (k, z) in s.t.iter().enumerate() {
        if z.re > best_raw {
            (best_k, best_raw) = (k, z.re);
        }
    }
    let (bi, bj) = (best_k / n, best_k % n);
    let best = f64::from(best_raw) * norm;
    if !best.is_finite() || best <= 0.0 {
        return Err(NoPeak::NoPeak);
    }
    let c = |i: usize, j: usize| f64::from(s.t[(i % n) * n + (j % n)].re) * norm;
    // The second peak: the maximum outside the 5×5 around the first.
    let mut second_raw = 0.0f32;
    let dist = |k: usize, b: usize| if k >= b { k - b } else { k + n - b };
    for i in 0..n {
        let di = dist(i, bi);
        let row = &s.t[i * n..(i + 1) * n];
        if di <= 2 || di >= n - 2 {
            for (j, z) in row.iter().enumerate() {
                let dj = dist(j, bj);
                if dj > 2 && dj < n - 2 {
                    second_raw = second_raw.max(z.re);
                }
            }
        } else {
            for z in row {
                second_raw = second_raw.max(z.re);
            }
        }
    }
    let second = f64::from(second_raw) * norm;
    let ratio = if second > 0.0 {
        (best / second).min(1000.0)
    } else {
        1000.0
    };
    let fit = |m: f64, p: f64| match method {
        Subpixel::Gaussian => subpixel(m, best, p),
        Subpixel::Parabolic => parabolic(m, best, p),
        Subpixel::Gaussian2d => subpixel(m, best, p),
    };
    let (mut sy, mut sx) = (
        fit(c(bi + n - 1, bj), c(bi + 1, bj)),
        fit(c(bi, bj + n - 1), c(bi, bj + 1)),
    );
    if method == Subpixel::Gaussian2d {
        let mut v = [[0.0; 3]; 3];
        for (r, row) in v.iter_mut().enumerate() {
            for (k, x) in row.iter_mut().enumerate() {
                *x = c(bi + n + r - 1, bj + n + k - 1);
            }
        }
        if let Some((dx, dy)) = gaussian2d(&v) {
            (sx, sy) = (dx, dy);
        }
    }
    let wrap = |k: usize| {
        if k >= n / 2 {
            k as f64 - n as f64
        } else {
            k as f64
        }
    };
    Ok(Peak {
        dx: wrap(bj) + sx,
        dy: wrap(bi) + sy,
        height: best,
        ratio,
    })
}

/// Makes `w` zero-mean over unmasked pixels; returns its energy Σw², its
/// former mean and the number of unmasked pixels.
fn zero_mean(w: &mut [f32], masked: &[bool]) -> (f64, f64, usize) {
    if masked.is_empty() {
        // No mask: the same sums without a lookup per pixel.
        let sum: f64 = w.iter().fold(0.0, |acc, &v| acc + f64::from(v));
        let cnt = w.len();
        if cnt == 0 {
            return (0.0, 0.0, 0);
        }
        let mean = sum / cnt as f64;
        let m32 = mean as f32;
        let mut e = 0.0f64;
        for v in w.iter_mut() {
            *v -= m32;
            e += f64::from(*v) * f64::from(*v);
        }
        return (e, mean, cnt);
    }
    let (mut sum, mut cnt) = (0.0f64, 0usize);
    for (k, &v) in w.iter().enumerate() {
        if masked.get(k).copied() != Some(true) {
            sum += f64::from(v);
            cnt += 1;
        }
    }
    if cnt == 0 {
        w.fill(0.0);
        return (0.0, 0.0, 0);
    }
    let mean = sum / cnt as f64;
    let m32 = mean as f32;
    let mut e = 0.0f64;
    for (k, v) in w.iter_mut().enumerate() {
        *v = if masked.get(k).copied() == Some(true) {
            0.0
        } else {
            *v - m32
        };
        e += f64::from(*v) * f64::from(*v);
    }
    (e, mean, cnt)
}

fn transpose(src: &[Complex32], dst: &mut [Complex32], n: usize) {
    transpose::transpose(src, dst, n, n);
}

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
fn gaussian2d(v: &[[f64; 3]; 3]) -> Option<(f64, f64)> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(n: usize, cx: f64, cy: f64, out: &mut [f32]) {
        for i in 0..n {
            for j in 0..n {
                let (dx, dy) = (j as f64 - cx, i as f64 - cy);
                out[i * n + j] += (200.0 * (-(dx * dx + dy * dy) / 4.0).exp()) as f32;
            }
        }
    }

    #[test]
    fn finds_a_shift_of_one_particle_both_ways() {
        let plan = Plan::new(32);
        let mut s = Scratch::new(&plan);
        for (dx, dy) in [(3.3, -2.6), (-7.25, 5.5), (0.0, 0.0)] {
            s.a.fill(0.0);
            s.b.fill(0.0);
            blob(32, 14.0, 15.0, &mut s.a);
            blob(32, 14.0 + dx, 15.0 + dy, &mut s.b);
            let p = correlate(&plan, &mut s, Subpixel::Gaussian).expect("peak");
            assert!(
                (p.dx - dx).abs() < 0.1 && (p.dy - dy).abs() < 0.1,
                "{p:?} vs {dx},{dy}"
            );
            assert!(p.height > 0.5 && p.height <= 1.0 + 1e-6);
        }
    }

    #[test]
    fn flat_windows_have_no_signal() {
        let plan = Plan::new(16);
        let mut s = Scratch::new(&plan);
        s.a.fill(255.0);
        s.b.fill(255.0);
        assert_eq!(
            correlate(&plan, &mut s, Subpixel::Gaussian),
            Err(NoPeak::NoSignal)
        );
        s.a.fill(0.0);
        blob(16, 8.0, 8.0, &mut s.b);
        assert_eq!(
            correlate(&plan, &mut s, Subpixel::Gaussian),
            Err(NoPeak::NoSignal)
        );
    }

    #[test]
    fn subpixel_fallbacks_stay_finite() {
        assert_eq!(subpixel(0.0, 0.0, 0.0), 0.0);
        assert!((subpixel(-0.2, 0.5, 0.1)).abs() < 1.0);
        assert!((subpixel(0.5, 1.0, 0.5)).abs() < 1e-12);
        assert_eq!(subpixel(1.0, 0.5, 1.0), 0.0);
    }
}
