//! Vector validation and replacement: the normalised median test
//! (Westerweel & Scarano 2005), the peak ratio, and replacement of rejected
//! vectors from their neighbours — the least-squares plane of the valid
//! ones, which is their mean inside the grid and follows a gradient at its
//! edges and corners.

use ndarray::Array2;
use rayon::prelude::*;

pub use spiv_formats::State;

/// Validation settings.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Validation {
    /// Normalised median test threshold (2 is the usual value; 0 disables).
    pub median_threshold: f64,
    /// The test's noise level ε, px (0.1 px for cross-correlation).
    pub median_eps: f64,
    /// Minimum peak ratio (1 disables).
    pub min_peak_ratio: f64,
}

impl Default for Validation {
    fn default() -> Self {
        Validation {
            median_threshold: 2.0,
            median_eps: 0.1,
            min_peak_ratio: 1.5,
        }
    }
}

/// The median of `v` (sorted in place), 0 when empty.
///
/// ```
/// use spiv_piv::validate::median;
/// assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
/// assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
/// assert_eq!(median(&mut []), 0.0);
/// ```
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_unstable_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return 0.0;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Up to 8 neighbours' entries on the stack (the test and the replacement
/// run for every vector of every pass: no allocation per vector).
#[derive(Default)]
struct Eight<T> {
    v: [T; 8],
    n: usize,
}

impl<T: Copy> Eight<T> {
    fn push(&mut self, x: T) {
        if let Some(slot) = self.v.get_mut(self.n) {
            *slot = x;
            self.n += 1;
        }
    }

    fn values(&mut self) -> &mut [T] {
        &mut self.v[..self.n]
    }

    fn as_slice(&self) -> &[T] {
        &self.v[..self.n]
    }
}

/// A neighbour's offset and vector: `(dr, dc, u, v)`.
type Point = (f64, f64, f64, f64);

/// The least-squares plane `a + b·dr + c·dc` of one component through
/// up to 8 neighbours around a vector. With the full symmetric ring of 8
/// neighbours its value at the centre is their mean; at an edge or a
/// corner, where the neighbours sit on one side, it follows a gradient
/// that the mean would pull towards the far side (a corner of a shear
/// replaced by the mean of its neighbours was off by 40 % of its row's
/// speed).
#[derive(Debug, Clone, Copy)]
struct Plane {
    a: f64,
    b: f64,
    c: f64,
}

impl Plane {
    /// The planes of u and of v through `pts` (one fit: the positions'
    /// moments serve both), or `None` when the points do not span a plane
    /// (fewer than 3, or all on one line).
    fn fit(pts: &[Point]) -> Option<(Plane, Plane)> {
        if pts.len() < 3 {
            return None;
        }
        let n = pts.len() as f64;
        let mean = |f: fn(&Point) -> f64| pts.iter().map(f).sum::<f64>() / n;
        let (mr, mc) = (mean(|p| p.0), mean(|p| p.1));
        let (mu, mv) = (mean(|p| p.2), mean(|p| p.3));
        // Centred second moments of the positions, and with the values.
        let (mut crr, mut ccc, mut crc) = (0.0, 0.0, 0.0);
        let (mut cru, mut ccu, mut crv, mut ccv) = (0.0, 0.0, 0.0, 0.0);
        for &(r, c, u, v) in pts {
            let (r, c, u, v) = (r - mr, c - mc, u - mu, v - mv);
            crr += r * r;
            ccc += c * c;
            crc += r * c;
            cru += r * u;
            ccu += c * u;
            crv += r * v;
            ccv += c * v;
        }
        let det = crr * ccc - crc * crc;
        // Offsets are small integers: the moments are multiples of 1/n²,
        // so a determinant this small means the points lie on one line,
        // which leaves the slope across it open.
        if det <= 1e-9 {
            return None;
        }
        let plane = |m: f64, cr: f64, cc: f64| {
            let (b, c) = ((ccc * cr - crc * cc) / det, (crr * cc - crc * cr) / det);
            Plane {
                a: m - b * mr - c * mc,
                b,
                c,
            }
        };
        Some((plane(mu, cru, ccu), plane(mv, crv, ccv)))
    }

