//! The dense ensemble: a pair's flow measured where window PIV cannot
//! start the time ladder — eddies smaller than its windows, displacements
//! beyond a quarter of them (turbulence, large shifts).
//!
//! Around the pair's midpoint the recording is cut into consecutive,
//! disjoint [`FRAME`]-tick innovation frames (within the ladder's
//! bootstrap reach). One steady flow is fitted to all of them at once
//! ([`dense_frames`]: the dense stage's pyramid from rest with the
//! divergence penalty, its data term summed over every pair of frames one
//! and two frames apart, and three apart at full resolution, compared along
//! the flow's own paths). Short frames blur little whatever the speed;
//! disjoint frames share no spike; pairs further apart measure the flow
//! more finely. A second pass fits the flow again, from the first pass's
//! at pyramid level 1, to [`SHARP`]-tick frames on the same centres whose
//! spikes are summed along the first pass's paths: twice the spikes per
//! particle, with little blur.
//!
//! The uncertainty of each node's vector comes from the pairs' own
//! disagreement with the fit: each consecutive pair's least-squares
//! correction over [`LOOK`] px around the node (`look`) is one look, and
//! the looks' standard error of the mean is the standard uncertainty —
//! or, where larger, the root mean square of its measured 3×3
//! neighbourhood's (`pooled`): a node's few looks alone leave its
//! error's estimate spread wide, and one that reads low by chance would
//! claim a certainty the data do not hold. A node is flagged by its own
//! looks' spread ([`Ensemble::pool`]).
//!
//! A node is measured only where the frames, warped by the flow, match
//! ([`MIN_MATCH`]: the mean zero-normalised correlation over the node's
//! window of each consecutive pair's frame A and frame B moved half the
//! flow towards each other). Pure noise and static light match nothing, so
//! nothing is reported there; a flow beyond what the pyramid reaches
//! leaves the frames unmatched too.
//!
//! What was measured to choose this design and its constants:
//! `docs/results.md#the-constants-and-what-chose-them`.

use ndarray::Array2;
use rayon::prelude::*;

use spiv_formats::grid::Grid;
use spiv_piv::dense::{dense_frames, dense_frames_from, DenseSettings, Flow, Steps};
use spiv_piv::{Field, State};

use crate::compensate::WarpFlow;
use crate::events::Events;
use crate::Velocity;

/// Ticks per frame of the ensemble.
pub const FRAME: u64 = 6;

/// The frame pairs the flow is measured on: consecutive frames and those
/// two apart at every pyramid level, three apart at full resolution.
pub const STEPS: Steps<'static> = Steps {
    every: &[1, 2],
    fine: &[3],
};

/// The dense stage's settings for the ensemble's frames (the second pass
/// enters the pyramid at level 1).
pub fn settings() -> DenseSettings {
    DenseSettings {
        alpha: 0.2,
        levels: 5,
        warps: 6,
        iterations: 60,
        median: 5,
        init_level: 1,
        div_weight: 0.5,
    }
}

/// Ticks of the second pass's frames, on the first pass's frame centres,
/// their spikes summed along the first pass's flow (clipped to the
/// ensemble's span); chosen on the tuning seeds
/// (`docs/results.md#the-constants-and-what-chose-them`).
pub const SHARP: u64 = 12;

/// Node spacing of the first pass's flow as the second pass's frames
/// follow it ([`WarpFlow::from_velocity`]), px.
pub const FLOW_PITCH: usize = 4;

/// A flow per frame step of `s` ticks as a velocity, px per tick.
fn per_tick(f: &Flow, s: u64) -> Velocity {
    Velocity::from_displacement(&f.u, &f.v, s as f64)
}

/// Least mean zero-normalised correlation of a node's window between the
/// frames warped by their flows for the node to count as measured.
pub const MIN_MATCH: f64 = 0.2;

/// Side of the window around a node's centre over which each pair's own
/// correction (`look`) is measured, px: the vector is the flow at the
/// centre, so its uncertainty is that of the flow there, not of the mean
/// over the node's window (a wider window's looks agree too well:
/// `docs/results.md#the-constants-and-what-chose-them`).
pub const LOOK: usize = 8;

