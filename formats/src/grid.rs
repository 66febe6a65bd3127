//! The grid a vector field lives on: interrogation windows of `size` px
//! every `step` px from the top-left corner, as many as fit whole, each
//! vector at its window's centre (docs/formats.md: the centre of columns
//! `j0..j0+size−1` is `x = j0 + (size−1)/2`). PIV measures on it, the
//! simulator's truth and the metrics compare on it.

/// A regular grid of square windows over an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Grid {
    /// Window side, px.
    pub size: usize,
    /// Distance between window origins, px (≥ 1).
    pub step: usize,
    /// Windows across.
    pub nx: usize,
    /// Windows down.
    pub ny: usize,
}

impl Grid {
    /// The grid over a `w × h` image, or `None` when no window fits.
    ///
    /// ```
    /// use spiv_formats::grid::Grid;
    /// let g = Grid::new(64, 48, 16, 8).unwrap();
    /// assert_eq!((g.nx, g.ny), (7, 5));
    /// assert_eq!(g.centre(0, 0), (7.5, 7.5));
    /// assert!(Grid::new(8, 8, 16, 8).is_none());
    /// ```
    pub fn new(w: usize, h: usize, size: usize, step: usize) -> Option<Grid> {
        let step = step.max(1);
        if size == 0 || w < size || h < size {
            return None;
        }
        Some(Grid {
            size,
            step,
            nx: (w - size) / step + 1,
            ny: (h - size) / step + 1,
        })
    }

    /// Top-left pixel (column, row) of window (r, c).
    pub fn origin(&self, r: usize, c: usize) -> (usize, usize) {
        (c * self.step, r * self.step)
    }

    /// Centre of window (r, c) as docs/formats.md defines it: (x, y) px with the
    /// centre of pixel (i, j) at (j, i).
    pub fn centre(&self, r: usize, c: usize) -> (f64, f64) {
        let half = (self.size as f64 - 1.0) / 2.0;
        ((c * self.step) as f64 + half, (r * self.step) as f64 + half)
    }

    /// Linear position of column coordinate `x` among window centres: (left
    /// index, right index, weight of the right one); the weight leaves
    /// [0, 1] up to one step beyond the outer centres (extrapolation).
    pub fn locate_x(&self, x: f64) -> (usize, usize, f64) {
        locate(x, (self.size as f64 - 1.0) / 2.0, self.step as f64, self.nx)
    }

    /// The same for a row coordinate.
    pub fn locate_y(&self, y: f64) -> (usize, usize, f64) {
        locate(y, (self.size as f64 - 1.0) / 2.0, self.step as f64, self.ny)
    }

    /// Every window centre (x, y), px, row by row (the order of a vectors
    /// CSV).
    pub fn centres(&self) -> Vec<(f64, f64)> {
        (0..self.ny)
            .flat_map(|r| (0..self.nx).map(move |c| (r, c)))
            .map(|(r, c)| self.centre(r, c))
            .collect()
    }

    /// Number of windows.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// Whether the grid is empty (never, for a grid that was made).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

fn locate(p: f64, first: f64, step: f64, n: usize) -> (usize, usize, f64) {
    if n < 2 {
        return (0, 0, 0.0);
    }
    // Linear extrapolation by at most one step beyond the outer centres
    // (a window's outer half lies there), constant further out.
    let f = ((p - first) / step).clamp(-1.0, n as f64);
    let k0 = (f.floor().max(0.0) as usize).min(n - 2);
    (k0, k0 + 1, f - k0 as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_of_the_paper_window() {
        let g = Grid::new(400, 250, 32, 16).expect("fits");
        assert_eq!((g.nx, g.ny), (24, 14));
        assert_eq!(g.centre(0, 0), (15.5, 15.5));
        assert_eq!(g.centre(13, 23), (23.0 * 16.0 + 15.5, 13.0 * 16.0 + 15.5));
        assert_eq!(g.locate_x(15.5 + 8.0), (0, 1, 0.5));
        assert_eq!(g.locate_x(-0.5), (0, 1, -1.0));
        assert_eq!(g.locate_x(-1e9), (0, 1, -1.0));
        assert_eq!(g.locate_x(1e9), (22, 23, 2.0));
        assert!(Grid::new(31, 250, 32, 16).is_none());
        let c = g.centres();
        assert_eq!(
            (c.len(), c[1], c[24]),
            (24 * 14, (31.5, 15.5), (15.5, 31.5))
        );
    }
}