    fn at(&self, dr: f64, dc: f64) -> f64 {
        self.a + self.b * dr + self.c * dc
    }
}

/// Marks `Valid` vectors that fail the normalised median test as
/// `Invalid`; returns how many. Each component is tested against the median
/// of its (up to 8) valid neighbours (beyond the grid's edge, linear
/// extrapolations of the two vectors inward; at a corner, where that line
/// would run through the tested vector, the plane of its valid
/// neighbours); a vector with fewer than 2 valid neighbours is rejected as
/// unsupported.
pub fn median_test(
    u: &Array2<f64>,
    v: &Array2<f64>,
    state: &mut Array2<State>,
    threshold: f64,
    eps: f64,
) -> usize {
    if threshold <= 0.0 {
        return 0;
    }
    let (ny, nx) = u.dim();
    let before = state.clone();
    // Rows in parallel: each reads only `before`.
    let failed: Vec<Vec<usize>> = (0..ny)
        .into_par_iter()
        .map(|r| {
            let mut nu = Eight::<f64>::default();
            let mut nv = Eight::<f64>::default();
            (0..nx)
                .filter(|&c| {
                    if before[[r, c]] != State::Valid {
                        return false;
                    }
                    neighbours(u, v, &before, (r, c), (&mut nu, &mut nv));
                    // Unsupported (fewer than 2 neighbours): no neighbour
                    // agrees or disagrees, and a lone vector among rejected
                    // ones is as likely noise as not.
                    nu.n < 2
                        || [(&mut nu, u[[r, c]]), (&mut nv, v[[r, c]])]
                            .into_iter()
                            .any(|(vals, x)| normalised_residual(vals.values(), x, eps) > threshold)
                })
                .collect()
        })
        .collect();
    let mut rejected = 0;
    for (r, cols) in failed.into_iter().enumerate() {
        for c in cols {
            state[[r, c]] = State::Invalid;
            rejected += 1;
        }
    }
    rejected
}

/// The normalised median residual of `x` against its neighbours `vals`
/// (at most 8, at least 1; reordered): |x − median| over the median of
/// the neighbours' own residuals plus `eps`.
fn normalised_residual(vals: &mut [f64], x: f64, eps: f64) -> f64 {
    let m = median(vals);
    let mut res = [0.0f64; 8];
    for (o, y) in res.iter_mut().zip(vals.iter()) {
        *o = (y - m).abs();
    }
    let rm = median(&mut res[..vals.len()]);
    (x - m).abs() / (rm + eps)
}

/// The neighbours of (r, c) that the median test compares it with, into
/// `nu`, `nv`: its valid neighbours; beyond the grid's edge, the linear
/// extrapolation of the two vectors inward of the missing one (never the
/// tested vector itself), so a gradient at the edge is not an outlier; at
/// a corner, where that line would run through the tested vector, the
/// plane of its valid neighbours, so a gradient is not an outlier there
/// either.
fn neighbours(
    u: &Array2<f64>,
    v: &Array2<f64>,
    before: &Array2<State>,
    (r, c): (usize, usize),
    (nu, nv): (&mut Eight<f64>, &mut Eight<f64>),
) {
    let (ny, nx) = u.dim();
    (nu.n, nv.n) = (0, 0);
    let inside = |k: isize, n: usize| (0..n as isize).contains(&k);
    // Rows or columns (k, 2k − inward) of an extrapolation.
    let fold = |k: isize, n: usize| -> Option<(usize, usize)> {
        if inside(k, n) {
            Some((k as usize, k as usize))
        } else if n >= 2 {
            let near = k.clamp(0, n as isize - 1);
            Some((near as usize, (2 * near - k) as usize))
        } else {
            None
        }
    };
    let mut planes: Option<Option<(Plane, Plane)>> = None;
    for (dr, dc) in (-1isize..=1).flat_map(|dr| (-1isize..=1).map(move |dc| (dr, dc))) {
        if dr == 0 && dc == 0 {
            continue;
        }
        let (rr, cc) = (r as isize + dr, c as isize + dc);
        if inside(rr, ny) && inside(cc, nx) {
            let (rr, cc) = (rr as usize, cc as usize);
            if before[[rr, cc]] == State::Valid {
                nu.push(u[[rr, cc]]);
                nv.push(v[[rr, cc]]);
            }
            continue;
        }
        let (Some((r1, r2)), Some((c1, c2))) = (fold(rr, ny), fold(cc, nx)) else {
            continue;
        };
        if (r1, c1) == (r, c) || (r2, c2) == (r, c) || r2 >= ny || c2 >= nx {
            if let Some((pu, pv)) =
                planes.get_or_insert_with(|| neighbour_planes(u, v, before, r, c))
            {
                nu.push(pu.at(dr as f64, dc as f64));
                nv.push(pv.at(dr as f64, dc as f64));
            }
            continue;
        }
        if before[[r1, c1]] == State::Valid && before[[r2, c2]] == State::Valid {
            nu.push(2.0 * u[[r1, c1]] - u[[r2, c2]]);
            nv.push(2.0 * v[[r1, c1]] - v[[r2, c2]]);
        }
    }
}

