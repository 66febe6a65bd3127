//! Image pre-filters applied before correlation.

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
    // Along rows: one running sum per row (rows in parallel; running sums
    // are cheap enough that 32-row lane blocks measured slower here).
    bg.axis_iter_mut(Axis(0))
        .into_par_iter()
        .for_each_init(Vec::new, |pad, mut row| {
            if let Some(row) = row.as_slice_mut() {
                for _ in 0..3 {
                    box_line(row, r, pad);
                }
            }
        });
    // Down columns: stripes of whole rows, one lane per column.
    for_column_blocks(&mut bg, |block, w| {
        let mut tmp = vec![0.0f32; block.len()];
        for _ in 0..3 {
            box_columns(block, &mut tmp, w, r);
            block.copy_from_slice(&tmp);
        }
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
    // The line padded by r clamped values on each side.
    pad.clear();
    pad.extend(std::iter::repeat_n(row[0], r));
    pad.extend_from_slice(row);
    pad.extend(std::iter::repeat_n(row[w - 1], r + 1));
    let mut sum: f32 = pad[..2 * r + 1].iter().sum();
    for j in 0..w {
        row[j] = sum * norm;
        sum += pad[j + 2 * r + 1] - pad[j];
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
pub(crate) fn for_row_blocks(img: &mut Array2<f32>, f: impl Fn(&mut [f32], usize) + Sync) {
    const ROWS: usize = 32;
    img.axis_chunks_iter_mut(Axis(0), ROWS)
        .into_par_iter()
        .for_each(|mut chunk| {
            let (r, w) = chunk.dim();
            let mut block = vec![0.0f32; r * w];
            for (i, row) in chunk.rows().into_iter().enumerate() {
                for (lanes, &v) in block.chunks_exact_mut(r).zip(row) {
                    lanes[i] = v;
                }
            }
            f(&mut block, r);
            for (i, mut row) in chunk.rows_mut().into_iter().enumerate() {
                for (o, lanes) in row.iter_mut().zip(block.chunks_exact(r)) {
                    *o = lanes[i];
                }
            }
        });
}

/// Columns of `img` in blocks, each copied to a contiguous row-major
/// buffer (`block`, `width`), handed to `f` and copied back; blocks in
/// parallel. The column filters run down whole block rows at once, which
/// vectorises, instead of transposing the image twice.
pub(crate) fn for_column_blocks(img: &mut Array2<f32>, f: impl Fn(&mut [f32], usize) + Sync) {
    const BLOCK: usize = 128;
    img.axis_chunks_iter_mut(Axis(1), BLOCK)
        .into_par_iter()
        .for_each(|mut chunk| {
            let w = chunk.dim().1;
            let mut block = Vec::with_capacity(chunk.len());
            for row in chunk.rows() {
                match row.to_slice() {
                    Some(row) => block.extend_from_slice(row),
                    None => block.extend(row.iter().copied()),
                }
            }
            f(&mut block, w);
            for (mut row, src) in chunk.rows_mut().into_iter().zip(block.chunks_exact(w)) {
                row.assign(&ndarray::aview1(src));
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_a_ramp_and_keeps_a_spot() {
        let mut img = Array2::from_shape_fn((64, 150), |(i, j)| (3 * i + j) as f32);
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
}