/// A pair measured by the dense ensemble.
#[derive(Debug, Clone)]
pub struct Ensemble {
    /// Velocities per node (px per tick) on the grid asked for: valid
    /// where the frames match, with the pairs' looks' standard error
    /// (`pooled`) as the uncertainty; invalid, with none, elsewhere. `peak_height`
    /// holds each node's match (the mean correlation, `−1..=1`).
    pub field: Field,
    /// What the neighbourhood's pool adds to each measured node's own
    /// standard error, in quadrature (px per tick; zero where its own is
    /// the larger): the node's measurement is as certain as its own
    /// looks say, its reported σ as the pool says.
    pub pool: Array2<(f64, f64)>,
    /// The fitted flow per pixel, px per tick.
    pub velocity: Velocity,
    /// The consecutive frames, oldest first; frames `centre - 1` and
    /// `centre` meet at the midpoint.
    pub frames: Vec<Array2<f32>>,
    /// Index of the first frame after the midpoint.
    pub centre: usize,
}

impl Ensemble {
    /// The frames that meet at the midpoint (A before, B after).
    pub fn centre_pair(&self) -> [Array2<f32>; 2] {
        [
            self.frames[self.centre - 1].clone(),
            self.frames[self.centre].clone(),
        ]
    }
}

/// Measures the flow at `mid` (a tick boundary) from the frames within
/// `reach` ticks of it, reported on `grid`; `None` when fewer than two
/// pairs of frames fit (no spread, so no uncertainty).
pub fn measure(ev: &Events, mid: u64, grid: &Grid, reach: u64) -> Option<Ensemble> {
    let span = ev.range();
    if mid < span.start || mid > span.end {
        return None;
    }
    let s = FRAME;
    let back = ((mid - span.start).min(reach) / s) * s;
    let ahead = ((span.end - mid).min(reach) / s) * s;
    if back == 0 || ahead == 0 || back + ahead < 3 * s {
        return None;
    }
    let still = WarpFlow::still();
    let starts: Vec<u64> = ((mid - back)..(mid + ahead)).step_by(s as usize).collect();
    let frames: Vec<Array2<f32>> = starts
        .par_iter()
        .map(|&t| ev.frame(t as f64 + s as f64 / 2.0, (t, s), &still))
        .collect();
    let first = dense_frames(&frames, STEPS, &settings());
    // The second pass: longer frames on the same centres, each summing its
    // spikes along the first pass's paths, so a particle shows with twice
    // the spikes and little blur; the flow starts from the first pass's.
    let along = WarpFlow::from_velocity(&per_tick(&first, s), FLOW_PITCH, ev.flip);
    let (lo, hi) = (mid - back, mid + ahead);
    let sharp: Vec<Array2<f32>> = starts
        .par_iter()
        .map(|&t| {
            let c = t + s / 2;
            let a = c.saturating_sub(SHARP / 2).max(lo);
            let b = (c + SHARP / 2).min(hi);
            ev.frame(c as f64, (a, b - a), &along)
        })
        .collect();
    let flow = dense_frames_from(&sharp, Some(&first), STEPS, &settings());
    let velocity = per_tick(&flow, s);
    let n = frames.len() - 1;
    let mut field = Field::unmeasured(*grid);
    let nodes: Vec<(usize, usize)> = ndarray::indices((grid.ny, grid.nx)).into_iter().collect();
    let per_node: Vec<Node> = nodes
        .par_iter()
        .map(|&(r, c)| {
            let (x, y) = grid.centre(r, c);
            let at = flow.at(x, y);
            let looks: Vec<(f64, f64)> = (0..n)
                .filter_map(|i| look(&frames[i], &frames[i + 1], &flow, grid, (r, c)))
                .map(|d| (at.0 + d.0, at.1 + d.1))
                .collect();
            let (_, se) = mean_and_error(&looks, s as f64);
            let mean = (at.0 / s as f64, at.1 / s as f64);
            let m = (0..n)
                .map(|i| matched(&frames[i], &frames[i + 1], &flow, grid, (r, c)))
                .sum::<f64>()
                / n as f64;
            Node { mean, se, m }
        })
        .collect();
    let mut se = Array2::from_elem((grid.ny, grid.nx), None);
    for (&(r, c), node) in nodes.iter().zip(&per_node) {
        field.u[[r, c]] = node.mean.0;
        field.v[[r, c]] = node.mean.1;
        field.peak_height[[r, c]] = node.m;
        if node.m >= MIN_MATCH && node.se.0.is_finite() && node.se.1.is_finite() {
            field.state[[r, c]] = State::Valid;
            se[[r, c]] = Some(node.se);
        }
    }
    let mut pool = Array2::from_elem((grid.ny, grid.nx), (0.0, 0.0));
    for ((r, c), s) in pooled(&se).indexed_iter() {
        if let (Some(s), Some(own)) = (s, se[[r, c]]) {
            field.sigma[[r, c]] = *s;
            let excess = |p: f64, o: f64| (p * p - o * o).max(0.0).sqrt();
            pool[[r, c]] = (excess(s.0, own.0), excess(s.1, own.1));
        }
    }
    Some(Ensemble {
        field,
        pool,
        velocity,
        frames,
        centre: (back / s) as usize,
    })
}