/// The planes (u, v) through the neighbours of (r, c) that `state` calls
/// valid, when they span one.
fn neighbour_planes(
    u: &Array2<f64>,
    v: &Array2<f64>,
    state: &Array2<State>,
    r: usize,
    c: usize,
) -> Option<(Plane, Plane)> {
    Plane::fit(ring(u, v, r, c, |rr, cc| state[[rr, cc]] == State::Valid).as_slice())
}

/// The 3 × 3 ring around (r, c) that `keep` admits.
fn ring(
    u: &Array2<f64>,
    v: &Array2<f64>,
    r: usize,
    c: usize,
    keep: impl Fn(usize, usize) -> bool,
) -> Eight<Point> {
    let (ny, nx) = u.dim();
    let mut pts = Eight::default();
    for rr in r.saturating_sub(1)..(r + 2).min(ny) {
        for cc in c.saturating_sub(1)..(c + 2).min(nx) {
            if (rr, cc) != (r, c) && keep(rr, cc) {
                let (dr, dc) = (rr as f64 - r as f64, cc as f64 - c as f64);
                pts.push((dr, dc, u[[rr, cc]], v[[rr, cc]]));
            }
        }
    }
    pts
}

/// The replacement of (r, c) from its neighbours: the plane of the valid
/// ones at the centre, or else the mean of the measured (valid or
/// replaced) ones; `None` without any.
fn neighbour_fit(
    u: &Array2<f64>,
    v: &Array2<f64>,
    state: &Array2<State>,
    r: usize,
    c: usize,
) -> Option<(f64, f64)> {
    // The plane only through measured (valid) neighbours: through
    // replaced ones, sweep after sweep, it would extrapolate its own
    // extrapolations into a large hole.
    if let Some((pu, pv)) = neighbour_planes(u, v, state, r, c) {
        return Some((pu.a, pv.a));
    }
    let pts = ring(u, v, r, c, |rr, cc| state[[rr, cc]] != State::Invalid);
    let pts = pts.as_slice();
    if pts.is_empty() {
        return None;
    }
    let n = pts.len() as f64;
    let sum = pts.iter().fold((0.0, 0.0), |s, p| (s.0 + p.2, s.1 + p.3));
    Some((sum.0 / n, sum.1 / n))
}

