//! Dense refinement below the window size: a variational optical
//! flow for particle images — Horn & Schunck's brightness constancy and
//! smoothness, solved coarse to fine on an image pyramid with symmetric
//! warping (the flow is referenced to the pair's midpoint, as PIV and the
//! ground truth are) and a median filter of the flow after each warp (Sun,
//! Roth & Black 2010), and in the pyramid mode a soft penalty on the
//! flow's divergence (the first-order div-curl regulariser of Suter 1994,
//! the family Corpetti et al. 2006 extend: particles follow an
//! incompressible flow). It outputs one displacement per pixel, px per pair,
//! `u` right and `v` down, and may start from a PIV field.
//! [`dense_frames`] fits one steady flow to a run of frames instead of a
//! pair, px per frame step.
//!
//! Hand-written: no crate solves this for `ndarray` images; every loop is
//! a stencil over the image, parallel over rows (rayon).

use ndarray::{Array2, Zip};
use rayon::prelude::*;

/// Settings of the dense stage.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DenseSettings {
    /// Smoothness weight α on normalised images (unit variance); larger is
    /// smoother.
    pub alpha: f32,
    /// Pyramid levels below full resolution (each halves the image; the
    /// coarsest keeps at least 16 px per side).
    pub levels: usize,
    /// Warps (re-linearisations) per level.
    pub warps: usize,
    /// Relaxation sweeps per warp.
    pub iterations: usize,
    /// Side of the median filter of the flow after each warp, px (0: off).
    pub median: usize,
    /// The pyramid level an initial field enters at (0: full resolution):
    /// coarser levels are skipped, since the field already holds the large
    /// scales.
    pub init_level: usize,
    /// Weight of a divergence penalty λ·(∇·w)² (0: off), for flows known
    /// to be divergence-free in the plane.
    #[serde(default)]
    pub div_weight: f32,
}

impl Default for DenseSettings {
    fn default() -> Self {
        DenseSettings {
            alpha: 0.5,
            levels: 5,
            warps: 4,
            iterations: 60,
            median: 5,
            init_level: 1,
            div_weight: 0.0,
        }
    }
}

/// A dense field: `u` and `v` per pixel, px per pair.
#[derive(Debug, Clone, PartialEq)]
pub struct Flow {
    /// Displacement right.
    pub u: Array2<f32>,
    /// Displacement down.
    pub v: Array2<f32>,
}

/// The image at zero mean and unit variance (a flat image stays zero).
fn normalise(a: &Array2<f32>) -> Array2<f32> {
    let n = a.len().max(1) as f64;
    let mean = a.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    let var = a
        .iter()
        .map(|&x| (f64::from(x) - mean).powi(2))
        .sum::<f64>()
        / n;
    let s = if var > 1e-12 { 1.0 / var.sqrt() } else { 0.0 };
    a.mapv(|x| ((f64::from(x) - mean) * s) as f32)
}

/// Blurs with the binomial kernel [1 4 6 4 1]/16 along both axes
/// (edges clamped), then keeps every second pixel.
fn down(a: &Array2<f32>) -> Array2<f32> {
    let (h, w) = a.dim();
    const K: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    let mut t = Array2::<f32>::zeros((h, w.div_ceil(2)));
    t.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(i, mut row)| {
            for (j2, o) in row.iter_mut().enumerate() {
                let j = 2 * j2 as isize;
                *o = (0..5)
                    .map(|k| K[k] * a[[i, clamp(j + k as isize - 2, w)]])
                    .sum();
            }
        });
    let mut out = Array2::<f32>::zeros((h.div_ceil(2), w.div_ceil(2)));
    out.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(i2, mut row)| {
            let i = 2 * i2 as isize;
            for (j, o) in row.iter_mut().enumerate() {
                *o = (0..5)
                    .map(|k| K[k] * t[[clamp(i + k as isize - 2, h), j]])
                    .sum();
            }
        });
    out
}

