//! The joint fit: one steady flow fitted to every short frame around a
//! pair at once, along its own paths.
//!
//! The span within [`JointSettings::reach`] ticks of the midpoint is cut
//! into consecutive, disjoint [`FRAME`]-tick uncompensated frames (the
//! frames the core's warp makes with a still flow, as the ensemble's).
//! Each frame, band-passed (blurred by a Gaussian of [`Level::blur`] px,
//! less its blur by [`JointSettings::highpass`] px: light that stays put
//! over the span would align at any flow and pull the fit towards rest),
//! is carried to the midpoint along the flow's paths: the value at pixel `x`
//! of frame `k`, centred `τ_k` ticks before the midpoint, is the frame
//! sampled where the particle now at `x` was then. The fit maximises the
//! sum over every pair of frames of their products so carried — the
//! contrast of the frames' sum less each frame's own, so that no frame
//! gains by folding onto itself — less a smoothness penalty on the
//! correction. Every pair of frames, up to the span apart, measures the
//! flow, and each frame's path is followed through the field, not
//! linearised at the pixel.
//!
//! The flow is the start (the ladder's or the ensemble's field) plus a
//! correction on a node grid (bilinear between nodes), fitted coarse to
//! fine ([`JointSettings::levels`]) by gradient ascent, each step scaled
//! per node by its own curvature and accepted only where the objective
//! grows.
//!
//! Hand-written: the objective and its gradient run over every pixel and
//! frame, and no optimisation crate in the workspace takes a gradient
//! that costs one pass over the frames.

use ndarray::{Array2, Zip};
use rayon::prelude::*;

use crate::compensate::{Velocity, WarpFlow};
use crate::events::Events;

/// Ticks per frame of the joint fit.
pub const FRAME: u64 = 6;

/// One level of the fit: the correction's node spacing and the frames'
/// blur.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Level {
    /// Spacing of the correction's nodes, px.
    pub pitch: usize,
    /// Gaussian blur of the frames, px (σ).
    pub blur: f32,
}

/// The joint fit's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct JointSettings {
    /// Ticks on each side of the midpoint whose frames are fitted.
    pub reach: u64,
    /// The levels, coarse to fine.
    pub levels: Vec<Level>,
    /// Gradient steps per level, at most.
    pub iterations: usize,
    /// Width of what the frames lose as still, px (σ of the Gaussian
    /// subtracted): light that stays put over the span aligns at any flow
    /// and pulls the fit towards rest.
    pub highpass: f32,
    /// Weight of the correction's smoothness: the sum over neighbouring
    /// nodes of the squared difference of their corrections over
    /// [`JointSettings::reach`] ticks (px²; for a smooth correction about
    /// the same on every level), against the objective normalised by the
    /// frames' own energy.
    pub smooth: f64,
    /// Ticks per step along a path (midpoint rule).
    pub step: f64,
    /// Spacing of the points whose paths are followed, px; the pixels
    /// between take their paths' ends bilinearly.
    pub lattice: usize,
}

impl Default for JointSettings {
    fn default() -> Self {
        JointSettings {
            reach: 30,
            levels: vec![
                Level {
                    pitch: 32,
                    blur: 0.7,
                },
                Level {
                    pitch: 16,
                    blur: 0.7,
                },
                Level {
                    pitch: 8,
                    blur: 0.7,
                },
            ],
            iterations: 10,
            highpass: 3.0,
            smooth: 1e-4,
            step: 2.0,
            lattice: 4,
        }
    }
}

/// A frame of the fit: its band-passed values and their gradient, and how
/// many ticks before the midpoint its centre lies (negative: after).
struct Frame {
    f: Array2<f32>,
    gx: Array2<f32>,
    gy: Array2<f32>,
    tau: f64,
}