/// Replaces `Invalid` vectors whose `replaceable` entry is true from their
/// neighbours (the least-squares plane of the valid ones at the vector,
/// or else the mean of the valid and replaced ones), growing inwards over up to
/// `iterations` sweeps; they become `Replaced`. Others keep u = v = 0.
pub fn replace(
    u: &mut Array2<f64>,
    v: &mut Array2<f64>,
    state: &mut Array2<State>,
    replaceable: &Array2<bool>,
    iterations: usize,
) {
    let (ny, nx) = u.dim();
    for _ in 0..iterations {
        let mut changed = Vec::new();
        for r in 0..ny {
            for c in 0..nx {
                if state[[r, c]] != State::Invalid || !replaceable[[r, c]] {
                    continue;
                }
                if let Some((pu, pv)) = neighbour_fit(u, v, state, r, c) {
                    changed.push((r, c, pu, pv));
                }
            }
        }
        if changed.is_empty() {
            break;
        }
        for (r, c, a, b) in changed {
            u[[r, c]] = a;
            v[[r, c]] = b;
            state[[r, c]] = State::Replaced;
        }
    }
    for ((s, a), b) in state.iter().zip(u.iter_mut()).zip(v.iter_mut()) {
        if *s == State::Invalid {
            *a = 0.0;
            *b = 0.0;
        }
    }
}

/// The uncertainty of every replaced vector, px, from its neighbours: the
/// root of the mean of their squared uncertainties plus the spread of their
/// values about the replacement (what a neighbour fit cannot know of the
/// window itself), over the measured vectors of its 3 × 3 neighbourhood,
/// plus, where they all lie on one side of it, the field's change over
/// the next step outwards (`extrapolation`); infinite where it has none. Invalid vectors get infinite uncertainty;
/// valid ones keep theirs.
pub fn replaced_uncertainty(
    u: &Array2<f64>,
    v: &Array2<f64>,
    state: &Array2<State>,
    sigma: &mut Array2<(f64, f64)>,
) {
    let (ny, nx) = u.dim();
    let mut out = sigma.clone();
    for r in 0..ny {
        for c in 0..nx {
            match state[[r, c]] {
                State::Valid => continue,
                State::Invalid => {
                    out[[r, c]] = (f64::INFINITY, f64::INFINITY);
                    continue;
                }
                State::Replaced => {}
            }
            let (mut n, mut su, mut sv) = (0usize, 0.0f64, 0.0f64);
            let mut sides = Vec::with_capacity(8);
            for rr in r.saturating_sub(1)..(r + 2).min(ny) {
                for cc in c.saturating_sub(1)..(c + 2).min(nx) {
                    if (rr, cc) == (r, c) || state[[rr, cc]] != State::Valid {
                        continue;
                    }
                    let (a, b) = sigma[[rr, cc]];
                    if !(a.is_finite() && b.is_finite()) {
                        continue;
                    }
                    n += 1;
                    su += a * a + (u[[rr, cc]] - u[[r, c]]).powi(2);
                    sv += b * b + (v[[rr, cc]] - v[[r, c]]).powi(2);
                    sides.push((rr as isize - r as isize, cc as isize - c as isize));
                }
            }
            let (eu, ev) = if surrounded(&sides) {
                (0.0, 0.0)
            } else {
                extrapolation(u, v, state, (r, c), &sides)
            };
            out[[r, c]] = if n == 0 {
                (f64::INFINITY, f64::INFINITY)
            } else {
                ((su / n as f64 + eu).sqrt(), (sv / n as f64 + ev).sqrt())
            };
        }
    }
    *sigma = out;
}

/// Whether neighbours at the offsets `sides` (row, column) lie on both
/// sides of their node along some line through it: a fill between them
/// interpolates.
fn surrounded(sides: &[(isize, isize)]) -> bool {
    sides.iter().any(|&(dr, dc)| sides.contains(&(-dr, -dc)))
}