/// Bilinear sample of `a` at (row `y`, column `x`), edges clamped.
#[inline]
pub fn sample(a: &Array2<f32>, y: f32, x: f32) -> f32 {
    let (h, w) = a.dim();
    let y = y.clamp(0.0, (h - 1) as f32);
    let x = x.clamp(0.0, (w - 1) as f32);
    let (i, j) = (y.floor() as usize, x.floor() as usize);
    let (i1, j1) = ((i + 1).min(h - 1), (j + 1).min(w - 1));
    let (fy, fx) = (y - i as f32, x - j as f32);
    let top = a[[i, j]] + fx * (a[[i, j1]] - a[[i, j]]);
    let bot = a[[i1, j]] + fx * (a[[i1, j1]] - a[[i1, j]]);
    top + fy * (bot - top)
}

/// The flow of a level upsampled to `(h, w)`, twice as long.
fn up(f: &Flow, h: usize, w: usize) -> Flow {
    let (hc, wc) = f.u.dim();
    let map = |a: &Array2<f32>| {
        Array2::from_shape_fn((h, w), |(i, j)| {
            let y = ((i as f32 + 0.5) * hc as f32 / h as f32 - 0.5).max(0.0);
            let x = ((j as f32 + 0.5) * wc as f32 / w as f32 - 0.5).max(0.0);
            2.0 * sample(a, y, x)
        })
    };
    Flow {
        u: map(&f.u),
        v: map(&f.v),
    }
}

/// Central differences (one-sided at the edges): (d/dx, d/dy), per px.
pub fn gradients(a: &Array2<f32>) -> (Array2<f32>, Array2<f32>) {
    let (h, w) = a.dim();
    let gx = Array2::from_shape_fn((h, w), |(i, j)| {
        let (l, r) = (j.saturating_sub(1), (j + 1).min(w - 1));
        (a[[i, r]] - a[[i, l]]) / (r - l).max(1) as f32
    });
    let gy = Array2::from_shape_fn((h, w), |(i, j)| {
        let (t, b) = (i.saturating_sub(1), (i + 1).min(h - 1));
        (a[[b, j]] - a[[t, j]]) / (b - t).max(1) as f32
    });
    (gx, gy)
}

/// The median of each `n × n` neighbourhood (clamped at the edges).
fn median(a: &Array2<f32>, n: usize) -> Array2<f32> {
    if n < 2 {
        return a.clone();
    }
    let (h, w) = a.dim();
    let r = (n / 2) as isize;
    let mut out = Array2::<f32>::zeros((h, w));
    out.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(i, mut row)| {
            let mut buf = Vec::with_capacity(n * n);
            for (j, o) in row.iter_mut().enumerate() {
                buf.clear();
                for di in -r..=r {
                    let ii = (i as isize + di).clamp(0, h as isize - 1) as usize;
                    for dj in -r..=r {
                        let jj = (j as isize + dj).clamp(0, w as isize - 1) as usize;
                        buf.push(a[[ii, jj]]);
                    }
                }
                let m = buf.len() / 2;
                buf.select_nth_unstable_by(m, f32::total_cmp);
                *o = buf[m];
            }
        });
    out
}

/// One level: `warps` re-linearisations around the current flow, each
/// solved by `iterations` Jacobi sweeps of the Horn–Schunck equations.
fn level(a: &Array2<f32>, b: &Array2<f32>, f: &mut Flow, s: &DenseSettings) {
    let (h, w) = a.dim();
    let (ax, ay) = gradients(a);
    let (bx, by) = gradients(b);
    let a2 = s.alpha * s.alpha;
    for _ in 0..s.warps {
        // Symmetric warp: a at x − w/2, b at x + w/2.
        let mut ix = Array2::<f32>::zeros((h, w));
        let mut iy = Array2::<f32>::zeros((h, w));
        let mut it = Array2::<f32>::zeros((h, w));
        Zip::indexed(&mut ix)
            .and(&mut iy)
            .and(&mut it)
            .and(&f.u)
            .and(&f.v)
            .par_for_each(|(i, j), gx, gy, gt, &u, &v| {
                let (y, x) = (i as f32, j as f32);
                let (ya, xa, yb, xb) = (y - v / 2.0, x - u / 2.0, y + v / 2.0, x + u / 2.0);
                *gx = 0.5 * (sample(&ax, ya, xa) + sample(&bx, yb, xb));
                *gy = 0.5 * (sample(&ay, ya, xa) + sample(&by, yb, xb));
                *gt = sample(b, yb, xb) - sample(a, ya, xa);
            });
        let (u0, v0) = (f.u.clone(), f.v.clone());
        let lam = s.div_weight;
        if lam > 0.0 {
            let data = Data::of_pair((&ix, &iy, &it), (&u0, &v0));
            relax(f, &data, a2, lam, s.iterations);
        }
        let plain = if lam > 0.0 { 0 } else { s.iterations };
        for _ in 0..plain {
            let (ub, vb) = (neighbour_mean(&f.u), neighbour_mean(&f.v));
            Zip::indexed(&mut f.u)
                .and(&mut f.v)
                .and(&ub)
                .and(&vb)
                .par_for_each(|(i, j), u, v, &ub, &vb| {
                    let (gx, gy, gt) = (ix[[i, j]], iy[[i, j]], it[[i, j]]);
                    // Linearised constancy: gx·(u − u0) + gy·(v − v0) + gt = 0.
                    let r = gx * (ub - u0[[i, j]]) + gy * (vb - v0[[i, j]]) + gt;
                    let d = r / (a2 + gx * gx + gy * gy);
                    *u = ub - gx * d;
                    *v = vb - gy * d;
                });
        }
        if s.median > 1 {
            f.u = median(&f.u, s.median);
            f.v = median(&f.v, s.median);
        }
    }
}