/// The flow at `mid` fitted to the frames within the reach, starting from
/// `start` (px per tick, upright, the events' size); `None` when fewer than
/// three frames fit, `start` is not the events' size or the frames hold
/// nothing that moves.
pub fn fit(ev: &Events, mid: u64, start: &Velocity, cfg: &JointSettings) -> Option<Velocity> {
    let span = ev.range();
    if mid < span.start || mid > span.end {
        return None;
    }
    let s = FRAME;
    let back = ((mid - span.start).min(cfg.reach) / s) * s;
    let ahead = ((span.end - mid).min(cfg.reach) / s) * s;
    if back + ahead < 3 * s {
        return None;
    }
    let (h, w) = (ev.height, ev.width);
    if start.u.dim() != (h, w) || h < 2 || w < 2 {
        return None;
    }
    let still = WarpFlow::still();
    let starts: Vec<u64> = ((mid - back)..(mid + ahead)).step_by(s as usize).collect();
    let raw: Vec<(Array2<f32>, f64)> = starts
        .par_iter()
        .map(|&t| {
            let c = t as f64 + s as f64 / 2.0;
            (ev.frame(c, (t, s), &still), mid as f64 - c)
        })
        .collect();
    let mut correction: Option<Nodes> = None;
    // The band-passed frames and their energy, kept while the levels'
    // blur stays the same.
    let mut passed: Option<(f32, Vec<Frame>, f64)> = None;
    for level in &cfg.levels {
        if passed.as_ref().is_none_or(|p| p.0 != level.blur) {
            let frames = band_passed(&raw, level.blur, cfg.highpass);
            let energy: f64 = frames
                .iter()
                .map(|fr| {
                    fr.f.iter()
                        .map(|&x| f64::from(x) * f64::from(x))
                        .sum::<f64>()
                })
                .sum();
            if energy <= 0.0 || !energy.is_finite() {
                return None;
            }
            passed = Some((level.blur, frames, energy));
        }
        let Some((_, frames, energy)) = &passed else {
            return None;
        };
        let (frames, energy) = (frames.as_slice(), *energy);
        let fit = Fit {
            frames,
            start,
            cfg,
            energy,
        };
        let mut nodes = Nodes::new(w, h, level.pitch.max(1));
        if let Some(prev) = &correction {
            nodes.take(prev);
        }
        let mut rate = 1.0;
        let mut now = fit.eval(&nodes, true);
        for _ in 0..cfg.iterations {
            let step = nodes.step(&now);
            let mut next = None;
            for _ in 0..6 {
                let trial = nodes.moved(&step, rate);
                let e = fit.eval(&trial, true);
                if e.j > now.j {
                    next = Some((trial, e));
                    rate = (rate * 1.5).min(4.0);
                    break;
                }
                rate *= 0.3;
            }
            let Some((n, e)) = next else { break };
            nodes = n;
            now = e;
        }
        correction = Some(nodes);
    }
    Some(match &correction {
        Some(n) => with(start, n),
        None => start.clone(),
    })
}

/// The frames blurred by `blur` less their blur by `highpass` (px, σ).
fn band_passed(raw: &[(Array2<f32>, f64)], blur: f32, highpass: f32) -> Vec<Frame> {
    raw.par_iter()
        .map(|(f, tau)| {
            let mut b = blurred(f, blur);
            if highpass > blur {
                b -= &blurred(f, highpass);
            }
            let (gx, gy) = spiv_piv::dense::gradients(&b);
            Frame {
                f: b,
                gx,
                gy,
                tau: *tau,
            }
        })
        .collect()
}

/// A correction to the flow on a node grid, px per tick.
#[derive(Debug, Clone)]
struct Nodes {
    pitch: usize,
    nx: usize,
    ny: usize,
    u: Vec<f64>,
    v: Vec<f64>,
}

impl Nodes {
    fn new(w: usize, h: usize, pitch: usize) -> Nodes {
        let nx = (w.saturating_sub(1)).div_ceil(pitch) + 1;
        let ny = (h.saturating_sub(1)).div_ceil(pitch) + 1;
        Nodes {
            pitch,
            nx,
            ny,
            u: vec![0.0; nx * ny],
            v: vec![0.0; nx * ny],
        }
    }

    /// The four nodes around `(x, y)` and their bilinear weights.
    fn weights(&self, x: f64, y: f64) -> [(usize, f64); 4] {
        let p = self.pitch as f64;
        let gx = (x / p).clamp(0.0, (self.nx - 1) as f64);
        let gy = (y / p).clamp(0.0, (self.ny - 1) as f64);
        let (j, i) = (gx.floor() as usize, gy.floor() as usize);
        let (j1, i1) = ((j + 1).min(self.nx - 1), (i + 1).min(self.ny - 1));
        let (fx, fy) = (gx - j as f64, gy - i as f64);
        [
            (i * self.nx + j, (1.0 - fx) * (1.0 - fy)),
            (i * self.nx + j1, fx * (1.0 - fy)),
            (i1 * self.nx + j, (1.0 - fx) * fy),
            (i1 * self.nx + j1, fx * fy),
        ]
    }

