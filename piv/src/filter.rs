//! Image pre-filters applied before correlation, and the mask of clipped
//! (saturated) areas that correlation leaves out.

use ndarray::{Array2, Axis};
use rayon::prelude::*;

/// Subtracts a smooth background: the image blurred by three box passes
/// per axis of width `2·round(σ)+1` (≈ a Gaussian of `sigma` px). Static
/// light that varies slowly — glare near an interface, vignetting — would
/// otherwise correlate at zero displacement and compete with the particles'
/// peak. Edges are clamped. `sigma` ≤ 0 returns a copy.
pub fn highpass(img: &Array2<f32>, sigma: f32) -> Array2<f32> {
    if sigma.is_nan() || sigma <= 0.0 {
        return img.clone();
    }
    let r = (sigma.round() as usize).max(1);
    let mut bg = img.as_standard_layout().into_owned();
    // Along rows: four rows' running sums in lockstep (blocks of rows in
    // parallel; 32-row lane blocks, transposed, measured slower here).
    let w = bg.ncols();
    bg.axis_chunks_iter_mut(Axis(0), LOCKSTEP)
        .into_par_iter()
        .for_each_init(Vec::new, |pad, mut rows| {
            if let Some(rows) = rows.as_slice_mut() {
                for _ in 0..3 {
                    box_lines(rows, w, r, pad);
                }
            }
        });
    // Down columns: stripes of whole rows, one lane per column; the three
    // passes alternate between the stripe and one buffer.
    for_column_blocks(&mut bg, |block, w, scratch| {
        // The worker's scratch, grown, never cleared: each pass writes
        // every sample of its output.
        if scratch.len() < block.len() {
            scratch.resize(block.len(), 0.0f32);
        }
        let tmp = &mut scratch[..block.len()];
        box_columns(block, tmp, w, r);
        box_columns(tmp, block, w, r);
        box_columns(block, tmp, w, r);
        block.copy_from_slice(tmp);
    });
    bg.zip_mut_with(img, |b, &v| *b = v - *b);
    bg
}

/// Running-sum box blur of radius `r` along one line, edges clamped; `pad`
/// is a reusable buffer.
fn box_line(row: &mut [f32], r: usize, pad: &mut Vec<f32>) {
    let w = row.len();
    if w == 0 {
        return;
    }
    let norm = 1.0 / (2 * r + 1) as f32;
    pad.clear();
    clamped(pad, row, r);
    let mut sum: f32 = pad[..2 * r + 1].iter().sum();
    for j in 0..w {
        row[j] = sum * norm;
        sum += pad[j + 2 * r + 1] - pad[j];
    }
}

/// Appends `row` (not empty) padded by `r` clamped values on the left and
/// `r + 1` on the right (the last running-sum step reads one more).
fn clamped(pad: &mut Vec<f32>, row: &[f32], r: usize) {
    pad.extend(std::iter::repeat_n(row[0], r));
    pad.extend_from_slice(row);
    pad.extend(std::iter::repeat_n(row[row.len() - 1], r + 1));
}

/// Rows [`box_lines`] blurs together.
const LOCKSTEP: usize = 4;

/// [`box_line`] on each row of `rows` (row-major, `w` wide): four rows at
/// a time in lockstep, so that four independent running sums overlap where
/// one waits on its own additions (the same additions in the same order
/// per row). `pad` is a reusable buffer.
fn box_lines(rows: &mut [f32], w: usize, r: usize, pad: &mut Vec<f32>) {
    if w == 0 {
        return;
    }
    let norm = 1.0 / (2 * r + 1) as f32;
    let pw = w + 2 * r + 1;
    let mut blocks = rows.chunks_exact_mut(LOCKSTEP * w);
    for block in &mut blocks {
        pad.clear();
        for row in block.chunks_exact(w) {
            clamped(pad, row, r);
        }
        let p: [&[f32]; LOCKSTEP] = std::array::from_fn(|l| &pad[l * pw..(l + 1) * pw]);
        let mut sum: [f32; LOCKSTEP] = std::array::from_fn(|l| p[l][..2 * r + 1].iter().sum());
        let (r0, rest) = block.split_at_mut(w);
        let (r1, rest) = rest.split_at_mut(w);
        let (r2, r3) = rest.split_at_mut(w);
        for j in 0..w {
            for (l, row) in [&mut *r0, &mut *r1, &mut *r2, &mut *r3]
                .into_iter()
                .enumerate()
            {
                row[j] = sum[l] * norm;
                sum[l] += p[l][j + 2 * r + 1] - p[l][j];
            }
        }
    }
    for row in blocks.into_remainder().chunks_exact_mut(w) {
        box_line(row, r, pad);
    }
}