/// Each measured node's standard error (px per tick, per component): its
/// own, or the mean of the squared errors of the measured nodes of its
/// 3×3 neighbourhood (itself included) where that is larger. Nine looks
/// give an error's square with eight degrees of freedom, which reads below
/// half its true value one time in seven; the neighbourhood's pool holds
/// up to nine times as many, while a node whose own looks disagree more
/// keeps its own. `None` where the node is not measured.
fn pooled(se: &Array2<Option<(f64, f64)>>) -> Array2<Option<(f64, f64)>> {
    let (ny, nx) = se.dim();
    Array2::from_shape_fn((ny, nx), |(r, c)| {
        let own = se[[r, c]]?;
        let (mut su, mut sv, mut n) = (0.0, 0.0, 0.0);
        for y in r.saturating_sub(1)..(r + 2).min(ny) {
            for x in c.saturating_sub(1)..(c + 2).min(nx) {
                if let Some(s) = se[[y, x]] {
                    su += s.0 * s.0;
                    sv += s.1 * s.1;
                    n += 1.0;
                }
            }
        }
        Some((own.0.max((su / n).sqrt()), own.1.max((sv / n).sqrt())))
    })
}

/// One node's mean velocity and its standard error (px per tick) and its
/// match.
#[derive(Clone, Copy)]
struct Node {
    mean: (f64, f64),
    se: (f64, f64),
    m: f64,
}

/// The mean of `looks` (displacements over `s` ticks) and its standard
/// error, both per tick (infinite error with fewer than two looks).
fn mean_and_error(looks: &[(f64, f64)], s: f64) -> ((f64, f64), (f64, f64)) {
    let n = looks.len() as f64;
    if looks.is_empty() {
        return ((0.0, 0.0), (f64::INFINITY, f64::INFINITY));
    }
    let mu = looks.iter().map(|l| l.0).sum::<f64>() / n;
    let mv = looks.iter().map(|l| l.1).sum::<f64>() / n;
    if looks.len() < 2 {
        return ((mu / s, mv / s), (f64::INFINITY, f64::INFINITY));
    }
    let var = |f: &dyn Fn(&(f64, f64)) -> f64, m: f64| {
        looks.iter().map(|l| (f(l) - m).powi(2)).sum::<f64>() / (n - 1.0)
    };
    let (vu, vv) = (var(&|l| l.0, mu), var(&|l| l.1, mv));
    ((mu / s, mv / s), ((vu / n).sqrt() / s, (vv / n).sqrt() / s))
}

