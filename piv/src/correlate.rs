//! FFT cross-correlation of one pair of interrogation windows, with the
//! sub-pixel peak and the peak ratio.
//!
//! Both windows go through one complex FFT (`a + i·b`, separated by the
//! conjugate symmetry of real signals), and the real correlation comes
//! back through half an inverse: the columns of half the spectrum, then two
//! rows per complex transform. Plans are made once per window size and
//! shared by all threads; each thread owns a [`Scratch`].

use std::sync::{Arc, Mutex, OnceLock};

use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use wide::f32x8;

use super::peak::{gaussian2d, parabolic, subpixel, width as peak_width, Subpixel};

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
    /// Plans come from one planner shared by the process, which keeps
    /// every size it has made: later passes and pairs reuse them.
    pub fn new(n: usize) -> Plan {
        static PLANNER: OnceLock<Mutex<FftPlanner<f32>>> = OnceLock::new();
        let planner = PLANNER.get_or_init(|| Mutex::new(FftPlanner::new()));
        // A poisoned lock only means another thread panicked while
        // planning; the planner's cache is still valid.
        let mut planner = planner.lock().unwrap_or_else(|e| e.into_inner());
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
    /// The real correlation plane (row-major n×n, lag 0 at index 0).
    c: Vec<f32>,
    /// The window of image A (row-major n×n, gray values); masked pixels
    /// are overwritten with the window's mean.
    pub a: Vec<f32>,
    /// The window of image B.
    pub b: Vec<f32>,
    /// Pixels excluded by the mask (`true` = masked), or empty.
    pub masked: Vec<bool>,
    /// [`spread`]'s zero-mean windows, (n+1)×(n+1).
    ae: Vec<f32>,
    be: Vec<f32>,
    /// [`spread`]'s differences, (n+1)×(n+2).
    dx: Vec<f32>,
    dy: Vec<f32>,
}

impl Scratch {
    /// The raw correlation plane [`plane`] left (row-major n×n, lag 0 at
    /// index 0).
    pub fn plane(&self) -> &[f32] {
        &self.c
    }

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
            c: vec![0.0; n2],
            a: vec![0.0; n2],
            b: vec![0.0; n2],
            masked: Vec::new(),
            ae: vec![0.0; (plan.n + 1) * (plan.n + 1)],
            be: vec![0.0; (plan.n + 1) * (plan.n + 1)],
            dx: vec![0.0; (plan.n + 1) * (plan.n + 2)],
            dy: vec![0.0; (plan.n + 1) * (plan.n + 2)],
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
    /// The peak's width, px: the larger of its Gaussian σ along x and y
    /// (infinite on a plateau).
    pub width: f64,
    /// Standard uncertainty of `dx` and `dy` from the correlation
    /// statistics ([`uncertainty`]), px.
    pub sigma: (f64, f64),
}

/// A window is flat (no signal: all-zero, clipped, masked) when its
/// standard deviation is below this fraction of its mean level (or of 1 gray
/// in the dark): interpolation ripple and rounding are not particles.
const FLAT: f64 = 1e-3;

/// Correlates the windows already in `s.a` and `s.b` (raw gray values).
///
/// Each window is made zero-mean over its unmasked pixels (masked pixels are
/// set to the mean, so they add nothing) on its way into the FFT buffer; the
/// correlation is normalised by both energies. Sub-pixel: 3-point Gaussian per axis, the 3-point parabola
/// where a value is not positive, 0 where neither has a maximum. The
/// peak's uncertainty comes from the windows' own pixels ([`spread`]).
///
/// The loops over the window are written so that the compiler vectorises
/// them (independent lane accumulators, no index arithmetic per sample):
/// at 32×32 px the scalar versions cost three times the FFTs.
pub fn correlate(plan: &Plan, s: &mut Scratch, method: Subpixel) -> Result<Peak, NoPeak> {
    let p = plane(plan, s)?;
    let (peak, at) = locate(plan.n, &s.c, p.norm, method)?;
    Ok(with_uncertainty(plan, s, peak, at, p))
}

/// `peak` (at lag `at` of the plane [`plane`] left, scaled
/// by `p`) with its uncertainty from the windows in `s.a` and `s.b`.
pub fn with_uncertainty(
    plan: &Plan,
    s: &mut Scratch,
    peak: Peak,
    at: (usize, usize),
    p: PlaneScale,
) -> Peak {
    let (su, sv) = spread(s, plan.n, at, p.means);
    Peak {
        sigma: peak_uncertainty(plan.n, &s.c, p.norm, at, (su * p.direct, sv * p.direct)),
        ..peak
    }
}