/// The same box blur down the columns of a row-major block `w` wide, into
/// `out`: every column's running sum in its own lane, so the loop runs
/// over whole rows and vectorises (the same additions in the same order as
/// [`box_line`] on each column).
fn box_columns(block: &[f32], out: &mut [f32], w: usize, r: usize) {
    let h = block.len() / w.max(1);
    if h == 0 {
        return;
    }
    let norm = 1.0 / (2 * r + 1) as f32;
    let row = |k: isize| {
        let k = k.clamp(0, h as isize - 1) as usize;
        &block[k * w..(k + 1) * w]
    };
    let mut sum = vec![0.0f32; w];
    for k in -(r as isize)..=(r as isize) {
        for (s, &v) in sum.iter_mut().zip(row(k)) {
            *s += v;
        }
    }
    for i in 0..h {
        let (new, old) = (row((i + r + 1) as isize), row(i as isize - r as isize));
        let o = &mut out[i * w..(i + 1) * w];
        for (((o, s), &n), &p) in o.iter_mut().zip(sum.iter_mut()).zip(new).zip(old) {
            *o = *s * norm;
            *s += n - p;
        }
    }
}

/// Rows of `img` in blocks of 32, each transposed into a contiguous buffer
/// (one row of the image per lane: `block` is `w` lines of 32), handed to
/// the column filter `f` and transposed back; blocks in parallel. A
/// recursion along one row is a chain of dependent operations; 32 rows
/// side by side run as vectors (32 rather than 8 lanes: the per-step loop
/// overhead is shared by four times the pixels).
pub fn for_row_blocks(img: &mut Array2<f32>, f: impl Fn(&mut [f32], usize) + Sync) {
    const ROWS: usize = 32;
    img.axis_chunks_iter_mut(Axis(0), ROWS)
        .into_par_iter()
        .for_each_init(Vec::new, |buf, mut chunk| {
            let (r, w) = chunk.dim();
            // One buffer per worker, grown, never cleared: the copy below
            // writes every sample the filter reads.
            if buf.len() < r * w {
                buf.resize(r * w, 0.0f32);
            }
            let block = &mut buf[..r * w];
            for (i, row) in chunk.rows().into_iter().enumerate() {
                for (lanes, &v) in block.chunks_exact_mut(r).zip(row) {
                    lanes[i] = v;
                }
            }
            f(block, r);
            for (i, mut row) in chunk.rows_mut().into_iter().enumerate() {
                for (o, lanes) in row.iter_mut().zip(block.chunks_exact(r)) {
                    *o = lanes[i];
                }
            }
        });
}

/// Columns of `img` in blocks, each copied to a contiguous row-major
/// buffer (`block`, `width`), handed to `f` with a scratch vector of the
/// worker's (holding whatever an earlier block left) and copied back;
/// blocks in parallel. The column filters run down whole block rows at once, which
/// vectorises, instead of transposing the image twice.
pub fn for_column_blocks(
    img: &mut Array2<f32>,
    f: impl Fn(&mut [f32], usize, &mut Vec<f32>) + Sync,
) {
    const BLOCK: usize = 128;
    img.axis_chunks_iter_mut(Axis(1), BLOCK)
        .into_par_iter()
        .for_each_init(Vec::new, |scratch, mut chunk| {
            let w = chunk.dim().1;
            let mut block = Vec::with_capacity(chunk.len());
            for row in chunk.rows() {
                match row.to_slice() {
                    Some(row) => block.extend_from_slice(row),
                    None => block.extend(row.iter().copied()),
                }
            }
            f(&mut block, w, scratch);
            for (mut row, src) in chunk.rows_mut().into_iter().zip(block.chunks_exact(w)) {
                row.assign(&ndarray::aview1(src));
            }
        });
}

/// The clipped areas of `img` (pixels at or above `level`): those that
/// survive an erosion by `CLIP_CORE` px — so a particle with a clipped core
/// keeps its pixels — grown back by `grow` px to cover the rim where the
/// high-pass filter rings at the area's static edge. `None` without a level
/// or without any area.
pub fn clipped_areas(img: &Array2<f32>, level: Option<f32>, grow: usize) -> Option<Array2<bool>> {
    let l = level?;
    // An area needs a row with 2·CLIP_CORE + 1 clipped pixels in a row;
    // clipped particle cores (a few px) have none, and then no area exists.
    let side = 2 * CLIP_CORE + 1;
    if !img.rows().into_iter().any(|row| has_run(&row, l, side)) {
        return None;
    }
    let clipped = img.mapv(|v| v >= l);
    let full = (side * side) as u32;
    let eroded = box_count(&clipped, CLIP_CORE, |c| c == full);
    Some(box_count(&eroded, CLIP_CORE + grow, |c| c > 0))
}

/// Whether `row` holds `side` consecutive values at or above `level`. Any
/// `side` consecutive positions hold a multiple of `side`, so only runs
/// through those positions are measured: a `side`-th of the row is read
/// where nothing is clipped.
fn has_run(row: &ndarray::ArrayView1<'_, f32>, level: f32, side: usize) -> bool {
    let w = row.len();
    let at = |j: usize| row[j] >= level;
    (0..w).step_by(side.max(1)).any(|j| {
        if !at(j) {
            return false;
        }
        let left = (1..side).take_while(|&k| k <= j && at(j - k)).count();
        let right = (1..side).take_while(|&k| j + k < w && at(j + k)).count();
        left + 1 + right >= side
    })
}