/// The squared change of the field over one step just beyond a one-sided
/// node's valid neighbours (at `sides`), going away from it: the mean,
/// over each neighbour whose next node outwards is valid, of the squared
/// difference between them. A fill from one side extrapolates, and can be
/// off by as much as the field changes over a step there (a vortex's edge
/// filled from its inside), which the neighbours' spread about the fill
/// does not show.
fn extrapolation(
    u: &Array2<f64>,
    v: &Array2<f64>,
    state: &Array2<State>,
    (r, c): (usize, usize),
    sides: &[(isize, isize)],
) -> (f64, f64) {
    let (ny, nx) = u.dim();
    let (mut n, mut su, mut sv) = (0usize, 0.0f64, 0.0f64);
    for &(dr, dc) in sides {
        let (r1, c1) = (r as isize + dr, c as isize + dc);
        let (r2, c2) = (r1 + dr, c1 + dc);
        if r2 < 0 || c2 < 0 || r2 >= ny as isize || c2 >= nx as isize {
            continue;
        }
        let (a, b) = ((r1 as usize, c1 as usize), (r2 as usize, c2 as usize));
        if state[b] != State::Valid {
            continue;
        }
        n += 1;
        su += (u[a] - u[b]).powi(2);
        sv += (v[a] - v[b]).powi(2);
    }
    if n == 0 {
        (0.0, 0.0)
    } else {
        (su / n as f64, sv / n as f64)
    }
}

/// `u`, `v` with every vector that was not measured (invalid, including
/// windows without signal: masked, clipped, empty) filled from the
/// measured ones as [`replace`] fills, growing outwards until none is
/// left: the field a predictor interpolates between window centres. Left
/// at zero, such a vector would pull the predictor of its measured
/// neighbours towards zero over a whole grid step (a window beside a mask
/// was measured 0.4–0.55 px short in a 2.3 px shift). A hole with a rim
/// all round is then relaxed to the harmonic fill of its rim (`relax`):
/// growing inwards from every side, the fronts meet in a seam (a 6 × 7
/// hole in a linear shear of 1 px per node row was filled with a 4 px
/// step across its middle). All zero when nothing was measured.
pub fn extended(
    u: &Array2<f64>,
    v: &Array2<f64>,
    state: &Array2<State>,
) -> (Array2<f64>, Array2<f64>) {
    let (mut u, mut v, mut st) = (u.clone(), v.clone(), state.clone());
    let (ny, nx) = u.dim();
    replace(
        &mut u,
        &mut v,
        &mut st,
        &Array2::from_elem((ny, nx), true),
        ny + nx,
    );
    let free = enclosed(state);
    if free.iter().any(|&f| f) {
        relax(&mut u, &free);
        relax(&mut v, &free);
    }
    (u, v)
}

/// The invalid nodes of holes that do not reach the grid's border
/// (4-connected): a hole with a rim all round.
fn enclosed(state: &Array2<State>) -> Array2<bool> {
    let (ny, nx) = state.dim();
    let hole = |r: usize, c: usize| state[[r, c]] == State::Invalid;
    // Flood from the invalid border nodes: what it reaches is open.
    let mut open = Array2::from_elem((ny, nx), false);
    let mut stack: Vec<(usize, usize)> = ndarray::indices((ny, nx))
        .into_iter()
        .filter(|&(r, c)| (r == 0 || c == 0 || r + 1 == ny || c + 1 == nx) && hole(r, c))
        .collect();
    while let Some((r, c)) = stack.pop() {
        if open[[r, c]] {
            continue;
        }
        open[[r, c]] = true;
        for (rr, cc) in [
            (r.wrapping_sub(1), c),
            (r + 1, c),
            (r, c.wrapping_sub(1)),
            (r, c + 1),
        ] {
            if rr < ny && cc < nx && hole(rr, cc) && !open[[rr, cc]] {
                stack.push((rr, cc));
            }
        }
    }
    Array2::from_shape_fn((ny, nx), |(r, c)| hole(r, c) && !open[[r, c]])
}