/// One pair's own correction to `flow` over node `(r, c)`'s window: the
/// least-squares displacement (Lucas & Kanade) that brings `a` and `b`,
/// each moved half of `flow` towards the other, into register, px per
/// step; `None` where the window has no texture to measure it.
fn look(
    a: &Array2<f32>,
    b: &Array2<f32>,
    flow: &Flow,
    grid: &Grid,
    (r, c): (usize, usize),
) -> Option<(f64, f64)> {
    use spiv_piv::dense::sample;
    let (h, w) = a.dim();
    let side = LOOK;
    let (cx, cy) = grid.centre(r, c);
    let x0 = (cx - (side as f64 - 1.0) / 2.0).round().max(0.0) as usize;
    let y0 = (cy - (side as f64 - 1.0) / 2.0).round().max(0.0) as usize;
    let (mut sxx, mut sxy, mut syy, mut sxt, mut syt) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for y in y0..(y0 + side).min(h) {
        for x in x0..(x0 + side).min(w) {
            let (u, v) = (flow.u[[y, x]], flow.v[[y, x]]);
            let (xf, yf) = (x as f32, y as f32);
            let (xa, ya, xb, yb) = (xf - 0.5 * u, yf - 0.5 * v, xf + 0.5 * u, yf + 0.5 * v);
            let grad = |img: &Array2<f32>, xx: f32, yy: f32| {
                (
                    0.5 * (sample(img, yy, xx + 1.0) - sample(img, yy, xx - 1.0)),
                    0.5 * (sample(img, yy + 1.0, xx) - sample(img, yy - 1.0, xx)),
                )
            };
            let (gax, gay) = grad(a, xa, ya);
            let (gbx, gby) = grad(b, xb, yb);
            let gx = f64::from(0.5 * (gax + gbx));
            let gy = f64::from(0.5 * (gay + gby));
            let gt = f64::from(sample(b, yb, xb) - sample(a, ya, xa));
            sxx += gx * gx;
            sxy += gx * gy;
            syy += gy * gy;
            sxt += gx * gt;
            syt += gy * gt;
        }
    }
    let det = sxx * syy - sxy * sxy;
    // Zero trace (no texture) makes both sides zero.
    if det <= 1e-9 * (sxx + syy).powi(2) {
        return None;
    }
    // (Σ g gᵀ)·d = −Σ g·gt.
    let du = -(syy * sxt - sxy * syt) / det;
    let dv = -(sxx * syt - sxy * sxt) / det;
    Some((du, dv))
}

