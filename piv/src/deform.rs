//! Image deformation between passes: the displacement field of the previous
//! pass, interpolated to every pixel ([`dense`]), moves image A back and
//! image B forward by half of it (central difference, [`deform`]), so the
//! next pass correlates what is left. The images are sampled by
//! [`super::resample`].

use std::borrow::Cow;

use ndarray::{Array2, Axis};
use rayon::prelude::*;

use super::resample::{row_pair, Resampler};
use spiv_formats::grid::Grid;

/// The field of `grid` (`u`, `v` at window centres) at every pixel of an
/// `h × w` image: Catmull-Rom between centres (separable, 4 × 4 nodes),
/// over a grid extended by two linearly extrapolated nodes on each side,
/// positions clamped one node beyond the outer centres.
pub fn dense(
    grid: &Grid,
    u: &Array2<f64>,
    v: &Array2<f64>,
    h: usize,
    w: usize,
) -> (Array2<f32>, Array2<f32>) {
    let d = Dense::new(grid, u, v, (h, w));
    let mut du = Array2::<f32>::zeros((h, w));
    let mut dv = Array2::<f32>::zeros((h, w));
    du.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(dv.axis_iter_mut(Axis(0)))
        .enumerate()
        .for_each(|(i, (mut ru, mut rv))| {
            if let (Some(ru), Some(rv)) = (ru.as_slice_mut(), rv.as_slice_mut()) {
                d.row(i, ru, rv);
            }
        });
    (du, dv)
}

/// [`dense`] one row at a time, for whoever needs a row rather than the
/// whole image (the deformation computes each row where it uses it).
#[derive(Debug, Clone)]
pub struct Dense {
    grid: Grid,
    u: Array2<f64>,
    v: Array2<f64>,
    /// Image height and width, px.
    size: (usize, usize),
    /// Every pixel column's four tap weights into the extended grid row
    /// (the same for every row), one array per tap, so that the loop over
    /// a segment's pixels vectorises.
    weights: [Vec<f32>; 4],
    /// Columns sharing their taps: (first tap, first column, end column).
    segments: Vec<(usize, usize, usize)>,
}

impl Dense {
    /// The interpolation of `u`, `v` on `grid` over an image of `(h, w)` px.
    pub fn new(grid: &Grid, u: &Array2<f64>, v: &Array2<f64>, (h, w): (usize, usize)) -> Dense {
        let mut weights: [Vec<f32>; 4] = Default::default();
        let mut segments: Vec<(usize, usize, usize)> = Vec::new();
        for j in 0..w {
            let p = position(grid, j, grid.nx);
            let kf = p.floor();
            let k = (kf as isize + 1) as usize;
            for (wv, c) in weights.iter_mut().zip(catmull_rom(p - kf)) {
                wv.push(c as f32);
            }
            match segments.last_mut() {
                Some(seg) if seg.0 == k => seg.2 = j + 1,
                _ => segments.push((k, j, j + 1)),
            }
        }
        Dense {
            grid: *grid,
            u: u.clone(),
            v: v.clone(),
            size: (h, w),
            weights,
            segments,
        }
    }