/// Radius of the erosion that tells a clipped area from a clipped particle.
const CLIP_CORE: usize = 3;

/// For every pixel, whether the count of set pixels within `r` (a (2r+1)²
/// square, clipped at the image edge) passes `test`. Separable: a running
/// count along each row (rows in parallel), then a running sum of those
/// counts down the columns with one lane per column (vectorises).
fn box_count(m: &Array2<bool>, r: usize, test: impl Fn(u32) -> bool + Sync) -> Array2<bool> {
    let (h, w) = m.dim();
    let mut rows = Array2::<u32>::zeros((h, w));
    rows.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .zip(m.axis_iter(ndarray::Axis(0)))
        .for_each(|(mut o, s)| {
            let mut acc: u32 = s.iter().take(r.min(w)).map(|&b| u32::from(b)).sum();
            for j in 0..w {
                if j + r < w {
                    acc += u32::from(s[j + r]);
                }
                o[j] = acc;
                if j >= r {
                    acc -= u32::from(s[j - r]);
                }
            }
        });
    let mut out = Array2::from_elem((h, w), false);
    let mut sum = vec![0u32; w];
    for k in 0..r.min(h) {
        for (s, &v) in sum.iter_mut().zip(rows.row(k)) {
            *s += v;
        }
    }
    for i in 0..h {
        if i + r < h {
            for (s, &v) in sum.iter_mut().zip(rows.row(i + r)) {
                *s += v;
            }
        }
        for (o, &s) in out.row_mut(i).iter_mut().zip(&sum) {
            *o = test(s);
        }
        if i >= r {
            for (s, &v) in sum.iter_mut().zip(rows.row(i - r)) {
                *s -= v;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_a_ramp_and_keeps_a_spot() {
        let mut img = Array2::from_shape_fn((66, 150), |(i, j)| (3 * i + j) as f32);
        img[[32, 32]] += 100.0;
        let hp = highpass(&img, 4.0);
        // Away from the clamped edges the ramp is gone.
        assert!(hp[[20, 20]].abs() < 0.5, "{}", hp[[20, 20]]);
        assert!(hp[[32, 32]] > 90.0);
        // Against the plain definition: three clamped box passes along each
        // row, then along each column (copied out).
        let r = 4;
        let mut want = img.clone();
        let mut pad = Vec::new();
        for mut row in want.rows_mut() {
            let mut line = row.to_vec();
            for _ in 0..3 {
                box_line(&mut line, r, &mut pad);
            }
            row.assign(&ndarray::Array1::from(line));
        }
        for mut col in want.columns_mut() {
            let mut line = col.to_vec();
            for _ in 0..3 {
                box_line(&mut line, r, &mut pad);
            }
            col.assign(&ndarray::Array1::from(line));
        }
        let want = &img - &want;
        assert_eq!(hp, want);
        let flat = Array2::from_elem((16, 16), 7.0f32);
        assert!(highpass(&flat, 3.0).iter().all(|v| v.abs() < 1e-4));
    }

    /// The run test that reads every `side`-th value against a scan of
    /// every value, on rows with runs of every length at every offset.
    #[test]
    fn has_run_matches_a_full_scan() {
        for side in [1, 2, 7] {
            for len in 0..12 {
                for start in 0..16 {
                    let row = ndarray::Array1::from_shape_fn(30, |j| {
                        if (start..start + len).contains(&j) {
                            9.0
                        } else {
                            1.0
                        }
                    });
                    let mut run = 0;
                    let want = row.iter().any(|&v| {
                        run = if v >= 9.0 { run + 1 } else { 0 };
                        run >= side
                    });
                    let got = has_run(&row.view(), 9.0, side);
                    assert_eq!(got, want, "side {side}, run {start}..{}", start + len);
                }
            }
        }
    }

    /// The separable running counts against counting every square.
    #[test]
    fn box_count_matches_brute_force() {
        let (h, w) = (23, 37);
        let m = Array2::from_shape_fn((h, w), |(i, j)| (i * 7 + j * 11 + i * j) % 5 < 2);
        for r in [0, 1, 2, 5, 30] {
            let got = box_count(&m, r, |c| c % 3 == 1);
            for i in 0..h {
                for j in 0..w {
                    let (i0, i1) = (i.saturating_sub(r), (i + r + 1).min(h));
                    let (j0, j1) = (j.saturating_sub(r), (j + r + 1).min(w));
                    let n = (i0..i1)
                        .flat_map(|a| (j0..j1).map(move |b| (a, b)))
                        .filter(|&p| m[p])
                        .count() as u32;
                    assert_eq!(got[[i, j]], n % 3 == 1, "r {r} at {i},{j}");
                }
            }
        }
    }
}