/// What [`plane`] leaves besides the raw correlation in `Scratch::c`.
#[derive(Debug, Clone, Copy)]
pub struct PlaneScale {
    /// The raw correlation times this is the normalised one.
    pub norm: f64,
    /// The direct sums of [`spread`] times this are normalised likewise
    /// (the FFT's correlation carries a factor n² they do not).
    pub direct: f64,
    /// The windows' means over their unmasked pixels.
    pub means: (f32, f32),
}

/// The raw cyclic cross-correlation of the windows in `s.a` and `s.b`
/// into `s.c` (lag 0 at index 0), each window zero-mean over its
/// unmasked pixels; [`NoPeak::NoSignal`] when a window is flat or mostly
/// masked.
pub fn plane(plan: &Plan, s: &mut Scratch) -> Result<PlaneScale, NoPeak> {
    let n = plan.n;
    let (ma, mb, k) = means(&mut s.a, &mut s.b, &s.masked);
    let (ea, eb) = fill_z(&mut s.z, &s.a, &s.b, ma as f32, mb as f32);
    let n2 = (n * n) as f64;
    // Too few pixels left (an eighth of the window) or no contrast.
    let flat = |e: f64, m: f64| {
        k < (n * n / 8).max(2) || e / k as f64 <= (FLAT * m.abs().max(1.0)).powi(2)
    };
    if flat(ea, ma) || flat(eb, mb) {
        return Err(NoPeak::NoSignal);
    }
    // Forward 2-D FFT; the result is left transposed (rows = frequency kx).
    plan.fwd.process_with_scratch(&mut s.z, &mut s.fft);
    transpose(&s.z, &mut s.t, n);
    plan.fwd.process_with_scratch(&mut s.t, &mut s.fft);
    // With Z = FFT(a + i·b) and W = Z(−k), the cross spectrum is
    // conj(A)·B = ½·Im(Z·W) − ¼·i·(|Z|² − |W|²): no separation of A and B
    // needed (the layout is symmetric under −k, so transposed is fine).
    // Only kx up to n/2 is transformed back (below).
    let h = n / 2 + 1;
    for p in 0..h {
        let pm = if p == 0 { 0 } else { n - p };
        let row = &s.t[p * n..(p + 1) * n];
        let row_m = &s.t[pm * n..(pm + 1) * n];
        let out = &mut s.z[p * n..(p + 1) * n];
        out[0] = cross(row[0], row_m[0]);
        for ((o, &zk), &w) in out[1..]
            .iter_mut()
            .zip(&row[1..])
            .zip(row_m[1..].iter().rev())
        {
            *o = cross(zk, w);
        }
    }
    // Inverse. The correlation is real, so its spectrum is Hermitian: the
    // columns (rows of the transposed layout) are transformed for kx up to
    // n/2 only. Each row of the plane is then real, so two rows go through
    // one complex transform (the first row's full spectrum plus i times the
    // second's), all pairs in one batched call: the real and imaginary
    // parts come out as the two rows.
    plan.inv.process_with_scratch(&mut s.z[..h * n], &mut s.fft);
    let pairs = n.div_ceil(2);
    // Row kx of the transposed half spectrum holds every row y of the
    // plane at kx: rows 2q and 2q + 1 go into pair q. With n odd the last
    // row has no partner; row n − 1 stands in (any real row does: its part
    // comes out imaginary and is not kept).
    let t = &mut s.t[..pairs * n];
    for (kx, zk) in s.z[..h * n].chunks_exact(n).enumerate() {
        let row_pairs = zk
            .chunks(2)
            .map(|p| (p[0], p.get(1).copied().unwrap_or(zk[n - 1])));
        if kx == 0 || 2 * kx == n {
            // Their own mirror: real up to rounding, the imaginary parts
            // dropped.
            for (out, (a, b)) in t.chunks_exact_mut(n).zip(row_pairs) {
                out[kx] = Complex32::new(a.re, b.re);
            }
        } else {
            // Above n/2 the spectrum is the conjugate of the one at n − kx.
            for (out, (a, b)) in t.chunks_exact_mut(n).zip(row_pairs) {
                out[kx] = Complex32::new(a.re - b.im, a.im + b.re);
                out[n - kx] = Complex32::new(a.re + b.im, b.re - a.im);
            }
        }
    }
    plan.inv
        .process_with_scratch(&mut s.t[..pairs * n], &mut s.fft);
    let parts: &[f32] = bytemuck::cast_slice(&s.t[..pairs * n]);
    for (rows, z) in s.c.chunks_mut(2 * n).zip(parts.chunks_exact(2 * n)) {
        let (first, second) = rows.split_at_mut(n.min(rows.len()));
        for (c, v) in first.iter_mut().zip(z.chunks_exact(2)) {
            *c = v[0];
        }
        for (c, v) in second.iter_mut().zip(z.chunks_exact(2)) {
            *c = v[1];
        }
    }
    let norm = 1.0 / (n2 * (ea * eb).sqrt());
    Ok(PlaneScale {
        norm,
        direct: n2 * norm,
        means: (ma as f32, mb as f32),
    })
}