    /// Row `i` of the field into `ru`, `rv` (`w` long).
    pub fn row(&self, i: usize, ru: &mut [f32], rv: &mut [f32]) {
        // Along y for every grid column (the position's whole part and
        // fraction found once for the row), then along x.
        let ny = self.grid.ny;
        let y = Position::at(position(&self.grid, i, ny));
        let blend = |f: &Array2<f64>| -> Vec<f64> {
            let mut e = Vec::with_capacity(f.ncols() + 5);
            e.extend([0.0, 0.0]);
            y.cubic_rows(f, &mut e);
            extend_in_place(&mut e);
            e
        };
        let (bu, bv) = (blend(&self.u), blend(&self.v));
        for (out, nodes) in [(ru, &bu), (rv, &bv)] {
            for &(k, j0, j1) in &self.segments {
                let Some(o) = out.get_mut(j0..j1) else {
                    continue;
                };
                let a = match nodes.get(k..k + 4) {
                    Some(&[a0, a1, a2, a3]) => [a0 as f32, a1 as f32, a2 as f32, a3 as f32],
                    _ => {
                        o.fill(0.0);
                        continue;
                    }
                };
                let n = o.len();
                let [w0, w1, w2, w3] = &self.weights;
                let (w0, w1, w2, w3) = (
                    &w0[j0..j0 + n],
                    &w1[j0..j0 + n],
                    &w2[j0..j0 + n],
                    &w3[j0..j0 + n],
                );
                // Indexed over equal lengths, so that it vectorises.
                for j in 0..n {
                    o[j] = w0[j] * a[0] + w1[j] * a[1] + w2[j] * a[2] + w3[j] * a[3];
                }
            }
        }
    }

    /// Image height and width, px.
    pub fn size(&self) -> (usize, usize) {
        self.size
    }
}

/// Pixel `p`'s position on a grid axis of `n` nodes, in nodes, clamped
/// one node beyond the outer centres.
fn position(grid: &Grid, p: usize, n: usize) -> f64 {
    let (first, step) = ((grid.size as f64 - 1.0) / 2.0, grid.step as f64);
    ((p as f64 - first) / step).clamp(-1.0, n as f64)
}

/// The row in `e` (after two places) with two linearly extrapolated
/// values on each side (index 2 is node 0): the two places are filled and
/// three values appended.
fn extend_in_place(e: &mut Vec<f64>) {
    let n = e.len() - 2;
    let row = &e[2..];
    let (d0, d1) = if n >= 2 {
        (row[1] - row[0], row[n - 1] - row[n - 2])
    } else {
        (0.0, 0.0)
    };
    let (first, last) = (row[0], row[n - 1]);
    e[0] = first - 2.0 * d0;
    e[1] = first - d0;
    e.extend([last + d1, last + 2.0 * d1, last + 3.0 * d1]);
}

/// A position on a grid axis split into its whole part and fraction, for
/// [`Position::cubic`] along many lines at the same position.
#[derive(Debug, Clone, Copy)]
struct Position {
    k: isize,
    t: f64,
    t2: f64,
    t3: f64,
}

impl Position {
    fn at(p: f64) -> Position {
        let k0 = p.floor();
        let t = p - k0;
        let t2 = t * t;
        Position {
            k: k0 as isize,
            t,
            t2,
            t3: t2 * t,
        }
    }

    /// Catmull-Rom interpolation of the sequence `f(0..n)` at this
    /// position (−1 ≤ p ≤ n): values beyond the ends are extended
    /// linearly, so a linear field is reproduced everywhere, and the curve
    /// passes through every node.
    #[inline]
    fn cubic(&self, f: impl Fn(usize) -> f64, n: usize) -> f64 {
        if n == 1 {
            return f(0);
        }
        let at = |k: isize| -> f64 {
            if k < 0 {
                f(0) + k as f64 * (f(1) - f(0))
            } else if k as usize >= n {
                f(n - 1) + (k as f64 - (n - 1) as f64) * (f(n - 1) - f(n - 2))
            } else {
                f(k as usize)
            }
        };
        let k = self.k;
        self.blend(at(k - 1), at(k), at(k + 1), at(k + 2))
    }