    fn at(&self, x: f64, y: f64) -> (f64, f64) {
        self.weights(x, y)
            .iter()
            .fold((0.0, 0.0), |(a, b), &(k, wt)| {
                (a + wt * self.u[k], b + wt * self.v[k])
            })
    }

    /// This grid's correction taken from a coarser one.
    fn take(&mut self, coarse: &Nodes) {
        for i in 0..self.ny {
            for j in 0..self.nx {
                let (u, v) = coarse.at((j * self.pitch) as f64, (i * self.pitch) as f64);
                self.u[i * self.nx + j] = u;
                self.v[i * self.nx + j] = v;
            }
        }
    }

    /// The step along the gradient of `e`, each node's scaled by its own
    /// curvature (at least a tenth of the mean node's).
    fn step(&self, e: &Eval) -> (Vec<f64>, Vec<f64>) {
        let mean = e.curv.iter().sum::<f64>() / e.curv.len().max(1) as f64;
        let floor = 0.1 * mean + f64::MIN_POSITIVE;
        let scale = |k: usize| 1.0 / (e.curv[k] + floor);
        (
            (0..self.u.len()).map(|k| e.gu[k] * scale(k)).collect(),
            (0..self.v.len()).map(|k| e.gv[k] * scale(k)).collect(),
        )
    }

    fn moved(&self, step: &(Vec<f64>, Vec<f64>), rate: f64) -> Nodes {
        let mut n = self.clone();
        for k in 0..n.u.len() {
            n.u[k] += rate * step.0[k];
            n.v[k] += rate * step.1[k];
        }
        n
    }

    /// The smoothness penalty and its gradient, over `ticks` ticks.
    fn roughness(&self, ticks: f64) -> (f64, Vec<f64>, Vec<f64>) {
        let t2 = ticks * ticks;
        let mut p = 0.0;
        let mut gu = vec![0.0; self.u.len()];
        let mut gv = vec![0.0; self.v.len()];
        let mut pair = |a: usize, b: usize| {
            let du = self.u[a] - self.u[b];
            let dv = self.v[a] - self.v[b];
            p += t2 * (du * du + dv * dv);
            gu[a] += 2.0 * t2 * du;
            gu[b] -= 2.0 * t2 * du;
            gv[a] += 2.0 * t2 * dv;
            gv[b] -= 2.0 * t2 * dv;
        };
        for i in 0..self.ny {
            for j in 0..self.nx {
                let k = i * self.nx + j;
                if j + 1 < self.nx {
                    pair(k, k + 1);
                }
                if i + 1 < self.ny {
                    pair(k, k + self.nx);
                }
            }
        }
        (p, gu, gv)
    }
}

/// `start` plus the correction `n`, per pixel.
fn with(start: &Velocity, n: &Nodes) -> Velocity {
    let mut out = start.clone();
    Zip::indexed(&mut out.u)
        .and(&mut out.v)
        .for_each(|(i, j), u, v| {
            let (du, dv) = n.at(j as f64, i as f64);
            *u += du as f32;
            *v += dv as f32;
        });
    out
}

/// The objective at one correction, with its gradient per node and each
/// node's curvature (the Gauss–Newton scale of its data term).
struct Eval {
    j: f64,
    gu: Vec<f64>,
    gv: Vec<f64>,
    curv: Vec<f64>,
}

/// What one level fits: its frames, the start, the settings and the
/// frames' energy the objective is normalised by.
struct Fit<'a> {
    frames: &'a [Frame],
    start: &'a Velocity,
    cfg: &'a JointSettings,
    energy: f64,
}

/// Where each lattice point's path is at every frame's centre and halfway
/// there, as displacements from the point, px.
struct Paths {
    step: usize,
    nx: usize,
    /// Per frame, per lattice point (row-major): the end and the halfway
    /// point.
    ends: Vec<Vec<[(f32, f32); 2]>>,
}