/// The peak of the `n × n` cyclic correlation `cp` (raw; times `norm` it is
/// normalised) and its integer lag `(row, column)`: position, normalised
/// height, peak ratio and width; its uncertainty is left at zero.
pub fn locate(
    n: usize,
    cp: &[f32],
    norm: f64,
    method: Subpixel,
) -> Result<(Peak, (usize, usize)), NoPeak> {
    // Each row's maximum, in one vectorised pass: the peak, its place and
    // the second peak come from them, and only the five rows around the
    // peak are read again.
    let mut on_stack = [f32::NEG_INFINITY; 64];
    let mut on_heap = Vec::new();
    let row_max: &mut [f32] = if n <= on_stack.len() {
        &mut on_stack[..n]
    } else {
        on_heap.resize(n, f32::NEG_INFINITY);
        &mut on_heap
    };
    for (m, row) in row_max.iter_mut().zip(cp.chunks_exact(n)) {
        *m = max_of(row, f32::NEG_INFINITY);
    }
    let best_raw = max_of(row_max, f32::NEG_INFINITY);
    let best = f64::from(best_raw) * norm;
    if !best.is_finite() || best <= 0.0 {
        return Err(NoPeak::NoPeak);
    }
    // The first sample equal to the peak, in row-major order.
    let bi = row_max
        .iter()
        .position(|&v| v == best_raw)
        .ok_or(NoPeak::NoPeak)?;
    let bj = cp[bi * n..(bi + 1) * n]
        .iter()
        .position(|&v| v == best_raw)
        .ok_or(NoPeak::NoPeak)?;
    let c = |i: usize, j: usize| f64::from(cp[(i % n) * n + (j % n)]) * norm;
    // The second peak: the maximum outside the 5×5 around the first.
    // In the five rows around the peak, the columns outside its 5×5 are
    // the cyclic run of n − 5 from bj + 3: at most two slices.
    let (from, run) = ((bj + 3) % n, n.saturating_sub(5));
    let (head, tail) = (run.min(n - from), run - run.min(n - from));
    let mut second_raw = 0.0f32;
    let dist = |k: usize, b: usize| if k >= b { k - b } else { k + n - b };
    for (i, &m) in row_max.iter().enumerate() {
        let di = dist(i, bi);
        if di <= 2 || di >= n - 2 {
            let row = &cp[i * n..(i + 1) * n];
            second_raw = max_of(&row[from..from + head], max_of(&row[..tail], second_raw));
        } else if m > second_raw {
            second_raw = m;
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
    let width = peak_width(c(bi + n - 1, bj), best, c(bi + 1, bj)).max(peak_width(
        c(bi, bj + n - 1),
        best,
        c(bi, bj + 1),
    ));
    Ok((
        Peak {
            dx: wrap(bj) + sx,
            dy: wrap(bi) + sy,
            height: best,
            ratio,
            width,
            sigma: (0.0, 0.0),
        },
        (bi, bj),
    ))
}

/// The standard uncertainty (x, y), px, of the peak at lag `(bi, bj)` of
/// the raw correlation `cp` (times `norm` normalised) when the asymmetry
/// about it has standard deviation `sd` (x, y; normalised).
pub fn peak_uncertainty(
    n: usize,
    cp: &[f32],
    norm: f64,
    (bi, bj): (usize, usize),
    sd: (f64, f64),
) -> (f64, f64) {
    let c = |i: usize, j: usize| f64::from(cp[(i % n) * n + (j % n)]) * norm;
    let best = c(bi, bj);
    (
        uncertainty(c(bi, bj + n - 1), best, c(bi, bj + 1), sd.0),
        uncertainty(c(bi + n - 1, bj), best, c(bi + 1, bj), sd.1),
    )
}

/// The standard deviation of the correlation's asymmetry about the peak at
/// lag `p = (bi, bj)` along x and along y, from the pixels' own
/// contributions (Wieneke 2015, "PIV uncertainty quantification from
/// correlation statistics"): the pair of neighbouring pixels `x`, `x + e`
/// adds `a(x)·b(x + p + e)` to the correlation one step past the peak and
/// `a(x + e)·b(x + p)` one step before it. Where the two windows match
/// (after deformation: the same particles at the same places) the two are
/// equal; noise and unmatched particles make them differ, and the spread
/// of the differences `Δ(x)` over the window is how far they can tilt the
/// peak. Neighbouring pixels' differences are not independent (a particle
/// image spans several), so the variance sums `Δ(x)·Δ(x')` over each
/// pixel's 3 × 3 neighbourhood (never below the sum of squares). Raw
/// units: the caller normalises as it normalises the correlation. Lags are
/// cyclic, as the FFT's.
pub fn spread(
    s: &mut Scratch,
    n: usize,
    (bi, bj): (usize, usize),
    (ma, mb): (f32, f32),
) -> (f64, f64) {
    let m = n + 1;
    // A and B (B moved by the lag) zero-mean, one row and one column
    // longer, wrapped: the differences then read both windows in order,
    // with no index arithmetic per pixel.
    wrapped(&s.a, n, (0, 0), ma, &mut s.ae);
    wrapped(&s.b, n, (bi, bj), mb, &mut s.be);
    // Δx and Δy in a frame of zeros (one column each side, one row below),
    // so that every pixel's forward neighbourhood is in the buffer.
    let p = n + 2;
    s.dx[n * p..].fill(0.0);
    s.dy[n * p..].fill(0.0);
    for i in 0..n {
        let (a, a1) = (&s.ae[i * m..(i + 1) * m], &s.ae[(i + 1) * m..(i + 2) * m]);
        let (b, b1) = (&s.be[i * m..(i + 1) * m], &s.be[(i + 1) * m..(i + 2) * m]);
        let dx = &mut s.dx[i * p..(i + 1) * p];
        let dy = &mut s.dy[i * p..(i + 1) * p];
        (dx[0], dx[p - 1], dy[0], dy[p - 1]) = (0.0, 0.0, 0.0, 0.0);
        for j in 0..n {
            dx[j + 1] = a[j] * b[j + 1] - a[j + 1] * b[j];
            dy[j + 1] = a[j] * b1[j] - a1[j] * b[j];
        }
    }
    // A pair of pixels with a masked one adds nothing.
    let k = s.masked.len().min(n * n);
    if s.masked[..k].iter().any(|&x| x) {
        let masked = |i: usize, j: usize| s.masked.get((i % n) * n + (j % n)) == Some(&true);
        for i in 0..n {
            for j in 0..n {
                let here = masked(i, j);
                if here || masked(i, j + 1) {
                    s.dx[i * p + j + 1] = 0.0;
                }
                if here || masked(i + 1, j) {
                    s.dy[i * p + j + 1] = 0.0;
                }
            }
        }
    }
    (
        neighbourhood_variance(&s.dx, n).sqrt(),
        neighbourhood_variance(&s.dy, n).sqrt(),
    )
}

/// `w` (n×n, row-major) read from row `i0` and column `j0` on, cyclically,
/// minus `mean`, into `out` as (n+1)×(n+1): the extra row and column
/// repeat the first ones.
fn wrapped(w: &[f32], n: usize, (i0, j0): (usize, usize), mean: f32, out: &mut [f32]) {
    let m = n + 1;
    let (i0, j0) = (i0 % n, j0 % n);
    for i in 0..m {
        let (head, tail) = w[((i0 + i) % n) * n..][..n].split_at(j0);
        let dst = &mut out[i * m..(i + 1) * m];
        let (first, rest) = dst[..n].split_at_mut(tail.len());
        for (d, &v) in first.iter_mut().zip(tail) {
            *d = v - mean;
        }
        for (d, &v) in rest.iter_mut().zip(head) {
            *d = v - mean;
        }
        dst[n] = dst[0];
    }
}

/// Eight samples (`s` is 8 long; shorter or longer gives zeros) as lanes.
#[inline(always)]
fn eight(s: &[f32]) -> f32x8 {
    f32x8::new(s.try_into().unwrap_or([0.0; 8]))
}

/// Σ Δ(x)·Δ(x′) over each pixel and its 3 × 3 neighbourhood, never below
/// Σ Δ(x)²; `d` holds Δ as n+1 rows of n+2 with zeros around (see
/// [`spread`]). Each row sums in 8 independent f32 lanes (so that it
/// vectorises; relative error at most n/8·2⁻²⁴, 8e-6 for n = 1024), the
/// rows in f64.
fn neighbourhood_variance(d: &[f32], n: usize) -> f64 {
    let p = n + 2;
    let (mut own, mut near) = (0.0f64, 0.0f64);
    for i in 0..n {
        let (r, q) = (&d[i * p..(i + 1) * p], &d[(i + 1) * p..(i + 2) * p]);
        // Pixel j is r[j + 1]; its forward half-neighbourhood (each pair
        // counts twice) is r[j + 2], q[j], q[j + 1], q[j + 2]. Eight
        // pixels at a time in `wide` lanes: the compiler does not
        // vectorise this loop by itself.
        let (mut o, mut e) = (f32x8::ZERO, f32x8::ZERO);
        let lanes = |s: &[f32], k: usize| eight(&s[k..k + 8]);
        let mut j = 0;
        while j + 8 <= n {
            let v = lanes(r, j + 1);
            o += v * v;
            e += v * (((lanes(r, j + 2) + lanes(q, j)) + lanes(q, j + 1)) + lanes(q, j + 2));
            j += 8;
        }
        let (mut o, mut e) = (o.to_array(), e.to_array());
        for j in j..n {
            let v = r[j + 1];
            o[0] += v * v;
            e[0] += v * (r[j + 2] + q[j] + q[j + 1] + q[j + 2]);
        }
        own += o.iter().map(|&x| f64::from(x)).sum::<f64>();
        near += e.iter().map(|&x| f64::from(x)).sum::<f64>();
    }
    (own + 2.0 * near).max(own)
}

/// The standard uncertainty, px, of the 3-point Gaussian peak position
/// between `cm` (at −1), `c0` and `cp` (at +1) when the asymmetry `cp −
/// cm` has standard deviation `sd` (normalised as the correlation):
/// half the change of the estimate as the neighbours move by ±`sd`/2 in
/// opposite directions (Wieneke 2015). At most one pixel: beyond that
/// the peak itself is in question, which validation judges.
pub fn uncertainty(cm: f64, c0: f64, cp: f64, sd: f64) -> f64 {
    if !(sd.is_finite() && sd >= 0.0) {
        return 1.0;
    }
    let h = 0.5 * sd;
    let hi = subpixel(cm - h, c0, cp + h);
    let lo = subpixel(cm + h, c0, cp - h);
    (0.5 * (hi - lo).abs()).min(1.0)
}

/// conj(A)·B at one frequency from Z = FFT(a + i·b) there and W at −k.
#[inline(always)]
fn cross(z: Complex32, w: Complex32) -> Complex32 {
    Complex32::new(
        0.5 * (z.re * w.im + z.im * w.re),
        -0.25 * (z.norm_sqr() - w.norm_sqr()),
    )
}

/// The largest of `v` and `init` (NaN samples ignored; `init` must not be
/// NaN), in 8 independent lanes so that it vectorises, the lanes reduced
/// by the same comparison (no NaN can reach them), as a tree.
pub fn max_of(v: &[f32], init: f32) -> f32 {
    let larger = |m: f32, x: f32| if x > m { x } else { m };
    let mut acc = [init; 8];
    let mut chunks = v.chunks_exact(8);
    for ch in &mut chunks {
        for (a, &x) in acc.iter_mut().zip(ch) {
            *a = larger(*a, x);
        }
    }
    let tail = chunks.remainder().iter().fold(init, |m, &x| larger(m, x));
    let four: [f32; 4] = std::array::from_fn(|l| larger(acc[l], acc[l + 4]));
    let two = [larger(four[0], four[2]), larger(four[1], four[3])];
    larger(larger(two[0], two[1]), tail)
}

/// Σ f(v) over 16 independent f32 lanes (vectorises), the lanes added in
/// f64. Each lane sums 1/16 of a window, so the worst-case relative error
/// is n/16·2⁻²⁴: 1.5e-5 for a 64² window, 4e-3 for the largest (1024²).
/// It only scales the normalised height a little and leaves a residual
/// constant in the zero-mean window, which moves no peak.
fn sum_lanes(v: &[f32], f: impl Fn(f32) -> f32) -> f64 {
    let mut acc = [0.0f32; 16];
    let mut chunks = v.chunks_exact(16);
    for ch in &mut chunks {
        for (a, &x) in acc.iter_mut().zip(ch) {
            *a += f(x);
        }
    }
    let tail: f64 = chunks.remainder().iter().map(|&x| f64::from(f(x))).sum();
    acc.iter().map(|&a| f64::from(a)).sum::<f64>() + tail
}

/// The means of `a` and `b` over unmasked pixels, and how many there are;
/// masked pixels are set to the mean, so that after subtracting it they add
/// nothing. (A mask shorter than the window leaves the rest unmasked.)
fn means(a: &mut [f32], b: &mut [f32], masked: &[bool]) -> (f64, f64, usize) {
    let n = a.len().min(b.len());
    let k = masked.len().min(n);
    let masked = &masked[..k];
    if k > 0 {
        for ((x, y), &m) in a.iter_mut().zip(b.iter_mut()).zip(masked) {
            (*x, *y) = if m { (0.0, 0.0) } else { (*x, *y) };
        }
    }
    let cnt = n - masked.iter().filter(|&&m| m).count();
    if cnt == 0 {
        return (0.0, 0.0, 0);
    }
    let (ma, mb) = (
        sum_lanes(a, |v| v) / cnt as f64,
        sum_lanes(b, |v| v) / cnt as f64,
    );
    if k > 0 {
        let (fa, fb) = (ma as f32, mb as f32);
        for ((x, y), &m) in a.iter_mut().zip(b.iter_mut()).zip(masked) {
            (*x, *y) = if m { (fa, fb) } else { (*x, *y) };
        }
    }
    (ma, mb, cnt)
}

/// `z = (a − ma) + i·(b − mb)`, and the energies Σ(a − ma)², Σ(b − mb)² in
/// 8 f32 lanes each (one pass, vectorised).
fn fill_z(z: &mut [Complex32], a: &[f32], b: &[f32], ma: f32, mb: f32) -> (f64, f64) {
    let (mut ea, mut eb) = (f32x8::ZERO, f32x8::ZERO);
    let (mut ta, mut tb) = (0.0f64, 0.0f64);
    // In `wide` lanes, written out as interleaved f32 parts: the compiler
    // vectorises neither the sums nor the interleaving by itself here.
    let zf: &mut [f32] = bytemuck::cast_slice_mut(z);
    let mut zc = zf.chunks_exact_mut(16);
    let (mut ac, mut bc) = (a.chunks_exact(8), b.chunks_exact(8));
    let (sa, sb) = (f32x8::splat(ma), f32x8::splat(mb));
    for ((zs, xs), ys) in (&mut zc).zip(&mut ac).zip(&mut bc) {
        let (x, y) = (eight(xs) - sa, eight(ys) - sb);
        ea += x * x;
        eb += y * y;
        let (x, y) = (x.to_array(), y.to_array());
        for l in 0..8 {
            zs[2 * l] = x[l];
            zs[2 * l + 1] = y[l];
        }
    }
    for ((zv, &x), &y) in zc
        .into_remainder()
        .chunks_exact_mut(2)
        .zip(ac.remainder())
        .zip(bc.remainder())
    {
        let (x, y) = (x - ma, y - mb);
        (zv[0], zv[1]) = (x, y);
        ta += f64::from(x * x);
        tb += f64::from(y * y);
    }
    let sum = |e: f32x8| e.to_array().iter().map(|&v| f64::from(v)).sum::<f64>();
    (sum(ea) + ta, sum(eb) + tb)
}

fn transpose(src: &[Complex32], dst: &mut [Complex32], n: usize) {
    transpose::transpose(src, dst, n, n);
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

    /// Uniform numbers in [0, 1) from a 64-bit LCG seeded with `seed`.
    fn uniform(seed: u64) -> impl FnMut() -> f32 {
        let mut rng = seed;
        move || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (rng >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// The peak, its lag and the peak ratio against their definitions read
    /// off every sample: the first maximum in row-major order (NaNs
    /// ignored, ties kept at the first), the second the largest sample
    /// outside the cyclic 5×5 around it. Sizes on the stack and the heap
    /// path, peaks at the wrap, ties and NaNs.
    #[test]
    fn locate_finds_the_first_maximum_and_the_second_outside_its_neighbourhood() {
        let mut next = uniform(77);
        for (case, n) in [4usize, 5, 16, 32, 64, 65, 96, 128].into_iter().enumerate() {
            for trial in 0..12 {
                let mut cp: Vec<f32> = (0..n * n).map(|_| next() - 0.3).collect();
                let at = |r: f32| ((r * (n * n) as f32) as usize).min(n * n - 1);
                match trial % 4 {
                    // A tie: the same peak value twice.
                    1 => {
                        let (p, q) = (at(next()), at(next()));
                        (cp[p], cp[q]) = (2.0, 2.0);
                    }
                    // NaNs, one where the maximum would be.
                    2 => {
                        for _ in 0..n {
                            let p = at(next());
                            cp[p] = f32::NAN;
                        }
                    }
                    // A peak in the last row and column: its 5×5 wraps.
                    3 => cp[n * n - 1] = 3.0,
                    _ => {}
                }
                let norm = 0.5;
                let (p, (bi, bj)) = locate(n, &cp, norm, Subpixel::Gaussian).expect("peak");
                let (mut k, mut best) = (0, f32::NEG_INFINITY);
                for (q, &v) in cp.iter().enumerate() {
                    if v > best {
                        (k, best) = (q, v);
                    }
                }
                assert_eq!((bi, bj), (k / n, k % n), "n {n} case {case} trial {trial}");
                assert_eq!(p.height, f64::from(best) * norm);
                let d = |u: usize, v: usize| (u + n - v) % n;
                let near = |q: usize| {
                    let (di, dj) = (d(q / n, bi), d(q % n, bj));
                    (di <= 2 || di >= n - 2) && (dj <= 2 || dj >= n - 2)
                };
                let second = (0..n * n)
                    .filter(|&q| !near(q))
                    .map(|q| cp[q])
                    .fold(0.0f32, f32::max);
                let ratio = if second > 0.0 {
                    (f64::from(best) / f64::from(second)).min(1000.0)
                } else {
                    1000.0
                };
                assert_eq!(p.ratio, ratio, "n {n} trial {trial}");
            }
        }
    }

    /// The cyclic cross-correlation of the zero-mean `a` and `b` (n×n)
    /// summed directly, lag (dy, dx) at dy·n + dx, and the product of
    /// their norms (what normalises it).
    fn direct_correlation(a: &[f32], b: &[f32], n: usize) -> (Vec<f64>, f64) {
        let zm = |v: &[f32]| {
            let m = v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
            v.iter().map(|&x| f64::from(x) - m).collect::<Vec<f64>>()
        };
        let (a0, b0) = (zm(a), zm(b));
        let e = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        let mut c = vec![0.0; n * n];
        for dy in 0..n {
            for dx in 0..n {
                let mut acc = 0.0;
                for i in 0..n {
                    for j in 0..n {
                        acc += a0[i * n + j] * b0[((i + dy) % n) * n + (j + dx) % n];
                    }
                }
                c[dy * n + dx] = acc;
            }
        }
        (c, (e(&a0) * e(&b0)).sqrt())
    }

    /// The FFT path against the cyclic cross-correlation summed directly:
    /// same integer peak, same normalised height and peak ratio.
    #[test]
    fn matches_the_direct_cyclic_correlation() {
        let n = 16;
        let plan = Plan::new(n);
        let mut s = Scratch::new(&plan);
        let mut next = uniform(12345);
        let a: Vec<f32> = (0..n * n).map(|_| 100.0 * next()).collect();
        // B: A moved by (dx 3, dy −2) cyclically, plus noise.
        let b: Vec<f32> = (0..n * n)
            .map(|k| {
                let (i, j) = (k / n, k % n);
                a[((i + 2) % n) * n + (j + n - 3) % n] + 30.0 * next()
            })
            .collect();
        s.a.copy_from_slice(&a);
        s.b.copy_from_slice(&b);
        let p = correlate(&plan, &mut s, Subpixel::Parabolic).expect("peak");
        let (raw, norm) = direct_correlation(&a, &b, n);
        let c: Vec<f64> = raw.iter().map(|&v| v / norm).collect();
        let (k, &best) = c
            .iter()
            .enumerate()
            .max_by(|x, y| x.1.total_cmp(y.1))
            .expect("max");
        assert_eq!((k / n, k % n), (n - 2, 3));
        assert!((p.height - best).abs() < 1e-5, "{} vs {best}", p.height);
        assert_eq!((p.dx.round(), p.dy.round()), (3.0, -2.0));
        let second = (0..n * n)
            .filter(|&q| {
                let d = |u: usize, v: usize| (u + n - v) % n;
                let (di, dj) = (d(q / n, k / n), d(q % n, k % n));
                !((di <= 2 || di >= n - 2) && (dj <= 2 || dj >= n - 2))
            })
            .map(|q| c[q])
            .fold(0.0f64, f64::max);
        assert!(
            (p.ratio - best / second).abs() < 1e-3 * p.ratio,
            "{} vs {}",
            p.ratio,
            best / second
        );
    }

    /// Every sample of the raw plane against the cyclic correlation of the
    /// zero-mean windows summed directly, for even and odd sides (an odd
    /// side leaves the last row of the inverse without a partner).
    #[test]
    fn the_whole_plane_matches_the_direct_sum() {
        let mut next = uniform(4242);
        for n in [4usize, 15, 16, 33] {
            let plan = Plan::new(n);
            let mut s = Scratch::new(&plan);
            let a: Vec<f32> = (0..n * n).map(|_| 50.0 * next()).collect();
            let b: Vec<f32> = (0..n * n).map(|_| 50.0 * next()).collect();
            s.a.copy_from_slice(&a);
            s.b.copy_from_slice(&b);
            plane(&plan, &mut s).expect("signal");
            let (direct, scale) = direct_correlation(&a, &b, n);
            let mut worst = 0.0f64;
            for (&fft, &acc) in s.plane().iter().zip(&direct) {
                // The FFT's plane carries a factor n².
                let fft = f64::from(fft) / (n * n) as f64;
                worst = worst.max((fft - acc).abs() / scale);
            }
            assert!(worst < 1e-5, "n {n}: worst {worst}");
        }
    }

    /// Wieneke's spread summed pixel by pixel with cyclic indices, as its
    /// doc comment defines it.
    fn spread_direct(
        s: &Scratch,
        n: usize,
        (bi, bj): (usize, usize),
        (ma, mb): (f32, f32),
    ) -> (f64, f64) {
        let a0 = |i: usize, j: usize| s.a[(i % n) * n + (j % n)] - ma;
        let b0 = |i: usize, j: usize| s.b[(i % n) * n + (j % n)] - mb;
        let masked = |i: usize, j: usize| s.masked.get((i % n) * n + (j % n)) == Some(&true);
        let (mut dx, mut dy) = (vec![0f32; n * n], vec![0f32; n * n]);
        for i in 0..n {
            for j in 0..n {
                let (pi, pj) = (i + bi, j + bj);
                if !masked(i, j) && !masked(i, j + 1) {
                    dx[i * n + j] = a0(i, j) * b0(pi, pj + 1) - a0(i, j + 1) * b0(pi, pj);
                }
                if !masked(i, j) && !masked(i + 1, j) {
                    dy[i * n + j] = a0(i, j) * b0(pi + 1, pj) - a0(i + 1, j) * b0(pi, pj);
                }
            }
        }
        let var = |d: &[f32]| {
            let (mut own, mut near) = (0.0f64, 0.0f64);
            for i in 0..n as isize {
                for j in 0..n as isize {
                    let v = f64::from(d[(i * n as isize + j) as usize]);
                    own += v * v;
                    for (di, dj) in [(0, 1), (1, -1), (1, 0), (1, 1)] {
                        let (k, l) = (i + di, j + dj);
                        if k < n as isize && (0..n as isize).contains(&l) {
                            near += 2.0 * v * f64::from(d[(k * n as isize + l) as usize]);
                        }
                    }
                }
            }
            (own + near).max(own)
        };
        (var(&dx).sqrt(), var(&dy).sqrt())
    }

    /// The row-wise spread equals the direct sum at lags inside and across
    /// the wrap, on odd and even sizes, with and without a mask.
    #[test]
    fn spread_matches_the_direct_sum() {
        let mut next = uniform(99);
        for n in [8usize, 13, 32] {
            let plan = Plan::new(n);
            let mut s = Scratch::new(&plan);
            for mask in [false, true] {
                for (k, v) in s.a.iter_mut().enumerate() {
                    *v = 200.0 * next() + (k % 7) as f32;
                }
                for v in s.b.iter_mut() {
                    *v = 200.0 * next();
                }
                s.masked = if mask {
                    (0..n * n).map(|_| next() < 0.2).collect()
                } else {
                    Vec::new()
                };
                for lag in [(0, 0), (1, n - 1), (n - 1, 3), (n / 2, n / 2)] {
                    let means = (90.0, 110.5);
                    let want = spread_direct(&s, n, lag, means);
                    let got = spread(&mut s, n, lag, means);
                    for (g, w) in [(got.0, want.0), (got.1, want.1)] {
                        assert!(
                            w > 0.0 && (g - w).abs() <= 1e-5 * w,
                            "n {n} mask {mask} lag {lag:?}: {g} vs {w}"
                        );
                    }
                }
            }
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
}