    /// [`Position::cubic`] down every column of `f` (nodes along axis 0),
    /// appended to `out`: the four rows around the position (extended
    /// linearly beyond the ends, as `cubic` extends them) blended column
    /// by column with the same arithmetic, so that the loop runs over
    /// contiguous rows instead of strided columns.
    fn cubic_rows(&self, f: &Array2<f64>, out: &mut Vec<f64>) {
        let (n, nx) = f.dim();
        let Some(flat) = f.as_slice().filter(|_| n >= 2) else {
            out.extend(f.columns().into_iter().map(|col| self.cubic(|k| col[k], n)));
            return;
        };
        let row = |k: usize| &flat[k * nx..(k + 1) * nx];
        let at = |k: isize| -> Cow<'_, [f64]> {
            if k < 0 {
                let (a, b) = (row(0), row(1));
                a.iter()
                    .zip(b)
                    .map(|(&a, &b)| a + k as f64 * (b - a))
                    .collect()
            } else if k as usize >= n {
                let (a, b, far) = (row(n - 2), row(n - 1), k as f64 - (n - 1) as f64);
                a.iter().zip(b).map(|(&a, &b)| b + far * (b - a)).collect()
            } else {
                Cow::Borrowed(row(k as usize))
            }
        };
        let k = self.k;
        let (p0, p1, p2, p3) = (at(k - 1), at(k), at(k + 1), at(k + 2));
        out.extend(
            p0.iter()
                .zip(p1.iter())
                .zip(p2.iter())
                .zip(p3.iter())
                .map(|(((&p0, &p1), &p2), &p3)| self.blend(p0, p1, p2, p3)),
        );
    }

    /// The Catmull-Rom curve through `p1` and `p2` at this fraction.
    #[inline(always)]
    fn blend(&self, p0: f64, p1: f64, p2: f64, p3: f64) -> f64 {
        let (t, t2, t3) = (self.t, self.t2, self.t3);
        0.5 * (2.0 * p1
            + (p2 - p0) * t
            + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
            + (3.0 * p1 - p0 - 3.0 * p2 + p3) * t3)
    }
}

/// Catmull-Rom weights of the nodes at −1, 0, 1, 2 for fraction `t`.
fn catmull_rom(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t + 2.0 * t2 - t3),
        0.5 * (2.0 - 5.0 * t2 + 3.0 * t3),
        0.5 * (t + 4.0 * t2 - 3.0 * t3),
        0.5 * (-t2 + t3),
    ]
}