impl Paths {
    fn new(vel: &Velocity, frames: &[Frame], step: usize, tick: f64) -> Paths {
        let (h, w) = vel.u.dim();
        let nx = (w - 1) / step + 2;
        let ny = (h - 1) / step + 2;
        let points: Vec<Vec<[(f32, f32); 2]>> = (0..ny * nx)
            .into_par_iter()
            .map(|q| {
                let p = ((q % nx * step) as f64, (q / nx * step) as f64);
                let mut path = Path::new(vel, p, tick);
                frames
                    .iter()
                    .map(|fr| {
                        let e = path.at(fr.tau);
                        let m = path.at(0.5 * fr.tau);
                        [
                            ((e.0 - p.0) as f32, (e.1 - p.1) as f32),
                            ((m.0 - p.0) as f32, (m.1 - p.1) as f32),
                        ]
                    })
                    .collect()
            })
            .collect();
        let ends = (0..frames.len())
            .map(|k| points.iter().map(|pt| pt[k]).collect())
            .collect();
        Paths { step, nx, ends }
    }

    /// Frame `k`'s end and halfway point of the path through pixel
    /// `(x, y)`, px.
    fn at(&self, k: usize, x: usize, y: usize) -> [(f64, f64); 2] {
        let (j, fx) = (x / self.step, (x % self.step) as f32 / self.step as f32);
        let (i, fy) = (y / self.step, (y % self.step) as f32 / self.step as f32);
        let e = &self.ends[k];
        let q = i * self.nx + j;
        let wts = [
            (q, (1.0 - fx) * (1.0 - fy)),
            (q + 1, fx * (1.0 - fy)),
            (q + self.nx, (1.0 - fx) * fy),
            (q + self.nx + 1, fx * fy),
        ];
        let mut out = [(x as f64, y as f64); 2];
        for (q, wt) in wts {
            for (o, d) in out.iter_mut().zip(&e[q]) {
                o.0 += f64::from(wt * d.0);
                o.1 += f64::from(wt * d.1);
            }
        }
        out
    }
}

impl Fit<'_> {
    /// The objective at `nodes` — the frames' pairwise products along the
    /// paths, over their energy, less the correction's roughness — and,
    /// with `grad`, its gradient and curvature per node.
    fn eval(&self, nodes: &Nodes, grad: bool) -> Eval {
        let vel = with(self.start, nodes);
        let (h, w) = vel.u.dim();
        let frames = self.frames;
        let paths = Paths::new(&vel, frames, self.cfg.lattice.max(1), self.cfg.step);
        let nn = nodes.u.len();
        let zero = || Eval {
            j: 0.0,
            gu: vec![0.0; nn],
            gv: vec![0.0; nn],
            curv: vec![0.0; nn],
        };
        let data = (0..h)
            .into_par_iter()
            .fold(zero, |mut acc, i| {
                let n = frames.len();
                let mut vals = vec![0.0f64; n];
                let mut ends = vec![[(0.0f64, 0.0f64); 2]; n];
                for j in 0..w {
                    let mut s = 0.0;
                    let mut self_sq = 0.0;
                    for (k, fr) in frames.iter().enumerate() {
                        ends[k] = paths.at(k, j, i);
                        vals[k] = match inside(ends[k][0], w, h) {
                            true => f64::from(sample(&fr.f, ends[k][0])),
                            false => 0.0,
                        };
                        s += vals[k];
                        self_sq += vals[k] * vals[k];
                    }
                    acc.j += 0.5 * (s * s - self_sq);
                    if !grad {
                        continue;
                    }
                    for (k, fr) in frames.iter().enumerate() {
                        if !inside(ends[k][0], w, h) {
                            continue;
                        }
                        // The sample moves by −τ·δv, so the gradient of
                        // the products it is in is (s − v_k)·∇f_k·(−τ).
                        let gx = f64::from(sample(&fr.gx, ends[k][0]));
                        let gy = f64::from(sample(&fr.gy, ends[k][0]));
                        let other = s - vals[k];
                        let (du, dv) = (-fr.tau * other * gx, -fr.tau * other * gy);
                        let c = fr.tau * fr.tau * (gx * gx + gy * gy);
                        let (mx, my) = ends[k][1];
                        for (q, wt) in nodes.weights(mx, my) {
                            acc.gu[q] += wt * du;
                            acc.gv[q] += wt * dv;
                            acc.curv[q] += wt * c;
                        }
                    }
                }
                acc
            })
            .reduce(zero, |mut a, b| {
                a.j += b.j;
                for (x, y) in [
                    (&mut a.gu, &b.gu),
                    (&mut a.gv, &b.gv),
                    (&mut a.curv, &b.curv),
                ] {
                    x.iter_mut().zip(y).for_each(|(p, q)| *p += q);
                }
                a
            });
        let (rough, ru, rv) = nodes.roughness(self.cfg.reach as f64);
        let k = self.cfg.smooth;
        let e = self.energy;
        let n = frames.len() as f64;
        Eval {
            j: data.j / e - k * rough,
            gu: (0..nn).map(|q| data.gu[q] / e - k * ru[q]).collect(),
            gv: (0..nn).map(|q| data.gv[q] / e - k * rv[q]).collect(),
            curv: data.curv.iter().map(|c| c * n / e).collect(),
        }
    }
}

