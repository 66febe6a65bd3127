//! Predictor filtering between passes (Schrijer & Scarano 2008, "Effect
//! of predictor–corrector filtering on the stability and spatial
//! resolution of iterative PIV interrogation", Exp. Fluids 45:927).
//!
//! Each deformation pass reports the predictor at the window centre plus
//! the residual the window measures; an error of the predictor that
//! alternates from node to node is hardly seen by a window twice the grid
//! step, so it survives every pass and feeds the noise of the next one. In
//! a shear that noise grows with the shear times the window: synthetic
//! particle images in a linear shear of 0.065 px/px (64 → 32 × 4 px) kept
//! 0.085 px rms per vector unfiltered, 0.006 px filtered
//! (`host/tests/piv_accuracy.rs` holds shears to it). Filtering the
//! predictor — not the result — damps those modes: the binomial 1-2-1
//! along each grid axis removes the node-to-node alternation, reproduces
//! every linear field and leaves a smooth field's curvature for the
//! pass's own residual to measure.
//!
//! Only measured vectors (valid or replaced) are filtered and only from
//! measured neighbours; at the grid's edges and next to unmeasured vectors
//! the one-sided least-squares line through three nodes takes the place
//! of the centred stencil, so a linear field stays exact there too.

use ndarray::Axis;

use super::{Field, State};

/// `f` with the 1-2-1 filter applied along x, then along y, to its
/// measured vectors.
pub fn filtered(f: &Field) -> Field {
    let measured = f.state.mapv(|s| s != State::Invalid);
    let mut out = f.clone();
    for comp in [&mut out.u, &mut out.v] {
        for axis in [Axis(1), Axis(0)] {
            let src = comp.clone();
            for ((mut line, src), ok) in comp
                .lanes_mut(axis)
                .into_iter()
                .zip(src.lanes(axis))
                .zip(measured.lanes(axis))
            {
                let n = line.len();
                for k in 0..n {
                    if !ok[k] {
                        continue;
                    }
                    let at = |j: isize| -> Option<f64> {
                        let j = usize::try_from(j).ok()?;
                        (j < n && ok[j]).then(|| src[j])
                    };
                    let k = k as isize;
                    let c = src[k as usize];
                    line[k as usize] = match (at(k - 1), at(k + 1)) {
                        (Some(l), Some(r)) => 0.25 * (l + 2.0 * c + r),
                        (None, Some(r)) => match at(k + 2) {
                            Some(rr) => (5.0 * c + 2.0 * r - rr) / 6.0,
                            None => c,
                        },
                        (Some(l), None) => match at(k - 2) {
                            Some(ll) => (5.0 * c + 2.0 * l - ll) / 6.0,
                            None => c,
                        },
                        (None, None) => c,
                    };
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;
    use spiv_formats::grid::Grid;

    fn field(ny: usize, nx: usize, f: impl Fn(usize, usize) -> f64) -> Field {
        let grid = Grid::new(16 * nx + 16, 16 * ny + 16, 32, 16).expect("grid");
        assert_eq!((grid.ny, grid.nx), (ny, nx));
        Field {
            grid,
            u: Array2::from_shape_fn((ny, nx), |(r, c)| f(r, c)),
            v: Array2::from_shape_fn((ny, nx), |(r, c)| -f(r, c)),
            state: Array2::from_elem((ny, nx), State::Valid),
            peak_ratio: Array2::zeros((ny, nx)),
            peak_height: Array2::zeros((ny, nx)),
        }
    }

    #[test]
    fn linear_fields_pass_unchanged_up_to_the_edges() {
        let f = field(5, 7, |r, c| 0.3 * r as f64 - 1.1 * c as f64 + 2.0);
        let g = filtered(&f);
        for (a, b) in f.u.iter().zip(&g.u).chain(f.v.iter().zip(&g.v)) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn node_to_node_alternation_is_removed_inside() {
        let f = field(6, 6, |r, c| if (r + c) % 2 == 0 { 1.0 } else { -1.0 });
        let g = filtered(&f);
        for r in 1..5 {
            for c in 1..5 {
                assert!(g.u[[r, c]].abs() < 1e-12);
            }
        }
    }

    #[test]
    fn unmeasured_vectors_neither_move_nor_leak() {
        let mut f = field(5, 5, |_, _| 1.0);
        f.u[[2, 2]] = 0.0;
        f.v[[2, 2]] = 0.0;
        f.state[[2, 2]] = State::Invalid;
        let g = filtered(&f);
        assert_eq!(g.u[[2, 2]], 0.0);
        for (k, &x) in g.u.iter().enumerate() {
            if k != 12 {
                assert!((x - 1.0).abs() < 1e-12, "vector {k}: {x}");
            }
        }
    }
}
