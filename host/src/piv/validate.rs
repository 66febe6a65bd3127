//! Vector validation and replacement: the normalised median test
//! (Westerweel & Scarano 2005), the peak ratio, and replacement of rejected
//! vectors by the mean of their valid neighbours.

use ndarray::Array2;

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

fn median(v: &mut [f64]) -> f64 {
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

/// Up to 8 neighbour values on the stack (the test runs for every vector
/// of every pass: no allocation per vector).
#[derive(Default)]
struct Neighbours {
    v: [f64; 8],
    n: usize,
}

impl Neighbours {
    fn push(&mut self, x: f64) {
        if let Some(slot) = self.v.get_mut(self.n) {
            *slot = x;
            self.n += 1;
        }
    }

    fn values(&mut self) -> &mut [f64] {
        &mut self.v[..self.n]
    }
}

/// Marks `Valid` vectors that fail the normalised median test as
/// `Invalid`; returns how many. Each component is tested against the median
/// of its (up to 8) valid neighbours (beyond the grid's edge, linear
/// extrapolations of the two vectors inward); a vector with fewer than 2
/// valid neighbours is rejected as unsupported.
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
    let mut rejected = 0;
    let mut nu = Neighbours::default();
    let mut nv = Neighbours::default();
    for r in 0..ny {
        for c in 0..nx {
            if before[[r, c]] != State::Valid {
                continue;
            }
            (nu.n, nv.n) = (0, 0);
            for dr in -1isize..=1 {
                for dc in -1isize..=1 {
                    if dr == 0 && dc == 0 {
                        continue;
                    }
                    let (rr, cc) = (r as isize + dr, c as isize + dc);
                    let inside = |k: isize, n: usize| (0..n as isize).contains(&k);
                    if inside(rr, ny) && inside(cc, nx) {
                        let (rr, cc) = (rr as usize, cc as usize);
                        if before[[rr, cc]] == State::Valid {
                            nu.push(u[[rr, cc]]);
                            nv.push(v[[rr, cc]]);
                        }
                        continue;
                    }
                    // Beyond the edge: extrapolate linearly from the two
                    // vectors inward of the missing one (never the tested
                    // vector itself), so a gradient at the edge is not an
                    // outlier.
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
                    let (Some((r1, r2)), Some((c1, c2))) = (fold(rr, ny), fold(cc, nx)) else {
                        continue;
                    };
                    if (r1, c1) == (r, c) || (r2, c2) == (r, c) || r2 >= ny || c2 >= nx {
                        continue;
                    }
                    if before[[r1, c1]] == State::Valid && before[[r2, c2]] == State::Valid {
                        nu.push(2.0 * u[[r1, c1]] - u[[r2, c2]]);
                        nv.push(2.0 * v[[r1, c1]] - v[[r2, c2]]);
                    }
                }
            }
            if nu.n < 2 {
                // Unsupported: no neighbour agrees or disagrees. A lone
                // vector among rejected ones is as likely noise as not.
                state[[r, c]] = State::Invalid;
                rejected += 1;
                continue;
            }
            let mut fails = false;
            for (vals, x) in [(&mut nu, u[[r, c]]), (&mut nv, v[[r, c]])] {
                let vals = vals.values();
                let m = median(vals);
                let mut res = [0.0f64; 8];
                for (o, y) in res.iter_mut().zip(vals.iter()) {
                    *o = (y - m).abs();
                }
                let rm = median(&mut res[..vals.len()]);
                if (x - m).abs() / (rm + eps) > threshold {
                    fails = true;
                }
            }
            if fails {
                state[[r, c]] = State::Invalid;
                rejected += 1;
            }
        }
    }
    rejected
}

/// Replaces `Invalid` vectors whose `replaceable` entry is true by the mean
/// of their valid or replaced neighbours, growing inwards over up to
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
                let (mut su, mut sv, mut k) = (0.0, 0.0, 0usize);
                for rr in r.saturating_sub(1)..(r + 2).min(ny) {
                    for cc in c.saturating_sub(1)..(c + 2).min(nx) {
                        if state[[rr, cc]] != State::Invalid {
                            su += u[[rr, cc]];
                            sv += v[[rr, cc]];
                            k += 1;
                        }
                    }
                }
                if k > 0 {
                    changed.push((r, c, su / k as f64, sv / k as f64));
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

#[cfg(test)]
mod tests {
    use super::*;

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
        let u = Array2::from_shape_fn((6, 6), |(r, _)| 1.04 * r as f64);
        let v = Array2::zeros((6, 6));
        let mut st = Array2::from_elem((6, 6), State::Valid);
        median_test(&u, &v, &mut st, 2.0, 0.1);
        // Edges pass; a corner has too few neighbours to extrapolate and may
        // be replaced from them.
        for ((r, c), s) in st.indexed_iter() {
            let corner = (r == 0 || r == 5) && (c == 0 || c == 5);
            assert!(corner || *s == State::Valid, "({r},{c})");
        }
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
