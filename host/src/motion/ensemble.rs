//! The dense ensemble: a pair's flow measured where window PIV cannot
//! start the time ladder — eddies smaller than its windows, displacements
//! beyond a quarter of them (turbulence, large shifts).
//!
//! Around the pair's midpoint the recording is cut into consecutive,
//! disjoint [`FRAME`]-tick innovation frames (within the ladder's
//! bootstrap reach), and the dense stage ([`crate::piv::dense`], the
//! pyramid from rest with the divergence penalty) measures each frame
//! against the next. Short frames blur little whatever the speed; disjoint
//! frames share no spike. The flows of the consecutive pairs are
//! independent looks at the same motion: their mean per pixel is the
//! measurement and their spread its uncertainty (the standard error of
//! the mean, [`SPREAD`]).
//!
//! A node is measured only where the frames, warped by its flows, match
//! ([`MIN_MATCH`]: the mean zero-normalised correlation over the node's
//! window of each pair's frame A and frame B moved half their flow
//! towards each other). Pure noise and static light match nothing, so
//! nothing is reported there; a flow beyond what the pyramid reaches
//! leaves the frames unmatched too.
//!
//! [`FRAME`] was chosen on the tuning seeds 1–5 (dense EPE of the mean
//! flow, px per pair, the ladder's 32-tick reach): turbulence 2.73 / 1.51 /
//! 2.06 / 2.19 with 4 / 6 / 8 / 10-tick frames, large-shift 1.88 / 1.57 /
//! 1.83 with 4 / 6 / 8. Compensated dense frames of 16–30 ticks along the
//! mean flow did not improve on it (turbulence 1.78–1.87 from 1.51); see
//! `docs/piv.md`.

use ndarray::Array2;
use rayon::prelude::*;

use crate::piv::dense::{dense_flow, DenseMode, Flow};
use crate::piv::{Field, State};
use spiv_formats::grid::Grid;

use super::{compensated, Innovation, Velocity};

/// Ticks per frame of the ensemble.
pub const FRAME: u64 = 6;

/// Least mean zero-normalised correlation of a node's window between the
/// frames warped by their flows for the node to count as measured.
pub const MIN_MATCH: f64 = 0.2;

/// Scale of the ensemble's standard error in a vector's uncertainty.
pub const SPREAD: f64 = 1.0;

/// A pair measured by the dense ensemble.
#[derive(Debug, Clone)]
pub struct Ensemble {
    /// Velocities per node (px per tick) on the grid asked for: valid
    /// where the frames match, with the standard error of the mean as
    /// the uncertainty; invalid, with none, elsewhere. `peak_height`
    /// holds each node's match (the mean correlation, `−1..=1`).
    pub field: Field,
    /// The mean flow per pixel, px per tick.
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
pub fn measure(inn: &Innovation, mid: u64, grid: &Grid, reach: u64) -> Option<Ensemble> {
    let span = inn.range();
    if mid < span.start || mid > span.end {
        return None;
    }
    let s = FRAME;
    let back = ((mid - span.start).min(reach) / s) * s;
    let ahead = ((span.end - mid).min(reach) / s) * s;
    if back == 0 || ahead == 0 || back + ahead < 3 * s {
        return None;
    }
    let (h, w) = (inn.height, inn.width);
    let zero = Velocity::zero(h, w);
    let starts: Vec<u64> = ((mid - back)..(mid + ahead)).step_by(s as usize).collect();
    let frames: Vec<Array2<f32>> = starts
        .par_iter()
        .map(|&t| compensated(inn, t as f64 + s as f64 / 2.0, (t, s), &zero))
        .collect();
    let settings = DenseMode::Pyramid.settings();
    let flows: Vec<Flow> = (0..frames.len() - 1)
        .into_par_iter()
        .map(|i| dense_flow(&frames[i], &frames[i + 1], None, &settings))
        .collect();
    let n = flows.len();
    let k = 1.0 / (n as f32 * s as f32);
    let mut velocity = Velocity::zero(h, w);
    for f in &flows {
        velocity.u.zip_mut_with(&f.u, |m, &x| *m += x * k);
        velocity.v.zip_mut_with(&f.v, |m, &x| *m += x * k);
    }
    let mut field = Field::unmeasured(*grid);
    let nodes: Vec<(usize, usize)> = ndarray::indices((grid.ny, grid.nx)).into_iter().collect();
    let per_node: Vec<Node> = nodes
        .par_iter()
        .map(|&(r, c)| {
            let (x, y) = grid.centre(r, c);
            let looks: Vec<(f64, f64)> = flows.iter().map(|f| f.at(x, y)).collect();
            let (mean, se) = mean_and_error(&looks, s as f64);
            let m = flows
                .iter()
                .enumerate()
                .map(|(i, f)| matched(&frames[i], &frames[i + 1], f, grid, (r, c)))
                .sum::<f64>()
                / n as f64;
            Node { mean, se, m }
        })
        .collect();
    for (&(r, c), &Node { mean, se, m }) in nodes.iter().zip(&per_node) {
        field.u[[r, c]] = mean.0;
        field.v[[r, c]] = mean.1;
        field.peak_height[[r, c]] = m;
        if m >= MIN_MATCH && se.0.is_finite() && se.1.is_finite() {
            field.state[[r, c]] = State::Valid;
            field.sigma[[r, c]] = (SPREAD * se.0, SPREAD * se.1);
        }
    }
    Some(Ensemble {
        field,
        velocity,
        frames,
        centre: (back / s) as usize,
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
            let pa = f64::from(crate::piv::dense::sample(a, yf - 0.5 * v, xf - 0.5 * u));
            let pb = f64::from(crate::piv::dense::sample(b, yf + 0.5 * v, xf + 0.5 * u));
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
}