/// Deforms the pair by the field `d` (each row computed where it is
/// used): A at x − d/2, B at x + d/2. Also returns where either sample
/// fell outside the image (no data: the correlation leaves those pixels
/// out).
pub fn deform(a: &Resampler, b: &Resampler, d: &Dense) -> (Array2<f32>, Array2<f32>, Array2<bool>) {
    let (h, w) = d.size();
    let (xmax, ymax) = ((w - 1) as f64 + 0.5, (h - 1) as f64 + 0.5);
    let mut oa = Array2::<f32>::zeros((h, w));
    let mut ob = Array2::<f32>::zeros((h, w));
    let mut out = Array2::from_elem((h, w), false);
    let inside = |x: f64, y: f64| (-0.5..=xmax).contains(&x) && (-0.5..=ymax).contains(&y);
    oa.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(ob.axis_iter_mut(Axis(0)))
        .zip(out.axis_iter_mut(Axis(0)))
        .enumerate()
        .for_each_init(
            || (vec![0.0f32; w], vec![0.0f32; w]),
            |(ru, rv), (i, ((mut ra, mut rb), mut ro))| {
                d.row(i, ru, rv);
                let rows = (ra.as_slice_mut(), rb.as_slice_mut(), ro.as_slice_mut());
                // Standard-layout arrays (all made here) always give
                // slices; the per-pixel loop is the general fallback.
                if let (Some(ra), Some(rb), Some(ro)) = rows {
                    row_pair(a, b, i, ru, rv, ra, rb);
                    // A at x − d/2 and B at x + d/2 are both inside when
                    // x − |d|/2 and x + |d|/2 are (f32 compares, vectorised).
                    let (y, xmax, ymax) = (i as f32, xmax as f32, ymax as f32);
                    for (j, ((o, &u), &v)) in
                        ro.iter_mut().zip(ru.iter()).zip(rv.iter()).enumerate()
                    {
                        let (hx, hy) = ((0.5 * u).abs(), (0.5 * v).abs());
                        let x = j as f32;
                        let inside =
                            x - hx >= -0.5 && x + hx <= xmax && y - hy >= -0.5 && y + hy <= ymax;
                        *o = !inside;
                    }
                } else {
                    let y = i as f64;
                    for j in 0..w {
                        let (hx, hy) = (0.5 * f64::from(ru[j]), 0.5 * f64::from(rv[j]));
                        let x = j as f64;
                        let (xa, ya, xb, yb) = (x - hx, y - hy, x + hx, y + hy);
                        ra[j] = a.at(xa, ya);
                        rb[j] = b.at(xb, yb);
                        ro[j] = !(inside(xa, ya) && inside(xb, yb));
                    }
                }
            },
        );
    (oa, ob, out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::ShapeBuilder;

    /// Every row of the field, from `u`, `v` as given.
    fn rows(grid: &Grid, u: &Array2<f64>, v: &Array2<f64>, (h, w): (usize, usize)) -> Vec<f32> {
        let d = Dense::new(grid, u, v, (h, w));
        let (mut ru, mut rv) = (vec![0.0; w], vec![0.0; w]);
        let mut out = Vec::new();
        for i in 0..h {
            d.row(i, &mut ru, &mut rv);
            out.extend_from_slice(&ru);
            out.extend_from_slice(&rv);
        }
        out
    }

    /// The rows blended down contiguous node rows (a row-major field)
    /// equal the column-by-column blend (the same field stored column-major)
    /// bit for bit, on grids of one, two and many node rows, over every
    /// image row (including those beyond the outer centres, where the
    /// nodes are extended); and a linear field comes out linear.
    #[test]
    fn node_rows_blend_as_node_columns_do() {
        for (h, size, step) in [(40, 32, 16), (48, 32, 16), (150, 32, 16), (97, 16, 5)] {
            let w = 90;
            let grid = Grid::new(w, h, size, step).expect("fits");
            let shape = (grid.ny, grid.nx);
            let field = |f: &dyn Fn(f64, f64) -> f64| {
                let c = Array2::from_shape_fn(shape, |(r, c)| {
                    let (x, y) = grid.centre(r, c);
                    f(x, y)
                });
                let mut f_order = Array2::zeros(shape.f());
                f_order.assign(&c);
                (c, f_order)
            };
            let (u, uf) = field(&|x, y| (0.07 * x).sin() * 3.0 + 0.01 * y * y);
            let (v, vf) = field(&|x, y| 0.3 * x - 0.2 * y + 1.5);
            assert!(u.as_slice().is_some() && (grid.ny == 1 || uf.as_slice().is_none()));
            let fast = rows(&grid, &u, &v, (h, w));
            let strided = rows(&grid, &uf, &vf, (h, w));
            assert_eq!(fast, strided, "{h}x{w} grid {size}/{step}");
            // v is linear: reproduced at every pixel, inside and beyond
            // (one node row is a constant along y).
            for i in (0..h).filter(|_| grid.ny > 1) {
                let rv = &fast[(2 * i + 1) * w..(2 * i + 2) * w];
                for (j, &got) in rv.iter().enumerate() {
                    let want = 0.3 * j as f64 - 0.2 * i as f64 + 1.5;
                    // Positions are clamped one node beyond the outer
                    // centres: compare only inside that.
                    let (x0, y0) = grid.centre(0, 0);
                    let (x1, y1) = grid.centre(grid.ny - 1, grid.nx - 1);
                    let s = step as f64;
                    let inside = (x0 - s..=x1 + s).contains(&(j as f64))
                        && (y0 - s..=y1 + s).contains(&(i as f64));
                    if inside {
                        assert!(
                            (f64::from(got) - want).abs() < 1e-4,
                            "{i},{j}: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }
}