/// A particle's path through a steady flow from `(x, y)` at the midpoint,
/// followed back (positive `τ`) or ahead (negative) in midpoint steps,
/// remembering where it has been so that frames are sampled along one
/// walk.
struct Path<'a> {
    vel: &'a Velocity,
    step: f64,
    back: Vec<(f64, f64)>,
    ahead: Vec<(f64, f64)>,
}

impl<'a> Path<'a> {
    fn new(vel: &'a Velocity, p: (f64, f64), step: f64) -> Path<'a> {
        Path {
            vel,
            step: step.max(0.25),
            back: vec![p],
            ahead: vec![p],
        }
    }

    /// Where the particle at the midpoint was `tau` ticks before it.
    fn at(&mut self, tau: f64) -> (f64, f64) {
        let dir = if tau >= 0.0 { -1.0 } else { 1.0 };
        let walk = if tau >= 0.0 {
            &mut self.back
        } else {
            &mut self.ahead
        };
        let t = tau.abs() / self.step;
        let need = t.floor() as usize + 1;
        while walk.len() <= need {
            let (x, y) = *walk.last().unwrap_or(&(0.0, 0.0));
            let h = dir * self.step;
            let (u1, v1) = self.vel.at(x, y);
            let (u2, v2) = self.vel.at(x + 0.5 * h * u1, y + 0.5 * h * v1);
            walk.push((x + h * u2, y + h * v2));
        }
        let i = t.floor() as usize;
        let f = t - i as f64;
        let (a, b) = (walk[i], walk[i + 1]);
        (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
    }
}

fn inside((x, y): (f64, f64), w: usize, h: usize) -> bool {
    x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64
}

fn sample(a: &Array2<f32>, (x, y): (f64, f64)) -> f32 {
    spiv_piv::dense::sample(a, y as f32, x as f32)
}

/// `a` blurred by a Gaussian of `sigma` px (separable, ±3σ, edges
/// clamped).
fn blurred(a: &Array2<f32>, sigma: f32) -> Array2<f32> {
    if sigma <= 0.0 {
        return a.clone();
    }
    let r = (3.0 * sigma).ceil() as i64;
    let taps: Vec<f32> = (-r..=r)
        .map(|d| (-(d * d) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f32 = taps.iter().sum();
    let (h, w) = a.dim();
    let pass = |src: &Array2<f32>, along_x: bool| {
        Array2::from_shape_fn((h, w), |(i, j)| {
            let mut s = 0.0;
            for (t, &k) in taps.iter().enumerate() {
                let d = t as i64 - r;
                let (ii, jj) = if along_x {
                    (i as i64, (j as i64 + d).clamp(0, w as i64 - 1))
                } else {
                    ((i as i64 + d).clamp(0, h as i64 - 1), j as i64)
                };
                s += k * src[[ii as usize, jj as usize]];
            }
            s / norm
        })
    };
    pass(&pass(a, true), false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const N: usize = 96;

    /// Spikes of particles (Gaussian spots of σ 1 px, about one per
    /// 40 px²) carried by `truth` over `ticks` ticks, each pixel firing
    /// with the chance its light gives, no static light.
    fn recording(truth: &Velocity, ticks: usize, seed: u64) -> Events {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut parts: Vec<(f64, f64)> = (0..N * N / 40)
            .map(|_| (rng.gen::<f64>() * N as f64, rng.gen::<f64>() * N as f64))
            .collect();
        let mut per_tick = Vec::with_capacity(ticks);
        for _ in 0..ticks {
            let mut light = vec![0.0f64; N * N];
            for &(x, y) in &parts {
                for r in (y as i64 - 3).max(0)..(y as i64 + 4).min(N as i64) {
                    for c in (x as i64 - 3).max(0)..(x as i64 + 4).min(N as i64) {
                        let d2 = (c as f64 - x).powi(2) + (r as f64 - y).powi(2);
                        light[r as usize * N + c as usize] += 0.6 * (-d2 / 2.0).exp();
                    }
                }
            }
            let tick: Vec<(u32, i8)> = light
                .iter()
                .enumerate()
                .filter(|(_, &l)| rng.gen::<f64>() < l)
                .map(|(i, _)| (i as u32, 1))
                .collect();
            per_tick.push(tick);
            for p in &mut parts {
                *p = truth.advect(*p, 1.0);
            }
        }
        Events::from_ticks((N, N), N, false, 0, per_tick, vec![0; N * N])
    }

    fn field(f: impl Fn(f64, f64) -> (f64, f64)) -> Velocity {
        let mut v = Velocity::zero(N, N);
        for ((i, j), u) in v.u.indexed_iter_mut() {
            *u = f(j as f64, i as f64).0 as f32;
        }
        for ((i, j), w) in v.v.indexed_iter_mut() {
            *w = f(j as f64, i as f64).1 as f32;
        }
        v
    }

    /// Mean distance between two velocities over the interior (8 px in
    /// from the edges, where paths leave the image), px per tick.
    fn off(a: &Velocity, b: &Velocity) -> f64 {
        let mut s = 0.0;
        let mut n = 0.0;
        for i in 8..N - 8 {
            for j in 8..N - 8 {
                let du = f64::from(a.u[[i, j]] - b.u[[i, j]]);
                let dv = f64::from(a.v[[i, j]] - b.v[[i, j]]);
                s += du.hypot(dv);
                n += 1.0;
            }
        }
        s / n
    }

    #[test]
    fn a_translation_started_off_is_fitted() {
        let truth = field(|_, _| (0.3, -0.15));
        let ev = recording(&truth, 61, 1);
        let start = field(|_, _| (0.25, -0.1));
        let fitted = fit(&ev, 30, &start, &JointSettings::default()).expect("fits");
        let (before, after) = (off(&start, &truth), off(&fitted, &truth));
        assert!(after < 0.015, "{before} -> {after} px per tick");
    }

    #[test]
    fn a_rotation_started_short_is_fitted() {
        // Solid-body rotation about the centre, 0.01 rad per tick: 0.4 px
        // per tick at 40 px out; started at 80 % of its speed.
        let c = (N as f64 - 1.0) / 2.0;
        let rot = |k: f64| move |x: f64, y: f64| (-k * (y - c), k * (x - c));
        let truth = field(rot(0.01));
        let ev = recording(&truth, 61, 2);
        let start = field(rot(0.008));
        let fitted = fit(&ev, 30, &start, &JointSettings::default()).expect("fits");
        let (before, after) = (off(&start, &truth), off(&fitted, &truth));
        assert!(after < 0.3 * before, "{before} -> {after} px per tick");
    }

    #[test]
    fn nothing_to_fit_is_no_flow() {
        let cfg = JointSettings::default();
        let still = Velocity::zero(N, N);
        let empty = Events::from_ticks((N, N), N, false, 0, vec![vec![]; 61], vec![0; N * N]);
        assert!(fit(&empty, 30, &still, &cfg).is_none(), "no spikes");
        let ev = recording(&still, 61, 3);
        assert!(
            fit(&ev, 30, &Velocity::zero(N, N - 1), &cfg).is_none(),
            "size"
        );
        assert!(fit(&ev, 80, &still, &cfg).is_none(), "midpoint outside");
        let short = recording(&still, 12, 3);
        assert!(fit(&short, 6, &still, &cfg).is_none(), "two frames");
    }
}
