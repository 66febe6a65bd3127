//! Resampling an image at non-integer positions: the interpolation kernels
//! (bilinear, Keys' bicubic, cubic and quintic B-splines with Unser's
//! prefilter) and the padded [`Resampler`] the deformation step samples.

use ndarray::{Array2, ShapeBuilder};
use wide::{f32x4, f32x8, f64x2};

/// How a deformed image is resampled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interp {
    /// 2×2 taps.
    Bilinear,
    /// Keys' cubic convolution (a = −½), 4×4 taps.
    Bicubic,
    /// Cubic B-spline interpolation (Unser's prefilter, then 4×4 taps):
    /// the most accurate cubic for 4–6 px particle images.
    Bspline,
    /// Quintic B-spline (6×6 taps): smaller interpolation error on small
    /// particles, 2.25× the taps.
    Bspline5,
}

/// An image ready to be resampled: the gray values, or for
/// [`Interp::Bspline`] their B-spline coefficients (computed once).
///
/// The values are stored with a border of `PAD` px already extended as
/// the kernel extends the image (mirrored for B-splines, clamped
/// otherwise), so samples up to `PAD − 3` px outside the image take the
/// fast path too: at the edges of a 400×250 image the general path cost
/// as much as all the interior.
#[derive(Debug, Clone)]
pub struct Resampler {
    /// The values (or coefficients) with the border, row-major
    /// `(h + 2·PAD) × (w + 2·PAD)`.
    data: Vec<f32>,
    w: usize,
    h: usize,
    /// Padded row length, `w + 2·PAD`.
    pw: usize,
    interp: Interp,
}

/// Border of a [`Resampler`]'s stored image, px.
const PAD: usize = 8;

impl Resampler {
    /// Prepares `img` for `interp`.
    pub fn new(img: &Array2<f32>, interp: Interp) -> Resampler {
        let img = match interp {
            Interp::Bspline => bspline_coefficients(img, &CUBIC_POLES),
            Interp::Bspline5 => bspline_coefficients(img, &QUINTIC_POLES),
            _ => img.as_standard_layout().into_owned(),
        };
        let (h, w) = img.dim();
        let (pw, ph) = (w + 2 * PAD, h + 2 * PAD);
        let extend: fn(isize, usize) -> usize = match interp {
            Interp::Bspline | Interp::Bspline5 => mirror,
            Interp::Bilinear | Interp::Bicubic => |k, n| k.clamp(0, n as isize - 1) as usize,
        };
        let cols: Vec<usize> = (0..pw)
            .map(|j| extend(j as isize - PAD as isize, w))
            .collect();
        let mut data = Vec::with_capacity(pw * ph);
        for i in 0..ph {
            let row = img.row(extend(i as isize - PAD as isize, h));
            match row.as_slice() {
                // The image's own columns copied whole, the border taken
                // column by column.
                Some(r) if w >= PAD => {
                    data.extend(cols[..PAD].iter().map(|&j| r[j]));
                    data.extend_from_slice(r);
                    data.extend(cols[PAD + w..].iter().map(|&j| r[j]));
                }
                _ => data.extend(cols.iter().map(|&j| row[j])),
            }
        }
        Resampler {
            data,
            w,
            h,
            pw,
            interp,
        }
    }

    /// The image without its border.
    fn view(&self) -> Option<ndarray::ArrayView2<'_, f32>> {
        let start = PAD * self.pw + PAD;
        ndarray::ArrayView2::from_shape(
            (self.h, self.w).strides((self.pw, 1)),
            self.data.get(start..)?,
        )
        .ok()
    }

    /// Start of the 4×4 taps around (xi, yi) (whole px, the tap at −1, −1)
    /// in the padded buffer, if they lie in it.
    #[inline(always)]
    fn taps4(&self, xi: i64, yi: i64) -> Option<usize> {
        let (x, y) = (xi + PAD as i64 - 1, yi + PAD as i64 - 1);
        let (pw, ph) = (self.pw as i64, (self.h + 2 * PAD) as i64);
        (x >= 0 && y >= 0 && x + 4 <= pw && y + 4 <= ph).then(|| y as usize * self.pw + x as usize)
    }

    /// The value at (x right, y down) px, mirrored at the edges for
    /// B-splines, clamped otherwise.
    ///
    /// Hand-written fast path (the deformation's hot loop): where the 4×4
    /// taps lie inside the image, they are read straight from the row-major
    /// buffer in f32, four rows accumulated as one 4-lane vector before the
    /// horizontal weights; elsewhere the general edge-handling path runs.
    #[inline(always)]
    pub fn at(&self, x: f64, y: f64) -> f32 {
        let (x0, y0) = (x.floor(), y.floor());
        // Saturating casts: NaN and far-out positions fail the tests below.
        let (xi, yi) = (x0 as i64, y0 as i64);
        match self.interp {
            Interp::Bspline | Interp::Bicubic | Interp::Bilinear => {
                if let Some(base) = self.taps4(xi, yi) {
                    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
                    let k = kernel4(self.interp).unwrap_or(&BSPLINE4);
                    if let Some(blk) = self.data.get(base..base + 3 * self.pw + 4) {
                        return dot4(blk, self.pw, weights4(k, fx), weights4(k, fy));
                    }
                }
            }
            Interp::Bspline5 => {
                // The 6×6 taps from (xi − 2, yi − 2), when inside the
                // padded buffer: one unsigned compare per axis (a negative
                // origin wraps to a huge one).
                let (bx, by) = (
                    xi.wrapping_add(PAD as i64 - 2) as u64,
                    yi.wrapping_add(PAD as i64 - 2) as u64,
                );
                // (The padded buffer is at least 2·PAD = 16 px each way.)
                let last = (self.pw as u64 - 6, (self.h + 2 * PAD) as u64 - 6);
                if bx <= last.0 && by <= last.1 {
                    let (wx, wy) = quintic_weights(x - x0, y - y0);
                    let base = by as usize * self.pw + bx as usize;
                    return dot6(&self.data, base, self.pw, wx, wy);
                }
            }
        }
        match self.view() {
            Some(img) => sample(&img, x, y, self.interp),
            None => 0.0,
        }
    }
}

