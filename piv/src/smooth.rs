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
//! a one-sided stencil ([`Edge`]) takes the place of the centred one, so a
//! linear field stays exact there too.

use ndarray::Axis;

use super::{Field, State};

/// The one-sided stencil of [`filtered`] at the grid's edges (and next to
/// unmeasured vectors), where the centred 1-2-1 has no neighbour.
///
/// An edge window sees beyond the grid's last node, where the predictor is
/// extrapolated, so the pass's residual cannot correct what the filter
/// does to a curved field there. The line reads a curved profile's edge
/// node low by a sixth of its second difference. Next to a glare band,
/// where the spike frames show no particle within about 18 px of the wall,
/// that edge window sees only its upper half and keeps the bias
/// (`host/examples/wall_probe.rs`). The quadratic does not, but it damps
/// an edge alternation less (to 0.6, the line to 1/3), so the pairs that
/// predict the closed loop keep the line (`docs/results.md#the-constants-and-what-chose-them`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Edge {
    /// The least-squares line through three nodes, `(5·f0 + 2·f1 − f2)/6`:
    /// exact for linear fields.
    #[default]
    Line,
    /// The least-squares quadratic through four nodes, `(19·f0 + 3·f1 −
    /// 3·f2 + f3)/20`: exact for quadratic fields (a boundary layer's
    /// curvature). With only three measured nodes on that side, the node is
    /// kept as it is (the quadratic through them).
    Quadratic,
}

impl Edge {
    /// The filtered value of a node `c` whose measured neighbours lie on
    /// one side only, `side(d)` the one `d` nodes away (`None` where
    /// unmeasured or beyond the grid); `c` itself where the stencil lacks
    /// a node.
    fn one_sided(self, c: f64, side: impl Fn(isize) -> Option<f64>) -> f64 {
        match (self, side(1), side(2), side(3)) {
            (Edge::Line, Some(f1), Some(f2), _) => (5.0 * c + 2.0 * f1 - f2) / 6.0,
            (Edge::Quadratic, Some(f1), Some(f2), Some(f3)) => {
                (19.0 * c + 3.0 * f1 - 3.0 * f2 + f3) / 20.0
            }
            _ => c,
        }
    }
}

/// `f` with the 1-2-1 filter applied along x, then along y, to its
/// measured vectors, with the `edge` stencil where one side has no
/// measured neighbour.
pub fn filtered(f: &Field, edge: Edge) -> Field {
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
                        (None, Some(_)) => edge.one_sided(c, |d| at(k + d)),
                        (Some(_), None) => edge.one_sided(c, |d| at(k - d)),
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
            sigma: Array2::from_elem((ny, nx), (0.1, 0.1)),
        }
    }

    #[test]
    fn linear_fields_pass_unchanged_up_to_the_edges() {
        let f = field(5, 7, |r, c| 0.3 * r as f64 - 1.1 * c as f64 + 2.0);
        let g = filtered(&f, Edge::Line);
        for (a, b) in f.u.iter().zip(&g.u).chain(f.v.iter().zip(&g.v)) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn the_quadratic_edge_keeps_quadratic_fields_at_the_edges() {
        // A boundary layer's curvature along y, a smaller one along x.
        let f = field(6, 7, |r, c| {
            0.05 * (r * r) as f64 + 0.01 * (c * c) as f64 - 0.2 * c as f64
        });
        let g = filtered(&f, Edge::Quadratic);
        let (ny, nx) = f.u.dim();
        for r in [0, ny - 1] {
            for c in [0, nx - 1] {
                // One-sided along both axes: kept exactly.
                assert!(
                    (f.u[[r, c]] - g.u[[r, c]]).abs() < 1e-12,
                    "corner ({r}, {c})"
                );
            }
        }
        // Along the edge row the filter is one-sided in y, centred in x:
        // the centred stencil adds a quarter of the second difference
        // along x (0.02 · 0.25 = 0.005), nothing along y.
        for c in 1..nx - 1 {
            let d = g.u[[0, c]] - f.u[[0, c]];
            assert!((d - 0.005).abs() < 1e-12, "edge node {c}: {d}");
        }
        // The line reads the same corner low by a sixth of its second
        // differences along y (0.1) and along x (0.02).
        let l = filtered(&f, Edge::Line);
        let d = l.u[[0, 0]] - f.u[[0, 0]];
        assert!((d + (0.1 + 0.02) / 6.0).abs() < 1e-12, "{d}");
    }

    #[test]
    fn the_quadratic_edge_keeps_linear_fields_and_a_short_line() {
        let f = field(5, 7, |r, c| 0.3 * r as f64 - 1.1 * c as f64 + 2.0);
        let g = filtered(&f, Edge::Quadratic);
        for (a, b) in f.u.iter().zip(&g.u) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        // Three measured nodes along y: the quadratic through them is the
        // data, so the edge nodes stay.
        let f = field(3, 1, |r, _| [0.7, -0.4, 1.3][r]);
        let g = filtered(&f, Edge::Quadratic);
        assert_eq!((g.u[[0, 0]], g.u[[2, 0]]), (0.7, 1.3));
    }

    #[test]
    fn edge_alternation_is_damped_by_either_stencil() {
        let f = field(6, 6, |r, c| if (r + c) % 2 == 0 { 1.0 } else { -1.0 });
        // One-sided along both axes at a corner: 0.6 · 0.6 of it is left
        // by the quadratic, (1/3)² by the line.
        let q = filtered(&f, Edge::Quadratic).u[[0, 0]];
        let l = filtered(&f, Edge::Line).u[[0, 0]];
        assert!((q - 0.36).abs() < 1e-12, "{q}");
        assert!((l - 1.0 / 9.0).abs() < 1e-12, "{l}");
    }

    #[test]
    fn node_to_node_alternation_is_removed_inside() {
        let f = field(6, 6, |r, c| if (r + c) % 2 == 0 { 1.0 } else { -1.0 });
        let g = filtered(&f, Edge::Line);
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
        let g = filtered(&f, Edge::Line);
        assert_eq!(g.u[[2, 2]], 0.0);
        for (k, &x) in g.u.iter().enumerate() {
            if k != 12 {
                assert!((x - 1.0).abs() < 1e-12, "vector {k}: {x}");
            }
        }
    }
}