/// The linearised data term per pixel: the normal equations
/// `J·w = −b` of brightness constancy around the flow of the warp, as
/// the 2×2 tensor `J` (`j11`, `j12`, `j22`) and the vector `b`.
struct Data {
    j11: Array2<f32>,
    j12: Array2<f32>,
    j22: Array2<f32>,
    b1: Array2<f32>,
    b2: Array2<f32>,
}

impl Data {
    /// One pair's term: gradient `g = (ix, iy)`, temporal difference `it`
    /// at the flow `(u0, v0)`: `J = g gᵀ`, `b = g·(it − g·w0)`.
    fn of_pair(
        (ix, iy, it): (&Array2<f32>, &Array2<f32>, &Array2<f32>),
        (u0, v0): (&Array2<f32>, &Array2<f32>),
    ) -> Data {
        let (h, w) = ix.dim();
        Data::from_fn(h, w, |i, j| {
            let (gx, gy) = (ix[[i, j]], iy[[i, j]]);
            let c = it[[i, j]] - gx * u0[[i, j]] - gy * v0[[i, j]];
            [gx * gx, gx * gy, gy * gy, gx * c, gy * c]
        })
    }

    /// The term whose pixel `(i, j)` is `f(i, j)` = `[j11, j12, j22, b1,
    /// b2]`, rows in parallel.
    fn from_fn(h: usize, w: usize, f: impl Fn(usize, usize) -> [f32; 5] + Sync) -> Data {
        let z = || Array2::<f32>::zeros((h, w));
        let mut d = Data {
            j11: z(),
            j12: z(),
            j22: z(),
            b1: z(),
            b2: z(),
        };
        Zip::indexed(&mut d.j11)
            .and(&mut d.j12)
            .and(&mut d.j22)
            .and(&mut d.b1)
            .and(&mut d.b2)
            .par_for_each(|(i, j), j11, j12, j22, b1, b2| {
                [*j11, *j12, *j22, *b1, *b2] = f(i, j);
            });
        d
    }
}

/// `sweeps` Jacobi sweeps of the data term `data` with smoothness `a2`
/// (α²) and the divergence penalty `lam`, from `f`.
fn relax(f: &mut Flow, data: &Data, a2: f32, lam: f32, sweeps: usize) {
    let (mut nu, mut nv) = (f.u.clone(), f.v.clone());
    for _ in 0..sweeps {
        div_sweep((&f.u, &f.v), (&mut nu, &mut nv), data, a2, lam);
        std::mem::swap(&mut f.u, &mut nu);
        std::mem::swap(&mut f.v, &mut nv);
    }
}