/// Σ wy[r]·wx[k]·blk[r·pw + k] over the 4×4 taps; a row beyond `blk`
/// counts as 0.
///
/// Written with explicit 4-lane vectors (`wide`): the four rows scaled by
/// their y weights and summed, then one horizontal dot with the x weights.
/// This is the deformation's innermost loop (two calls per pixel), and the
/// compiler turned the same arithmetic on arrays into 60 scalar
/// instructions.
#[inline(always)]
fn dot4(blk: &[f32], pw: usize, wx: f32x4, wy: f32x4) -> f32 {
    let wy = wy.to_array();
    let row = |r: usize| match blk.get(r * pw..r * pw + 4) {
        Some(&[a, b, c, d]) => f32x4::new([a, b, c, d]) * f32x4::splat(wy[r]),
        _ => f32x4::ZERO,
    };
    let acc = (row(0) + row(1)) + (row(2) + row(3));
    (acc * wx).reduce_add()
}

/// Σ wx[k]·(Σ wy[r]·data[base + r·pw + k]) over the 6×6 taps from `base`
/// (rows `pw` apart, all inside `data`).
///
/// Hand-written with 8-lane vectors (`wide`; lanes 6 and 7 are read and
/// dropped): the six columns' sums over the rows run in the lanes, each
/// lane adding its rows in order, so the result is the scalar loop's to
/// the bit; the compiler kept that loop scalar. The quintic B-spline's
/// deformation spends most of its time here.
#[inline(always)]
fn dot6(data: &[f32], base: usize, pw: usize, wx: [f64; 6], wy: [f64; 6]) -> f32 {
    let mut acc = f32x8::ZERO;
    for (r, &wr) in wy.iter().enumerate() {
        let o = base + r * pw;
        let row = match data.get(o..o + 8) {
            Some(&[a, b, c, d, e, f, g, h]) => f32x8::new([a, b, c, d, e, f, g, h]),
            _ => {
                let mut t = [0.0f32; 8];
                for (t, &v) in t.iter_mut().zip(data.get(o..o + 6).unwrap_or(&[])) {
                    *t = v;
                }
                f32x8::new(t)
            }
        };
        acc += f32x8::splat(wr as f32) * row;
    }
    let acc = acc.to_array();
    acc[..6].iter().zip(wx).map(|(a, w)| a * w as f32).sum()
}

/// A 4-tap kernel as the coefficients of its weights' cubic polynomials:
/// the weights of the taps at −1, 0, 1, 2 for fraction t are
/// `((C[3]·t + C[2])·t + C[1])·t + C[0]`, one lane per tap.
type Kernel4 = [[f32; 4]; 4];

/// Cubic B-spline: (1−t)³/6, (3t³−6t²+4)/6, (−3t³+3t²+3t+1)/6, t³/6.
const BSPLINE4: Kernel4 = [
    [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0, 0.0],
    [-0.5, 0.0, 0.5, 0.0],
    [0.5, -1.0, 0.5, 0.0],
    [-1.0 / 6.0, 0.5, -0.5, 1.0 / 6.0],
];

/// Keys' cubic convolution, a = −½.
const KEYS4: Kernel4 = [
    [0.0, 1.0, 0.0, 0.0],
    [-0.5, 0.0, 0.5, 0.0],
    [1.0, -2.5, 2.0, -0.5],
    [-0.5, 1.5, -1.5, 0.5],
];

/// Bilinear as a 4-tap kernel: 0, 1 − t, t, 0.
const BILINEAR4: Kernel4 = [
    [0.0, 1.0, 0.0, 0.0],
    [0.0, -1.0, 1.0, 0.0],
    [0.0; 4],
    [0.0; 4],
];

/// The 4-tap polynomial form of `interp`, if it has one (not the quintic).
fn kernel4(interp: Interp) -> Option<&'static Kernel4> {
    match interp {
        Interp::Bspline => Some(&BSPLINE4),
        Interp::Bicubic => Some(&KEYS4),
        Interp::Bilinear => Some(&BILINEAR4),
        Interp::Bspline5 => None,
    }
}

/// The four tap weights of `k` at fraction `t`, one per lane.
#[inline(always)]
fn weights4(k: &Kernel4, t: f32) -> f32x4 {
    let t = f32x4::splat(t);
    ((f32x4::new(k[3]) * t + f32x4::new(k[2])) * t + f32x4::new(k[1])) * t + f32x4::new(k[0])
}

impl Resampler {
    /// Row `i` of the image resampled at (`j + s·u[j]`, `i + s·v[j]`) for every
    /// column j, into `out` (`u`, `v` in px), one [`Resampler::at`] per
    /// pixel: the general path of [`row_pair`] (two images of different
    /// kernels or sizes, the quintic B-spline).
    pub fn row(&self, i: usize, u: &[f32], v: &[f32], s: f32, out: &mut [f32]) {
        for (j, ((o, &du), &dv)) in out.iter_mut().zip(u).zip(v).enumerate() {
            *o = self.at(j as f64 + f64::from(s * du), i as f64 + f64::from(s * dv));
        }
    }
}