/// The zero-normalised correlation over node `(r, c)`'s window of `a`
/// and `b` each moved half of `flow` towards the other (`a` sampled half
/// a displacement back, `b` half ahead): 1 where the flow carries one
/// onto the other, about 0 where they share nothing.
fn matched(
    a: &Array2<f32>,
    b: &Array2<f32>,
    flow: &Flow,
    grid: &Grid,
    (r, c): (usize, usize),
) -> f64 {
    let (x0, y0) = grid.origin(r, c);
    let (h, w) = a.dim();
    let side = grid.size;
    let n = (side * side) as f64;
    let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for y in y0..(y0 + side).min(h) {
        for x in x0..(x0 + side).min(w) {
            let (u, v) = (flow.u[[y, x]], flow.v[[y, x]]);
            let (xf, yf) = (x as f32, y as f32);
            let pa = f64::from(spiv_piv::dense::sample(a, yf - 0.5 * v, xf - 0.5 * u));
            let pb = f64::from(spiv_piv::dense::sample(b, yf + 0.5 * v, xf + 0.5 * u));
            sa += pa;
            sb += pb;
            saa += pa * pa;
            sbb += pb * pb;
            sab += pa * pb;
        }
    }
    let cov = sab - sa * sb / n;
    let va = saa - sa * sa / n;
    let vb = sbb - sb * sb / n;
    if va <= 1e-12 || vb <= 1e-12 {
        return 0.0;
    }
    cov / (va * vb).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_error_of_looks() {
        let looks = [(6.0, -3.0), (12.0, -3.0), (9.0, -3.0)];
        let ((u, v), (eu, ev)) = mean_and_error(&looks, 6.0);
        assert!((u - 1.5).abs() < 1e-12 && (v + 0.5).abs() < 1e-12);
        // Sample std 3 px, over √3 looks, per 6 ticks.
        assert!((eu - 3.0 / 3f64.sqrt() / 6.0).abs() < 1e-12);
        assert_eq!(ev, 0.0);
        let (_, e) = mean_and_error(&looks[..1], 6.0);
        assert!(e.0.is_infinite());
    }

    #[test]
    fn a_look_is_the_pairs_own_correction_to_the_flow() {
        let grid = Grid::new(64, 64, 32, 16).unwrap();
        // Smooth texture: b is a moved 3 px right and 1 px down.
        let tex = |x: f32, y: f32| (0.31 * x).sin() * (0.23 * y).cos() + (0.17 * (x + y)).sin();
        let a = Array2::from_shape_fn((64, 64), |(y, x)| tex(x as f32, y as f32));
        let b = Array2::from_shape_fn((64, 64), |(y, x)| tex(x as f32 - 3.0, y as f32 - 1.0));
        let flow = |u: f32, v: f32| Flow {
            u: Array2::from_elem((64, 64), u),
            v: Array2::from_elem((64, 64), v),
        };
        let (du, dv) = look(&a, &b, &flow(2.6, 1.2), &grid, (1, 1)).expect("textured");
        assert!(
            (du - 0.4).abs() < 0.05 && (dv + 0.2).abs() < 0.05,
            "{du} {dv}"
        );
        let (du, dv) = look(&a, &b, &flow(3.0, 1.0), &grid, (1, 1)).expect("textured");
        assert!(du.abs() < 0.02 && dv.abs() < 0.02, "{du} {dv}");
        let flat = Array2::zeros((64, 64));
        assert!(look(&flat, &flat, &flow(0.0, 0.0), &grid, (1, 1)).is_none());
    }

    #[test]
    fn frames_match_only_where_the_flow_carries_them() {
        let grid = Grid::new(64, 64, 32, 16).unwrap();
        let mut s = 7u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s % 1000) as f32 / 1000.0
        };
        let a = Array2::from_shape_fn((64, 64), |_| next());
        // b is a moved 3 px right.
        let b = Array2::from_shape_fn((64, 64), |(y, x)| a[[y, x.saturating_sub(3)]]);
        let right = Flow {
            u: Array2::from_elem((64, 64), 3.0),
            v: Array2::zeros((64, 64)),
        };
        let still = Flow {
            u: Array2::zeros((64, 64)),
            v: Array2::zeros((64, 64)),
        };
        let m = matched(&a, &b, &right, &grid, (1, 1));
        assert!(m > 0.8, "carried: {m}");
        let m = matched(&a, &b, &still, &grid, (1, 1));
        assert!(m < 0.2, "not carried: {m}");
        let flat = Array2::zeros((64, 64));
        assert_eq!(matched(&flat, &b, &right, &grid, (1, 1)), 0.0);
    }

    #[test]
    fn a_node_that_reads_certain_by_chance_takes_its_neighbours_error() {
        // A 3×3 grid: the centre's looks agree by chance (0.01), its
        // neighbours' do not (0.1); one corner is unmeasured; one edge
        // node's own looks disagree more than the pool (0.3).
        let mut se = Array2::from_elem((3, 3), Some((0.1, 0.1)));
        se[[1, 1]] = Some((0.01, 0.1));
        se[[0, 0]] = None;
        se[[2, 1]] = Some((0.3, 0.3));
        let p = pooled(&se);
        assert_eq!(p[[0, 0]], None, "an unmeasured node stays unmeasured");
        // The centre pools all eight measured nodes: (6·0.01 + 0.0001 + 0.09) / 8.
        let u = ((6.0 * 0.01 + 0.0001 + 0.09) / 8.0f64).sqrt();
        let (pu, pv) = p[[1, 1]].unwrap();
        assert!((pu - u).abs() < 1e-12, "{pu} against {u}");
        assert!(pv > 0.1, "the pool with the 0.3 node lifts v too: {pv}");
        assert_eq!(p[[2, 1]], Some((0.3, 0.3)), "its own larger error stands");
        // Beside the unmeasured corner the pool holds five nodes, whose
        // u error (0.090) is below the node's own.
        assert_eq!(p[[0, 1]], Some((0.1, 0.1)));
    }
}