/// One Jacobi sweep with the divergence penalty: per pixel the 2×2 system
/// (J + (α² + 2λ)·I)·w = α²·w̄ + λ·(2·w̄ₐₓᵢₛ + cross) − b, where J and b
/// are the data term ([`Data`]), w̄ is Horn & Schunck's neighbour mean,
/// w̄ₐₓᵢₛ the mean of the two neighbours along u's (v's) axis and cross
/// the mixed derivative of the other component (the grad-div term). Reads
/// `u`, `v`, writes `nu`, `nv`; one pass over the stencil per row (rows in
/// parallel).
fn div_sweep(
    (u, v): (&Array2<f32>, &Array2<f32>),
    (nu, nv): (&mut Array2<f32>, &mut Array2<f32>),
    data: &Data,
    a2: f32,
    lam: f32,
) {
    let (h, w) = u.dim();
    let d = a2 + 2.0 * lam;
    nu.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .zip(nv.axis_iter_mut(ndarray::Axis(0)).into_par_iter())
        .enumerate()
        .for_each(|(i, (mut ru, mut rv))| {
            let (t, b) = (i.saturating_sub(1), (i + 1).min(h - 1));
            let (ut, um, ubot) = (u.row(t), u.row(i), u.row(b));
            let (vt, vm, vbot) = (v.row(t), v.row(i), v.row(b));
            let (j11, j12, j22) = (data.j11.row(i), data.j12.row(i), data.j22.row(i));
            let (d1, d2) = (data.b1.row(i), data.b2.row(i));
            for j in 0..w {
                let (l, r) = (j.saturating_sub(1), (j + 1).min(w - 1));
                let mean = |top: &ndarray::ArrayView1<f32>,
                            mid: &ndarray::ArrayView1<f32>,
                            bot: &ndarray::ArrayView1<f32>| {
                    (top[j] + bot[j] + mid[l] + mid[r]) / 6.0
                        + (top[l] + top[r] + bot[l] + bot[r]) / 12.0
                };
                let (ub, vb) = (mean(&ut, &um, &ubot), mean(&vt, &vm, &vbot));
                let ux = 0.5 * (um[l] + um[r]);
                let vy = 0.5 * (vt[j] + vbot[j]);
                let vxy = 0.25 * (vbot[r] - vbot[l] - vt[r] + vt[l]);
                let uxy = 0.25 * (ubot[r] - ubot[l] - ut[r] + ut[l]);
                let (a11, a12, a22) = (j11[j] + d, j12[j], j22[j] + d);
                let b1 = a2 * ub + lam * (2.0 * ux + vxy) - d1[j];
                let b2 = a2 * vb + lam * (2.0 * vy + uxy) - d2[j];
                // det ≥ d² > 0: the system is positive definite.
                let det = a11 * a22 - a12 * a12;
                ru[j] = (a22 * b1 - a12 * b2) / det;
                rv[j] = (a11 * b2 - a12 * b1) / det;
            }
        });
}

/// Horn & Schunck's neighbour mean: edge neighbours weigh 1/6, corners
/// 1/12; edges clamped.
fn neighbour_mean(a: &Array2<f32>) -> Array2<f32> {
    let (h, w) = a.dim();
    let mut out = Array2::<f32>::zeros((h, w));
    out.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(i, mut row)| {
            let (t, b) = (i.saturating_sub(1), (i + 1).min(h - 1));
            for (j, o) in row.iter_mut().enumerate() {
                let (l, r) = (j.saturating_sub(1), (j + 1).min(w - 1));
                let edge = a[[t, j]] + a[[b, j]] + a[[i, l]] + a[[i, r]];
                let corner = a[[t, l]] + a[[t, r]] + a[[b, l]] + a[[b, r]];
                *o = edge / 6.0 + corner / 12.0;
            }
        });
    out
}

/// A full-resolution field at pyramid level `top` (size `(th, tw)`),
/// lengths scaled down with it.
fn scaled_down(i: &Flow, top: usize, (th, tw): (usize, usize)) -> Flow {
    let k = (1usize << top) as f32;
    let map = |a: &Array2<f32>| {
        Array2::from_shape_fn((th, tw), |(r, c)| {
            sample(a, (r as f32 + 0.5) * k - 0.5, (c as f32 + 0.5) * k - 0.5) / k
        })
    };
    Flow {
        u: map(&i.u),
        v: map(&i.v),
    }
}