/// Row `i` of the symmetric deformation: A resampled at (j − d/2) into
/// `oa` and B at (j + d/2) into `ob`, d = (`u[j]`, `v[j]`) px.
///
/// For the 4-tap kernels (when both images use the same one) one loop does
/// both: the kernels are symmetric, so A's fraction is 1 − B's and its
/// weights are B's reversed (tap block one pixel further left) — one set of
/// weight polynomials per pixel instead of two. Four neighbours that share
/// their displacement's whole part go together (`PairRow::four`); a tap block's
/// origin is tested with one unsigned compare per axis (a negative origin
/// wraps to a huge one); a pixel whose taps leave the padded buffer takes
/// [`Resampler::at`].
pub fn row_pair(
    a: &Resampler,
    b: &Resampler,
    i: usize,
    u: &[f32],
    v: &[f32],
    oa: &mut [f32],
    ob: &mut [f32],
) {
    let alike = a.interp == b.interp && (b.pw, b.h) == (a.pw, a.h);
    let Some(k) = kernel4(a.interp).filter(|_| alike) else {
        a.row(i, u, v, -0.5, oa);
        b.row(i, u, v, 0.5, ob);
        return;
    };
    let row = PairRow::new(a, b, k, i);
    let n = oa.len().min(ob.len()).min(u.len()).min(v.len());
    let mut j = 0;
    while j + 4 <= n {
        match row.four(j, &u[j..j + 4], &v[j..j + 4]) {
            Some((sa, sb)) => {
                oa[j..j + 4].copy_from_slice(&sa);
                ob[j..j + 4].copy_from_slice(&sb);
            }
            None => {
                for l in j..j + 4 {
                    (oa[l], ob[l]) = row.one(l, u[l], v[l]);
                }
            }
        }
        j += 4;
    }
    for l in j..n {
        (oa[l], ob[l]) = row.one(l, u[l], v[l]);
    }
}

/// Row `i` of a symmetric deformation with a 4-tap kernel `k` shared by
/// both images (padded rows `pw` long; `last`: the last column and row a
/// tap block may start at).
struct PairRow<'r> {
    a: &'r Resampler,
    b: &'r Resampler,
    k: &'static Kernel4,
    i: usize,
    pw: usize,
    last: (u64, u64),
    /// `k` is [`BILINEAR4`]: [`PairRow::four`] reads 2×2 taps.
    bilinear: bool,
}