/// Relaxes the `free` nodes of `f` (enclosed: each has four neighbours)
/// to the mean of their four neighbours, the others held (Gauss–Seidel):
/// the harmonic fill of each hole from its rim, exact for a field linear
/// in x and y and, by the maximum principle, within the rim's values.
/// Sweeps stop when no node moves by more than 1e-9 of the field's
/// largest value, or after 64 per node of the grid's longer side.
fn relax(f: &mut Array2<f64>, free: &Array2<bool>) {
    let (ny, nx) = f.dim();
    let range = f.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-12);
    for _ in 0..64 * ny.max(nx) {
        let mut moved = 0.0f64;
        for (r, c) in ndarray::indices((ny, nx)) {
            if !free[[r, c]] || r == 0 || c == 0 || r + 1 == ny || c + 1 == nx {
                continue;
            }
            let new = 0.25 * (f[[r - 1, c]] + f[[r + 1, c]] + f[[r, c - 1]] + f[[r, c + 1]]);
            moved = moved.max((new - f[[r, c]]).abs());
            f[[r, c]] = new;
        }
        if moved <= 1e-9 * range {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wide hole in a linear shear is filled with the shear, not with
    /// the rim's values carried inwards to a seam.
    #[test]
    fn a_wide_hole_is_filled_without_a_seam() {
        let (ny, nx) = (15, 25);
        let u = Array2::from_shape_fn((ny, nx), |(r, c)| 15.0 - r as f64 + 0.1 * c as f64);
        let v = Array2::from_elem((ny, nx), 0.5);
        let mut st = Array2::from_elem((ny, nx), State::Valid);
        let mut holed = u.clone();
        for r in 3..9 {
            for c in 9..15 {
                st[[r, c]] = State::Invalid;
                holed[[r, c]] = 0.0;
            }
        }
        let (eu, ev) = extended(&holed, &v, &st);
        for (idx, &x) in eu.indexed_iter() {
            assert!((x - u[idx]).abs() < 1e-6, "{idx:?}: {x} against {}", u[idx]);
        }
        assert!(ev.iter().all(|&x| (x - 0.5).abs() < 1e-9));
        // A hole open to the border (the bottom rows) keeps the
        // neighbours' fill: within the values around it.
        let mut st = Array2::from_elem((ny, nx), State::Valid);
        for r in 11..ny {
            for c in 0..nx {
                st[[r, c]] = State::Invalid;
            }
        }
        let (eu, _) = extended(&u, &v, &st);
        assert!(eu.iter().all(|&x| (0.0..=17.5).contains(&x)), "{eu:?}");
    }

    #[test]
    fn an_outlier_is_found_and_replaced() {
        let mut u = Array2::from_elem((5, 5), 2.0);
        let mut v = Array2::from_elem((5, 5), -1.0);
        u[[2, 2]] = 9.0;
        let mut st = Array2::from_elem((5, 5), State::Valid);
        assert_eq!(median_test(&u, &v, &mut st, 2.0, 0.1), 1);
        assert_eq!(st[[2, 2]], State::Invalid);
        replace(&mut u, &mut v, &mut st, &Array2::from_elem((5, 5), true), 3);
        assert_eq!(st[[2, 2]], State::Replaced);
        assert!((u[[2, 2]] - 2.0).abs() < 1e-12 && (v[[2, 2]] + 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_gradient_at_the_edge_is_not_an_outlier() {
        // Along the rows, along the columns and along a diagonal: edges and
        // corners pass (a corner's outward lines run through itself; the
        // plane of its neighbours stands in for them).
        let fields: [fn(usize, usize) -> f64; 3] = [
            |r, _| 1.04 * r as f64,
            |_, c| -0.7 * c as f64,
            |r, c| 0.9 * r as f64 + 0.6 * c as f64,
        ];
        for f in fields {
            let u = Array2::from_shape_fn((6, 6), |(r, c)| f(r, c));
            let v = Array2::from_shape_fn((6, 6), |(r, c)| 0.5 * f(c, r));
            let mut st = Array2::from_elem((6, 6), State::Valid);
            assert_eq!(median_test(&u, &v, &mut st, 2.0, 0.1), 0);
        }
    }

    #[test]
    fn an_outlier_in_a_corner_of_a_gradient_is_found() {
        let mut u = Array2::from_shape_fn((6, 6), |(r, _)| 1.04 * r as f64);
        let v = Array2::zeros((6, 6));
        u[[5, 0]] += 3.0;
        let mut st = Array2::from_elem((6, 6), State::Valid);
        assert_eq!(median_test(&u, &v, &mut st, 2.0, 0.1), 1);
        assert_eq!(st[[5, 0]], State::Invalid);
    }

    #[test]
    fn replacement_follows_a_gradient_at_edges_and_corners() {
        // A linear field with its corners, an edge vector and an interior
        // one rejected: each comes back exactly (the mean of a corner's
        // neighbours would be 0.9·0.6 + … off).
        let f = |r: usize, c: usize| 0.9 * r as f64 - 0.6 * c as f64 + 2.0;
        let (mut u, mut v) = (
            Array2::from_shape_fn((5, 6), |(r, c)| f(r, c)),
            Array2::from_shape_fn((5, 6), |(r, c)| -f(r, c)),
        );
        let mut st = Array2::from_elem((5, 6), State::Valid);
        let holes = [(0, 0), (4, 5), (0, 5), (4, 0), (2, 0), (2, 3)];
        for &(r, c) in &holes {
            st[[r, c]] = State::Invalid;
            u[[r, c]] = 99.0;
            v[[r, c]] = -99.0;
        }
        replace(&mut u, &mut v, &mut st, &Array2::from_elem((5, 6), true), 1);
        for &(r, c) in &holes {
            assert_eq!(st[[r, c]], State::Replaced);
            assert!(
                (u[[r, c]] - f(r, c)).abs() < 1e-9,
                "({r},{c}): {}",
                u[[r, c]]
            );
            assert!(
                (v[[r, c]] + f(r, c)).abs() < 1e-9,
                "({r},{c}): {}",
                v[[r, c]]
            );
        }
    }

    #[test]
    fn an_interior_replacement_is_the_mean_of_its_ring() {
        let mut u = Array2::from_shape_fn((3, 3), |(r, c)| ((r * 7 + c * 3) % 5) as f64);
        let mut v = u.clone();
        let mut st = Array2::from_elem((3, 3), State::Valid);
        st[[1, 1]] = State::Invalid;
        let mean = (u.sum() - u[[1, 1]]) / 8.0;
        replace(&mut u, &mut v, &mut st, &Array2::from_elem((3, 3), true), 1);
        assert!((u[[1, 1]] - mean).abs() < 1e-12 && (v[[1, 1]] - mean).abs() < 1e-12);
    }

    #[test]
    fn a_large_hole_is_not_filled_by_extrapolating_replacements() {
        // A gradient along the columns, valid in the first two rows only,
        // ten rows rejected below: every row is replaced within the valid
        // vectors' range (planes only through valid vectors; replaced ones
        // give means), not extended column by column sweep after sweep.
        let mut u = Array2::from_shape_fn((12, 5), |(_, c)| c as f64);
        let mut v = Array2::zeros((12, 5));
        let mut st = Array2::from_elem((12, 5), State::Invalid);
        for c in 0..5 {
            st[[0, c]] = State::Valid;
            st[[1, c]] = State::Valid;
        }
        for r in 2..12 {
            for c in 0..5 {
                u[[r, c]] = 50.0;
            }
        }
        replace(
            &mut u,
            &mut v,
            &mut st,
            &Array2::from_elem((12, 5), true),
            10,
        );
        assert!(u.iter().all(|&x| (0.0..=4.0 + 1e-9).contains(&x)), "{u:?}");
        assert!(st.iter().all(|s| *s != State::Invalid));
    }

    #[test]
    fn the_predictor_field_extends_over_unmeasured_windows() {
        // The two left columns had no signal (a mask): for the predictor
        // they take their measured neighbours' values instead of zeros (a
        // column of neighbours tells nothing of the gradient across it, so
        // they are carried over, not extrapolated); the field itself keeps
        // them invalid at zero. Nothing measured: all zero.
        let f = |_: usize, c: usize| 2.0 + 0.25 * c as f64;
        let mut u = Array2::from_shape_fn((4, 6), |(r, c)| f(r, c));
        let v = Array2::from_elem((4, 6), -1.0);
        let mut st = Array2::from_elem((4, 6), State::Valid);
        for r in 0..4 {
            for c in 0..2 {
                st[[r, c]] = State::Invalid;
                u[[r, c]] = 0.0;
            }
        }
        let (eu, ev) = extended(&u, &v, &st);
        for r in 0..4 {
            assert!((eu[[r, 1]] - f(r, 2)).abs() < 1e-9, "{}", eu[[r, 1]]);
            assert!((eu[[r, 0]] - f(r, 2)).abs() < 1e-9, "{}", eu[[r, 0]]);
            assert!((ev[[r, 0]] + 1.0).abs() < 1e-9);
            assert_eq!((u[[r, 0]], st[[r, 0]]), (0.0, State::Invalid));
        }
        let none = Array2::from_elem((4, 6), State::Invalid);
        let (eu, _) = extended(&Array2::zeros((4, 6)), &v, &none);
        assert!(eu.iter().all(|&x| x == 0.0));
    }

    /// A 3 × 4 field whose u is `col(c)` down every column, σ 0.1,
    /// the last column replaced from its valid neighbours.
    fn filled_edge(col: impl Fn(usize) -> f64) -> Array2<(f64, f64)> {
        let u = Array2::from_shape_fn((3, 4), |(_, c)| col(c));
        let v = Array2::zeros((3, 4));
        let mut state = Array2::from_elem((3, 4), State::Valid);
        let mut sigma = Array2::from_elem((3, 4), (0.1, 0.1));
        for r in 0..3 {
            state[[r, 3]] = State::Replaced;
            sigma[[r, 3]] = (0.0, 0.0);
        }
        // The fill: the inside column's value, as a mean of one side gives.
        let mut u = u;
        for r in 0..3 {
            u[[r, 3]] = u[[r, 2]];
        }
        replaced_uncertainty(&u, &v, &state, &mut sigma);
        sigma
    }

    #[test]
    fn a_fill_from_one_side_carries_the_change_over_the_next_step() {
        // u changes by 2 px from the second column to the third: a fill of
        // the fourth from the third alone may be off by that much.
        let sigma = filled_edge(|c| if c < 2 { 0.0 } else { 2.0 });
        let (su, sv) = sigma[[1, 3]];
        assert!((su - (0.01f64 + 4.0).sqrt()).abs() < 1e-12, "{su}");
        assert!((sv - 0.1).abs() < 1e-12, "{sv}");
        // A uniform field beyond it adds nothing.
        let (su, _) = filled_edge(|_| 1.0)[[1, 3]];
        assert!((su - 0.1).abs() < 1e-12, "{su}");
    }

    #[test]
    fn a_fill_between_neighbours_interpolates() {
        let u = Array2::from_shape_fn((3, 3), |(_, c)| [0.0, 1.0, 5.0][c]);
        let v = Array2::zeros((3, 3));
        let mut state = Array2::from_elem((3, 3), State::Valid);
        state[[1, 1]] = State::Replaced;
        let mut sigma = Array2::from_elem((3, 3), (0.0, 0.0));
        replaced_uncertainty(&u, &v, &state, &mut sigma);
        // Neighbours on both sides: only their spread about the fill (1),
        // none of the change beyond them.
        let spread = ((3.0 * 1.0 + 3.0 * 16.0 + 2.0 * 0.0) / 8.0f64).sqrt();
        assert!(
            (sigma[[1, 1]].0 - spread).abs() < 1e-12,
            "{:?}",
            sigma[[1, 1]]
        );
    }

    #[test]
    fn nothing_to_replace_from_stays_invalid_and_zero() {
        let mut u = Array2::from_elem((2, 2), 5.0);
        let mut lone = Array2::from_elem((2, 2), State::Invalid);
        lone[[0, 0]] = State::Valid;
        assert_eq!(median_test(&u, &u, &mut lone, 2.0, 0.1), 1, "unsupported");
        let mut v = Array2::from_elem((2, 2), 5.0);
        let mut st = Array2::from_elem((2, 2), State::Invalid);
        replace(&mut u, &mut v, &mut st, &Array2::from_elem((2, 2), true), 3);
        assert!(st.iter().all(|s| *s == State::Invalid));
        assert!(u.iter().chain(v.iter()).all(|x| *x == 0.0));
    }
}