/// Where a pyramid `levels` (full resolution first, at least one level)
/// is entered and with what flow: `init` (full resolution) scaled down to
/// level `init_level`, or rest at the coarsest level when there is no
/// `init` of that size.
fn start(init: Option<&Flow>, init_level: usize, levels: &[Array2<f32>]) -> (usize, Flow) {
    let coarsest = levels.len().saturating_sub(1);
    let full = levels[0].dim();
    let init = init.filter(|i| i.u.dim() == full && i.v.dim() == full);
    let top = match init {
        Some(_) => init_level.min(coarsest),
        None => coarsest,
    };
    let (th, tw) = levels[top].dim();
    let f = match init {
        Some(i) => scaled_down(i, top, (th, tw)),
        None => Flow {
            u: Array2::zeros((th, tw)),
            v: Array2::zeros((th, tw)),
        },
    };
    (top, f)
}

/// The dense flow from `a` to `b` (same size), starting from `init` (a
/// dense field, e.g. a PIV field interpolated to every pixel) or from rest.
pub fn dense_flow(
    a: &Array2<f32>,
    b: &Array2<f32>,
    init: Option<&Flow>,
    s: &DenseSettings,
) -> Flow {
    let mut pa = vec![normalise(a)];
    let mut pb = vec![normalise(b)];
    for _ in 0..s.levels {
        let (lh, lw) = pa[pa.len() - 1].dim();
        if lh < 32 || lw < 32 {
            break;
        }
        let (da, db) = rayon::join(|| down(&pa[pa.len() - 1]), || down(&pb[pb.len() - 1]));
        pa.push(da);
        pb.push(db);
    }
    let (top, mut f) = start(init, s.init_level, &pa);
    for l in (0..=top).rev() {
        level(&pa[l], &pb[l], &mut f, s);
        if l > 0 {
            let (nh, nw) = pa[l - 1].dim();
            f = up(&f, nh, nw);
        }
    }
    f
}

/// The steps of [`dense_frames`]'s data term: which pairs of frames it
/// compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Steps<'a> {
    /// Steps `k` whose pairs `(i, i + k)` enter at every level.
    pub every: &'a [usize],
    /// Steps that enter at full resolution only, where the flow is close
    /// enough for their longer paths.
    pub fine: &'a [usize],
}

/// The flow per frame step of `frames` (consecutive, equally spaced in
/// time, same size) from rest: one steady flow `w` whose data term sums,
/// over every pair `(i, i + k)` of `steps`, brightness constancy between
/// frame `i` where a particle at `x` is `k/2` steps earlier and frame
/// `i + k` where it is `k/2` steps later, along the paths of the current
/// flow (midpoint steps of a quarter step); a pair whose path leaves the
/// image adds nothing there. Coarse to fine on the pyramid
/// of [`dense_flow`], with its regularisers. A multi-frame
/// generalisation of the symmetric warp: every frame pair is another look
/// at the same flow, and a pair `k` steps apart measures it `k` times as
/// finely.
pub fn dense_frames(frames: &[Array2<f32>], steps: Steps<'_>, s: &DenseSettings) -> Flow {
    dense_frames_from(frames, None, steps, s)
}

/// [`dense_frames`] started from `init` (per frame step, full
/// resolution) at pyramid level [`DenseSettings::init_level`], or from rest
/// at the coarsest level.
pub fn dense_frames_from(
    frames: &[Array2<f32>],
    init: Option<&Flow>,
    steps: Steps<'_>,
    s: &DenseSettings,
) -> Flow {
    let Some(first) = frames.first() else {
        return Flow {
            u: Array2::zeros((0, 0)),
            v: Array2::zeros((0, 0)),
        };
    };
    let (h, w) = first.dim();
    if frames.iter().any(|f| f.dim() != (h, w)) || h == 0 || w == 0 {
        return Flow {
            u: Array2::zeros((h, w)),
            v: Array2::zeros((h, w)),
        };
    }
    let mut pyr: Vec<Vec<Array2<f32>>> = frames.par_iter().map(|f| vec![normalise(f)]).collect();
    for _ in 0..s.levels {
        let (lh, lw) = pyr[0][pyr[0].len() - 1].dim();
        if lh < 32 || lw < 32 {
            break;
        }
        pyr.par_iter_mut().for_each(|p| {
            let d = down(&p[p.len() - 1]);
            p.push(d);
        });
    }
    let (top, mut f) = start(init, s.init_level, &pyr[0]);
    let pairs = |ks: &[usize]| -> Vec<(usize, usize)> {
        ks.iter()
            .filter(|&&k| (1..=MAX_STEP).contains(&k))
            .flat_map(|&k| (0..frames.len().saturating_sub(k)).map(move |i| (i, k)))
            .collect()
    };
    let coarse = pairs(steps.every);
    let mut finest = coarse.clone();
    finest.extend(pairs(steps.fine));
    for l in (0..=top).rev() {
        let level_frames: Vec<&Array2<f32>> = pyr.iter().map(|p| &p[l]).collect();
        let terms = if l == 0 { &finest } else { &coarse };
        level_frames_warps(&level_frames, terms, &mut f, s);
        if l > 0 {
            let (nh, nw) = pyr[0][l - 1].dim();
            f = up(&f, nh, nw);
        }
    }
    f
}