impl<'r> PairRow<'r> {
    /// Row `i` of `a` and `b` (the same padded size) with kernel `k`.
    fn new(a: &'r Resampler, b: &'r Resampler, k: &'static Kernel4, i: usize) -> PairRow<'r> {
        let (pw, ph) = (a.pw, a.h + 2 * PAD);
        PairRow {
            a,
            b,
            k,
            i,
            pw,
            last: (pw as u64 - 4, ph as u64 - 4),
            bilinear: *k == BILINEAR4,
        }
    }

    /// Where B's tap block starts, from (j + kx − 1, i + ky − 1), and A's,
    /// from (j − kx − 2, i − ky − 2) with the reversed weights, (kx, ky) =
    /// ⌊d/2⌋: (column, row) of each in the padded buffer. (NaN or beyond
    /// ±2³¹ px truncates to i32::MIN on x86, far outside.)
    #[inline(always)]
    fn origins(&self, j: usize, kx: i32, ky: i32) -> (u64, u64, u64, u64) {
        let origin = PAD as i64 - 1;
        let (kx, ky, i) = (i64::from(kx), i64::from(ky), self.i as i64);
        (
            (j as i64 + kx + origin) as u64,
            (i + ky + origin) as u64,
            (j as i64 - kx - 1 + origin) as u64,
            (i - ky - 1 + origin) as u64,
        )
    }

    /// Pixel `j` displaced by (du, dv): the 4×4 taps of each image with one
    /// horizontal sum, or `Resampler::at` where they leave the padded
    /// buffer. (A's sample, B's.)
    #[inline(always)]
    fn one(&self, j: usize, du: f32, dv: f32) -> (f32, f32) {
        let (pw, (last_x, last_y)) = (self.pw, self.last);
        let d = f32x4::new([du, dv, 0.0, 0.0]) * f32x4::splat(0.5);
        let (f, kk) = floor_lanes(d);
        let t = (d - f).to_array();
        let (xb, yb, xa, ya) = self.origins(j, kk[0], kk[1]);
        if xb <= last_x && yb <= last_y && xa <= last_x && ya <= last_y {
            let (wx, wy) = (weights4(self.k, t[0]), weights4(self.k, t[1]));
            let tap = |r: &Resampler, x: u64, y: u64, wx: f32x4, wy: f32x4| {
                let base = y as usize * pw + x as usize;
                match r.data.get(base..base + 3 * pw + 4) {
                    Some(blk) => dot4(blk, pw, wx, wy),
                    None => 0.0,
                }
            };
            (
                tap(self.a, xa, ya, rev(wx), rev(wy)),
                tap(self.b, xb, yb, wx, wy),
            )
        } else {
            let dd = d.to_array();
            let (x, y) = (j as f64, self.i as f64);
            (
                self.a.at(x - f64::from(dd[0]), y - f64::from(dd[1])),
                self.b.at(x + f64::from(dd[0]), y + f64::from(dd[1])),
            )
        }
    }

    /// Pixels `j..j + 4` displaced by (`u`, `v`) together, when they share
    /// (kx, ky), as neighbours of a smooth field mostly do: their tap
    /// blocks then sit side by side, so each tap is one 4-lane load across
    /// the four pixels, weighted by lanes of per-pixel weights — no
    /// horizontal sums. The products are added in [`dot4`]'s order, so
    /// every sample equals [`PairRow::one`]'s. `None` when they do not
    /// share it or their blocks leave the buffer. (A's samples, B's.)
    #[inline(always)]
    fn four(&self, j: usize, u: &[f32], v: &[f32]) -> Option<([f32; 4], [f32; 4])> {
        let (pw, (last_x, last_y)) = (self.pw, self.last);
        let lanes = |s: &[f32]| f32x4::new([s[0], s[1], s[2], s[3]]);
        let half = f32x4::splat(0.5);
        let (dx, dy) = (lanes(u) * half, lanes(v) * half);
        let ((fx, kx), (fy, ky)) = (floor_lanes(dx), floor_lanes(dy));
        let shared = kx.iter().all(|&x| x == kx[0]) && ky.iter().all(|&y| y == ky[0]);
        let (xb, yb, xa, ya) = self.origins(j, kx[0], ky[0]);
        // The four blocks span 7 columns (a negative origin wraps to a huge
        // one and fails; `last_x` ≥ 13 for the smallest padded row).
        let end_x = last_x.saturating_sub(3);
        let inside = xb <= end_x && yb <= last_y && xa <= end_x && ya <= last_y;
        if !(shared && inside) {
            return None;
        }
        if self.bilinear {
            // Only the taps at 0 and 1 weigh: one 2×2 block per pixel.
            let (tx, ty) = (dx - fx, dy - fy);
            let (wx, wy) = ([f32x4::ONE - tx, tx], [f32x4::ONE - ty, ty]);
            let sb = span2(
                &self.b.data,
                yb as usize * pw + xb as usize + pw + 1,
                pw,
                wx,
                wy,
            );
            let sa = span2(
                &self.a.data,
                ya as usize * pw + xa as usize + pw + 1,
                pw,
                [wx[1], wx[0]],
                [wy[1], wy[0]],
            );
            return Some((sa.to_array(), sb.to_array()));
        }
        let wx = weights_across(self.k, dx - fx);
        let wy = weights_across(self.k, dy - fy);
        let sb = span4(&self.b.data, yb as usize * pw + xb as usize, pw, wx, wy);
        let [wx0, wx1, wx2, wx3] = wx;
        let [wy0, wy1, wy2, wy3] = wy;
        let sa = span4(
            &self.a.data,
            ya as usize * pw + xa as usize,
            pw,
            [wx3, wx2, wx1, wx0],
            [wy3, wy2, wy1, wy0],
        );
        Some((sa.to_array(), sb.to_array()))
    }
}

/// Each lane rounded down, as a float and as an integer. Without SSE4.1
/// (below the x86-64-v2 the workspace builds for) `f32x4::floor` calls
/// libm once per lane, so it is hand-written there: truncation, then one
/// step down where it rounded up; exact for |x| < 2³¹. A lane that is NaN
/// or beyond ±2³¹ gives i32::MIN (x86's truncation), which the callers'
/// bounds tests reject.
#[inline(always)]
fn floor_lanes(x: f32x4) -> (f32x4, [i32; 4]) {
    #[cfg(target_feature = "sse4.1")]
    let down = x.floor();
    #[cfg(not(target_feature = "sse4.1"))]
    let down = {
        let whole = x.fast_trunc_int().round_float();
        whole - (whole.simd_gt(x) & f32x4::ONE)
    };
    (down, down.fast_trunc_int().to_array())
}

/// `w` with its lanes in reverse order: A's weights, B's mirrored.
#[inline(always)]
fn rev(w: f32x4) -> f32x4 {
    let [w0, w1, w2, w3] = w.to_array();
    f32x4::new([w3, w2, w1, w0])
}

/// The weights of the four taps of `k` for four fractions `t` (one pixel
/// per lane): element `c` is tap `c`'s weight for each pixel, as
/// [`weights4`] computes it.
#[inline(always)]
fn weights_across(k: &Kernel4, t: f32x4) -> [f32x4; 4] {
    std::array::from_fn(|c| {
        ((f32x4::splat(k[3][c]) * t + f32x4::splat(k[2][c])) * t + f32x4::splat(k[1][c])) * t
            + f32x4::splat(k[0][c])
    })
}

/// Four neighbouring pixels sampled from the tap blocks starting at
/// `base`, `base + 1`, … (row length `pw`) with their own weights (lanes):
/// for each tap column the rows weighted by `wy` and summed, then the
/// columns weighted by `wx` and summed, in [`dot4`]'s order. Taps beyond
/// `data` count as 0.
#[inline(always)]
fn span4(data: &[f32], base: usize, pw: usize, wx: [f32x4; 4], wy: [f32x4; 4]) -> f32x4 {
    const NONE: [f32; 7] = [0.0; 7];
    let row = |r: usize| -> &[f32; 7] {
        let at = base + r * pw;
        data.get(at..at + 7)
            .and_then(|s| <&[f32; 7]>::try_from(s).ok())
            .unwrap_or(&NONE)
    };
    let rows = [row(0), row(1), row(2), row(3)];
    let col = |c: usize| {
        let tap = |r: usize| {
            let q: &[f32; 4] = rows[r][c..c + 4].try_into().unwrap_or(&[0.0; 4]);
            f32x4::from(*q) * wy[r]
        };
        (tap(0) + tap(1)) + (tap(2) + tap(3))
    };
    ((col(0) * wx[0] + col(1) * wx[1]) + col(2) * wx[2]) + col(3) * wx[3]
}

/// [`span4`] for bilinear: four neighbouring pixels from the 2×2 tap
/// blocks starting at `base`, `base + 1`, …, the two rows weighted by `wy`
/// and summed, then the two columns by `wx`. The 4-tap kernel's other taps
/// weigh exactly 0, so every sample equals [`span4`]'s with
/// [`BILINEAR4`], at a quarter of the loads and products.
#[inline(always)]
fn span2(data: &[f32], base: usize, pw: usize, wx: [f32x4; 2], wy: [f32x4; 2]) -> f32x4 {
    const NONE: [f32; 5] = [0.0; 5];
    let row = |r: usize| -> &[f32; 5] {
        let at = base + r * pw;
        data.get(at..at + 5)
            .and_then(|s| <&[f32; 5]>::try_from(s).ok())
            .unwrap_or(&NONE)
    };
    let rows = [row(0), row(1)];
    let col = |c: usize| {
        let tap = |r: usize| {
            let q: &[f32; 4] = rows[r][c..c + 4].try_into().unwrap_or(&[0.0; 4]);
            f32x4::from(*q) * wy[r]
        };
        tap(0) + tap(1)
    };
    col(0) * wx[0] + col(1) * wx[1]
}

/// Mirror index into 0..n (whole-sample symmetric).
fn mirror(k: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let p = 2 * (n - 1);
    let mut k = k.rem_euclid(p);
    if k >= n {
        k = p - k;
    }
    k as usize
}

fn bspline_at(c: &ndarray::ArrayView2<f32>, x: f64, y: f64) -> f32 {
    let (h, w) = c.dim();
    let (x0, y0) = (x.floor(), y.floor());
    let (wx, wy) = (bspline_weights(x - x0), bspline_weights(y - y0));
    let (xi, yi) = (x0 as isize, y0 as isize);
    let cols = [0, 1, 2, 3].map(|k| mirror(xi + k - 1, w));
    let mut acc = 0.0f64;
    for (r, wyr) in wy.iter().enumerate() {
        let row = mirror(yi + r as isize - 1, h);
        let mut s = 0.0f64;
        for (&col, wxc) in cols.iter().zip(&wx) {
            s += wxc * f64::from(c[[row, col]]);
        }
        acc += wyr * s;
    }
    acc as f32
}

fn bspline_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let u = 1.0 - t;
    [
        u * u * u / 6.0,
        (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
        t3 / 6.0,
    ]
}

/// Cubic B-spline coefficients of an image (separable recursive prefilter,
/// mirror boundaries; Unser 1999, Thévenaz et al. 2000).
///
/// Rows and columns both run as blocks with one lane per line, in f32
/// (see `columns_prefilter` and `filter::for_row_blocks`): a recursion
/// along one line is a chain of dependent operations, 32 or more lines
/// side by side vectorise, and no transpose of the whole image is needed.
pub fn bspline_coefficients(img: &Array2<f32>, poles: &[f64]) -> Array2<f32> {
    let mut c = img.as_standard_layout().into_owned();
    let lines = |block: &mut [f32], w: usize| columns_prefilter(block, w, poles);
    super::filter::for_row_blocks(&mut c, lines);
    super::filter::for_column_blocks(&mut c, |block, w, _| lines(block, w));
    c
}

/// A row weight of the prefilter's causal initialisation below which the
/// row is left out: 2⁻⁴⁰, far below an f32 sum's resolution.
const NEGLIGIBLE: f64 = 1e-12;

/// The B-spline prefilter (gain, then per pole a causal and an
/// anti-causal first-order recursion with the exact mirror-boundary
/// initialisation of Unser 1999) down every column of a row-major block `w`
/// wide, with the column index as the vector lane.
fn columns_prefilter(block: &mut [f32], w: usize, poles: &[f64]) {
    let h = block.len() / w.max(1);
    if h < 2 {
        return;
    }
    let gain: f64 = poles.iter().map(|&z| (1.0 - z) * (1.0 - 1.0 / z)).product();
    let gain = gain as f32;
    for v in block.iter_mut() {
        *v *= gain;
    }
    let mut sum = vec![0.0f32; w];
    for &z in poles {
        // Causal initialisation, mirror boundary, exact: row k enters with
        // weight z^k + z^(2h−2−k).
        let iz = 1.0 / z;
        let mut zn = z;
        let mut z2n = z.powi(h as i32 - 1);
        let (first, last) = (&block[..w], &block[(h - 1) * w..]);
        for ((s, &a), &b) in sum.iter_mut().zip(first).zip(last) {
            *s = a + z2n as f32 * b;
        }
        z2n = z2n * z2n * iz;
        for k in 1..h - 1 {
            // Rows whose weight is below 1e-12 change no f32 sum: only the
            // weights' recursion runs through them (so the weights of the
            // rows that count are the same numbers).
            if zn.abs() + z2n.abs() >= NEGLIGIBLE {
                let wk = (zn + z2n) as f32;
                for (s, &v) in sum.iter_mut().zip(&block[k * w..(k + 1) * w]) {
                    *s += wk * v;
                }
            }
            zn *= z;
            z2n *= iz;
        }
        let inv = (1.0 / (1.0 - zn * zn)) as f32;
        for (o, &s) in block[..w].iter_mut().zip(&sum) {
            *o = s * inv;
        }
        let zf = z as f32;
        for k in 1..h {
            let (prev, cur) = block[(k - 1) * w..(k + 1) * w].split_at_mut(w);
            for (c, &p) in cur.iter_mut().zip(prev.iter()) {
                *c += zf * p;
            }
        }
        let end = (z / (z * z - 1.0)) as f32;
        {
            let (prev, cur) = block[(h - 2) * w..h * w].split_at_mut(w);
            for (c, &p) in cur.iter_mut().zip(prev.iter()) {
                *c = end * (zf * p + *c);
            }
        }
        for k in (0..h - 1).rev() {
            let (cur, next) = block[k * w..(k + 2) * w].split_at_mut(w);
            for (c, &nx) in cur.iter_mut().zip(next.iter()) {
                *c = zf * (nx - *c);
            }
        }
    }
}

const CUBIC_POLES: [f64; 1] = [-0.267_949_192_431_122_7];
const QUINTIC_POLES: [f64; 2] = [-0.430_575_347_099_973, -0.043_096_288_203_264_7];

/// Quintic B-spline weights for the taps at −2..=3 (Thévenaz et al.), for
/// the fractions `tx` and `ty` at once: the two axes in the lanes of one
/// 2-lane vector (`wide`), each lane the scalar evaluation's operations in
/// its order, so each axis's weights are the scalar ones to the bit.
fn quintic_weights(tx: f64, ty: f64) -> ([f64; 6], [f64; 6]) {
    let c = f64x2::splat;
    let mut w = f64x2::new([tx, ty]);
    let mut w2 = w * w;
    let w5 = c(1.0 / 120.0) * w * w2 * w2;
    w2 -= w;
    let w4 = w2 * w2;
    w -= c(0.5);
    let t3 = w2 * (w2 - c(3.0));
    let w0 = c(1.0 / 24.0) * (c(1.0 / 5.0) + w2 + w4) - w5;
    let t0 = c(1.0 / 24.0) * (w2 * (w2 - c(5.0)) + c(46.0 / 5.0));
    let t1 = c(-1.0 / 12.0) * w * (t3 + c(4.0));
    let (x2, x3) = (t0 + t1, t0 - t1);
    let t0 = c(1.0 / 16.0) * (c(9.0 / 5.0) - t3);
    let t1 = c(1.0 / 24.0) * w * (w4 - w2 - c(5.0));
    let lanes = [w0, t0 + t1, x2, x3, t0 - t1, w5].map(|v| v.to_array());
    (lanes.map(|l| l[0]), lanes.map(|l| l[1]))
}

fn quintic_at(c: &ndarray::ArrayView2<f32>, x: f64, y: f64) -> f32 {
    let (h, w) = c.dim();
    let (x0, y0) = (x.floor(), y.floor());
    let (wx, wy) = quintic_weights(x - x0, y - y0);
    let (xi, yi) = (x0 as isize, y0 as isize);
    let cols = [0, 1, 2, 3, 4, 5].map(|k| mirror(xi + k - 2, w));
    let mut acc = 0.0f64;
    for (r, wyr) in wy.iter().enumerate() {
        let row = mirror(yi + r as isize - 2, h);
        let mut s = 0.0f64;
        for (&col, wxc) in cols.iter().zip(&wx) {
            s += wxc * f64::from(c[[row, col]]);
        }
        acc += wyr * s;
    }
    acc as f32
}

/// Samples `img` at (x right, y down) px; edges are clamped (mirrored for
/// B-splines, where `img` holds the coefficients).
fn sample(img: &ndarray::ArrayView2<f32>, x: f64, y: f64, interp: Interp) -> f32 {
    let (h, w) = img.dim();
    let clamp = |k: isize, n: usize| k.clamp(0, n as isize - 1) as usize;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (xi, yi) = (x0 as isize, y0 as isize);
    match interp {
        Interp::Bspline => bspline_at(img, x, y),
        Interp::Bspline5 => quintic_at(img, x, y),
        Interp::Bilinear => {
            let p = |dy: isize, dx: isize| f64::from(img[[clamp(yi + dy, h), clamp(xi + dx, w)]]);
            let top = p(0, 0) * (1.0 - fx) + p(0, 1) * fx;
            let bot = p(1, 0) * (1.0 - fx) + p(1, 1) * fx;
            (top * (1.0 - fy) + bot * fy) as f32
        }
        Interp::Bicubic => {
            let wx = keys(fx);
            let wy = keys(fy);
            let mut acc = 0.0f64;
            for (r, wyr) in wy.iter().enumerate() {
                let row = clamp(yi + r as isize - 1, h);
                let mut s = 0.0f64;
                for (c, wxc) in wx.iter().enumerate() {
                    s += wxc * f64::from(img[[row, clamp(xi + c as isize - 1, w)]]);
                }
                acc += wyr * s;
            }
            acc as f32
        }
    }
}

/// Keys' cubic convolution weights for the taps at −1, 0, 1, 2.
fn keys(t: f64) -> [f64; 4] {
    const A: f64 = -0.5;
    let f1 = |d: f64| ((A + 2.0) * d - (A + 3.0)) * d * d + 1.0;
    let f2 = |d: f64| ((A * d - 5.0 * A) * d + 8.0 * A) * d - 4.0 * A;
    [f2(1.0 + t), f1(t), f1(1.0 - t), f2(2.0 - t)]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `floor_lanes` against `f32::floor` on whole numbers, halves, values
    /// just off them, negatives and large values; NaN and values beyond
    /// ±2³¹ give i32::MIN.
    #[test]
    fn floor_lanes_rounds_down_as_floor_does() {
        let mut xs = vec![0.0f32, -0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, 1e-7, -1e-7];
        for k in -40..40 {
            let x = k as f32 * 0.37;
            xs.extend([x, x.floor(), f32::from_bits(x.to_bits() + 1), 1.0e6 * x]);
        }
        for x in xs.chunks_exact(4) {
            let v = f32x4::new([x[0], x[1], x[2], x[3]]);
            let (f, k) = floor_lanes(v);
            for l in 0..4 {
                assert_eq!(f.to_array()[l], x[l].floor(), "{}", x[l]);
                assert_eq!(k[l], x[l].floor() as i32, "{}", x[l]);
            }
        }
        let (_, k) = floor_lanes(f32x4::new([f32::NAN, 3e9, -3e9, f32::INFINITY]));
        assert_eq!(k, [i32::MIN; 4]);
    }

    /// The line prefilter in f64 (the reference for the lane version).
    fn prefilter(c: &mut [f64], poles: &[f64]) {
        let n = c.len();
        if n < 2 {
            return;
        }
        let gain: f64 = poles.iter().map(|&z| (1.0 - z) * (1.0 - 1.0 / z)).product();
        for v in c.iter_mut() {
            *v *= gain;
        }
        for &z in poles {
            // Causal initialisation, mirror boundary, exact.
            let iz = 1.0 / z;
            let mut zn = z;
            let mut z2n = z.powi(n as i32 - 1);
            let mut sum = c[0] + z2n * c[n - 1];
            z2n = z2n * z2n * iz;
            for &v in &c[1..n - 1] {
                sum += (zn + z2n) * v;
                zn *= z;
                z2n *= iz;
            }
            c[0] = sum / (1.0 - zn * zn);
            for k in 1..n {
                c[k] += z * c[k - 1];
            }
            c[n - 1] = (z / (z * z - 1.0)) * (z * c[n - 2] + c[n - 1]);
            for k in (0..n - 1).rev() {
                c[k] = z * (c[k + 1] - c[k]);
            }
        }
    }

    #[test]
    fn interpolators_are_exact_at_nodes_and_on_linear_ramps() {
        let img = Array2::from_shape_fn((8, 9), |(i, j)| (2 * i + 3 * j) as f32);
        for interp in [Interp::Bilinear, Interp::Bicubic] {
            assert_eq!(sample(&img.view(), 4.0, 3.0, interp), 18.0);
            let v = sample(&img.view(), 4.25, 3.5, interp);
            assert!((v - (7.0 + 12.75)).abs() < 1e-4, "{interp:?} {v}");
        }
        // B-splines interpolate (exact at nodes) and reproduce a ramp away
        // from the mirrored edges.
        let big = Array2::from_shape_fn((32, 32), |(i, j)| (2 * i + 3 * j) as f32);
        let r = Resampler::new(&big, Interp::Bspline);
        for (i, j) in [(0, 0), (3, 4), (31, 31), (17, 9)] {
            assert!((r.at(j as f64, i as f64) - big[[i, j]]).abs() < 1e-3);
        }
        let v = r.at(15.25, 16.5);
        assert!((v - (33.0 + 45.75)).abs() < 1e-3, "{v}");
        // Clamped outside.
        assert_eq!(sample(&img.view(), -5.0, -5.0, Interp::Bilinear), 0.0);
        // The padded fast path of bilinear and bicubic agrees with the
        // general path, inside, at the edges and beyond the border.
        let wavy = Array2::from_shape_fn((20, 23), |(i, j)| {
            ((i * 5 + j * 3) % 11) as f32 + 0.1 * i as f32
        });
        for interp in [Interp::Bilinear, Interp::Bicubic] {
            let r = Resampler::new(&wavy, interp);
            for (x, y) in [
                (3.3, 4.7),
                (0.2, 0.9),
                (22.6, 19.4),
                (-3.5, 7.25),
                (25.0, -2.2),
                (-40.0, 50.0),
            ] {
                let (got, want) = (r.at(x, y), sample(&wavy.view(), x, y, interp));
                assert!(
                    (got - want).abs() < 1e-4,
                    "{interp:?} at {x},{y}: {got} vs {want}"
                );
            }
        }
    }

    /// The quintic B-spline's padded fast path (six rows in 8-lane
    /// vectors, one bounds test per axis) gives the general path's value
    /// over the same coefficients, inside, next to the edges (where the
    /// 6×6 block just fits or just does not) and beyond the border.
    #[test]
    fn the_quintic_fast_path_agrees_with_the_general_path() {
        let wavy = Array2::from_shape_fn((20, 23), |(i, j)| {
            ((i * 5 + j * 3) % 11) as f32 + 0.1 * i as f32
        });
        let r = Resampler::new(&wavy, Interp::Bspline5);
        let c = r.view().expect("a B-spline keeps its coefficients");
        let mut n = 0;
        for y in (-120..=260).map(|k| f64::from(k) * 0.1 - 0.05) {
            for x in [
                -10.3, -6.0, -5.99, -2.5, 0.0, 0.4, 3.3, 11.7, 20.01, 22.6, 25.9, 30.2,
            ] {
                let (got, want) = (r.at(x, y), sample(&c, x, y, Interp::Bspline5));
                assert!((got - want).abs() < 1e-4, "at {x},{y}: {got} vs {want}");
                n += 1;
            }
        }
        assert!(n > 4000);
    }

    /// The column blocks give the coefficients of the f64 line prefilter
    /// run down every column (within f32 rounding: 2e-6 of the largest
    /// coefficient), for both spline orders.
    #[test]
    fn column_prefilter_matches_the_line_prefilter() {
        let img = Array2::from_shape_fn((37, 150), |(i, j)| {
            (((i * 7 + j * 13) % 23) as f32) * 9.0 + if (i + j) % 5 == 0 { 200.0 } else { 0.0 }
        });
        for poles in [&CUBIC_POLES[..], &QUINTIC_POLES[..]] {
            let got = bspline_coefficients(&img, poles);
            let mut want = img.mapv(f64::from);
            for mut row in want.rows_mut() {
                let mut l = row.to_vec();
                prefilter(&mut l, poles);
                row.assign(&ndarray::Array1::from(l));
            }
            for mut col in want.columns_mut() {
                let mut l = col.to_vec();
                prefilter(&mut l, poles);
                col.assign(&ndarray::Array1::from(l));
            }
            let err = got
                .iter()
                .zip(&want)
                .map(|(&g, &w)| (f64::from(g) - w).abs())
                .fold(0.0, f64::max);
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(err < 2e-6 * scale, "max error {err} of {scale}");
        }
    }

    /// A 40×53 image and a brighter copy of it, the pair the paired-row
    /// tests deform.
    fn pair_images() -> (Array2<f32>, Array2<f32>) {
        let img = Array2::from_shape_fn((40, 53), |(i, j)| {
            ((i * 7 + j * 13) % 31) as f32 + (i as f32).sin()
        });
        let img2 = img.mapv(|v| 2.0 * v + 1.0);
        (img, img2)
    }

    /// Row `i` of the pair deformed by (`u`, `v`) through [`row_pair`],
    /// and through each image's per-pixel samples ([`Resampler::row`]).
    fn paired_and_single(
        (ra, rb): (&Resampler, &Resampler),
        i: usize,
        u: &[f32],
        v: &[f32],
    ) -> [Vec<f32>; 4] {
        let w = u.len();
        let (mut pa, mut pb) = (vec![0.0; w], vec![0.0; w]);
        row_pair(ra, rb, i, u, v, &mut pa, &mut pb);
        let (mut sa, mut sb) = (vec![0.0; w], vec![0.0; w]);
        ra.row(i, u, v, -0.5, &mut sa);
        rb.row(i, u, v, 0.5, &mut sb);
        [pa, pb, sa, sb]
    }

    /// The paired loop (A's weights mirrored from B's) gives what each
    /// image's own per-pixel samples give, inside and at the edges, for the
    /// three 4-tap kernels.
    #[test]
    fn paired_rows_match_single_rows() {
        let (img, img2) = pair_images();
        let (h, w) = img.dim();
        for interp in [Interp::Bspline, Interp::Bicubic, Interp::Bilinear] {
            let (ra, rb) = (Resampler::new(&img, interp), Resampler::new(&img2, interp));
            for i in [0, 1, 17, h - 1] {
                // Offsets from −20 to +20 px, integers included.
                let u: Vec<f32> = (0..w).map(|j| (j as f32 - 26.0) * 0.77).collect();
                let v: Vec<f32> = (0..w).map(|j| ((j % 9) as f32 - 4.0) * 0.5).collect();
                let [pa, pb, sa, sb] = paired_and_single((&ra, &rb), i, &u, &v);
                for j in 0..w {
                    assert!(
                        (pa[j] - sa[j]).abs() < 1e-3,
                        "{interp:?} A {i},{j}: {} vs {}",
                        pa[j],
                        sa[j]
                    );
                    assert!(
                        (pb[j] - sb[j]).abs() < 1e-3,
                        "{interp:?} B {i},{j}: {} vs {}",
                        pb[j],
                        sb[j]
                    );
                }
            }
        }
    }

    /// Four neighbours with one displacement go through the four-pixel
    /// path: every sample equals the one-pixel path's bit for bit, and the
    /// general path's, at the edges and with displacements that carry the
    /// taps far outside the image (where an origin left of the buffer must
    /// not wrap into range).
    #[test]
    fn four_pixels_at_once_equal_one_at_a_time() {
        let (img, img2) = pair_images();
        let (h, w) = img.dim();
        let shifts = [
            (-30.3, 0.4),
            (30.7, -20.2),
            (2.6, 1.4),
            (0.0, 0.0),
            (-14.9, 14.9),
            (-60.0, -61.5),
        ];
        for interp in [Interp::Bspline, Interp::Bicubic, Interp::Bilinear] {
            let (ra, rb) = (Resampler::new(&img, interp), Resampler::new(&img2, interp));
            let k = kernel4(interp).unwrap_or(&BSPLINE4);
            for i in [0, 1, 17, h - 1] {
                let row = PairRow::new(&ra, &rb, k, i);
                for (du, dv) in shifts {
                    let (u, v) = (vec![du; w], vec![dv; w]);
                    let [pa, pb, sa, sb] = paired_and_single((&ra, &rb), i, &u, &v);
                    for j in 0..w {
                        let one = row.one(j, du, dv);
                        assert_eq!((pa[j], pb[j]), one, "{interp:?} {i},{j} by {du},{dv}");
                        assert!((pa[j] - sa[j]).abs() < 1e-3, "{interp:?} A {i},{j}");
                        assert!((pb[j] - sb[j]).abs() < 1e-3, "{interp:?} B {i},{j}");
                    }
                }
            }
        }
    }

    #[test]
    fn keys_weights_sum_to_one() {
        for t in [0.0, 0.1, 0.5, 0.9] {
            let s: f64 = keys(t).iter().sum();
            assert!((s - 1.0).abs() < 1e-12);
        }
    }
}