/// The longest step [`dense_frames`] compares.
pub const MAX_STEP: usize = 8;

/// One level of [`dense_frames`]: `warps` re-linearisations of the summed
/// data term of `terms` (frame index, step) around the current flow, each
/// relaxed and median-filtered as [`level`] does.
fn level_frames_warps(
    frames: &[&Array2<f32>],
    terms: &[(usize, usize)],
    f: &mut Flow,
    s: &DenseSettings,
) {
    let (h, w) = frames[0].dim();
    let grads: Vec<(Array2<f32>, Array2<f32>)> = frames.par_iter().map(|a| gradients(a)).collect();
    // Some smoothness always: with α = λ = 0 a pixel without texture
    // would have no equation.
    let a2 = (s.alpha * s.alpha).max(1e-6);
    let n = terms.len().max(1) as f32;
    let kmax = terms.iter().map(|t| t.1).max().unwrap_or(0);
    let (xmax, ymax) = ((w - 1) as f32, (h - 1) as f32);
    for _ in 0..s.warps {
        let (u0, v0) = (&f.u, &f.v);
        let data = Data::from_fn(h, w, |i, j| {
            let (x, y) = (j as f32, i as f32);
            let (u, v) = (u0[[i, j]], v0[[i, j]]);
            // Where the particle at (x, y) is k/2 steps later (fwd[k])
            // and earlier (bwd[k]).
            let mut fwd = [(x, y); MAX_STEP + 1];
            let mut bwd = [(x, y); MAX_STEP + 1];
            for (dir, out) in [(0.25f32, &mut fwd), (-0.25, &mut bwd)] {
                let (mut px, mut py) = (x, y);
                for slot in out.iter_mut().take(kmax + 1).skip(1) {
                    for _ in 0..2 {
                        let (a1, c1) = (sample(u0, py, px), sample(v0, py, px));
                        let (mx, my) = (px + 0.5 * dir * a1, py + 0.5 * dir * c1);
                        px += dir * sample(u0, my, mx);
                        py += dir * sample(v0, my, mx);
                    }
                    *slot = (px, py);
                }
            }
            let (mut s11, mut s12, mut s22, mut t1, mut t2) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for &(a, k) in terms {
                let b = a + k;
                let ((xa, ya), (xb, yb)) = (bwd[k], fwd[k]);
                // A particle whose path leaves the image has nothing
                // to compare (clamped samples would pull the flow to
                // the edge's).
                if [xa, xb].iter().any(|&q| q < 0.0 || q > xmax)
                    || [ya, yb].iter().any(|&q| q < 0.0 || q > ymax)
                {
                    continue;
                }
                // d(path end)/dw ≈ ±k/2 per component: the data term's
                // gradient in w is k times the mean image gradient.
                let kf = k as f32;
                let gx = 0.5 * kf * (sample(&grads[a].0, ya, xa) + sample(&grads[b].0, yb, xb));
                let gy = 0.5 * kf * (sample(&grads[a].1, ya, xa) + sample(&grads[b].1, yb, xb));
                let gt = sample(frames[b], yb, xb) - sample(frames[a], ya, xa);
                let c = gt - gx * u - gy * v;
                s11 += gx * gx;
                s12 += gx * gy;
                s22 += gy * gy;
                t1 += gx * c;
                t2 += gy * c;
            }
            [s11 / n, s12 / n, s22 / n, t1 / n, t2 / n]
        });
        relax(f, &data, a2, s.div_weight, s.iterations);
        if s.median > 1 {
            f.u = median(&f.u, s.median);
            f.v = median(&f.v, s.median);
        }
    }
}

/// How [`for_piv`] ran the dense stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DenseMode {
    /// PIV measured the field (at least half its vectors valid): refined
    /// from it at full resolution with strong smoothness (α = 1), which
    /// keeps PIV's precision and adds the scales below the window.
    Refine,
    /// PIV did not (eddies below the window, displacements beyond it): the
    /// whole pyramid from rest with weak smoothness (α = 0.2).
    Pyramid,
}

impl DenseMode {
    /// The settings of this mode.
    pub fn settings(self) -> DenseSettings {
        match self {
            DenseMode::Refine => DenseSettings {
                alpha: 1.0,
                init_level: 0,
                ..DenseSettings::default()
            },
            // 10 warps: turbulence EPE 1.94 px (6: 2.45, 16: 2.00). The
            // divergence penalty λ = 0.05 (`examples/dense_probe.rs`,
            // EPE from rest, λ 0 → 0.05 → 0.1): turbulence 1.94 → 1.40 →
            // 1.30, its spike TFP frames 2.71 → 1.84 → 1.98, large-shift
            // 4.25 → 3.83 → 4.13, vortex 0.264 → 0.181 → 0.166, uniform
            // 0.283 → 0.197 → 0.195; about 1.6× the time. Refining from
            // PIV it gained 4 % at twice the time: off there.
            DenseMode::Pyramid => DenseSettings {
                alpha: 0.2,
                warps: 10,
                div_weight: 0.05,
                ..DenseSettings::default()
            },
        }
    }
}

/// The mode a PIV field calls for: [`DenseMode::Refine`] when at least half
/// its vectors are valid.
pub fn mode_for(field: &super::Field) -> DenseMode {
    let (valid, _, _) = field.counts();
    if 2 * valid >= field.grid.len().max(1) {
        DenseMode::Refine
    } else {
        DenseMode::Pyramid
    }
}

/// The dense stage after PIV: the mode [`mode_for`] picks, from the PIV
/// field interpolated to every pixel or from rest.
pub fn for_piv(a: &Array2<f32>, b: &Array2<f32>, field: &super::Field) -> (Flow, DenseMode) {
    let mode = mode_for(field);
    let (h, w) = a.dim();
    let init = (mode == DenseMode::Refine).then(|| {
        let (u, v) = field.predictor(h, w);
        Flow { u, v }
    });
    (dense_flow(a, b, init.as_ref(), &mode.settings()), mode)
}

impl Flow {
    /// The flow as a file's field (row-major, upright).
    pub fn to_field(&self) -> spiv_formats::dense::DenseField {
        let (h, w) = self.u.dim();
        spiv_formats::dense::DenseField {
            width: w,
            height: h,
            u: self.u.iter().copied().collect(),
            v: self.v.iter().copied().collect(),
        }
    }

    /// The flow at pixel `(x, y)` (docs/formats.md coordinates: pixel centres on
    /// integers), bilinear.
    pub fn at(&self, x: f64, y: f64) -> (f64, f64) {
        (
            f64::from(sample(&self.u, y as f32, x as f32)),
            f64::from(sample(&self.v, y as f32, x as f32)),
        )
    }
}

/// Reports `flow` at the grid of a `field` whose last pass failed as a
/// whole: every window with a correlation peak gets the dense vector at its
/// centre, flagged replaced (measured, not by correlation); windows without
/// signal or masked stay invalid.
pub fn fill(field: &mut super::Field, flow: &Flow) {
    for r in 0..field.grid.ny {
        for c in 0..field.grid.nx {
            if field.peak_height[[r, c]] == 0.0 {
                continue;
            }
            let (x, y) = field.grid.centre(r, c);
            let (u, v) = flow.at(x, y);
            field.u[[r, c]] = u;
            field.v[[r, c]] = v;
            field.state[[r, c]] = super::State::Replaced;
            // The dense stage has no correlation statistics: unknown.
            field.sigma[[r, c]] = super::NO_SIGMA;
        }
    }
}
