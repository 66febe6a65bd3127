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
    let mut bg = img.clone();
    for _ in 0..3 {
        box_rows(&mut bg, r);
    }
    let mut t = bg.t().as_standard_layout().into_owned();
    for _ in 0..3 {
        box_rows(&mut t, r);
    }
    let bg = t.t();
    let mut out = img.clone();
    out.zip_mut_with(&bg, |o, &b| *o -= b);
    out
}

/// Running-sum box blur of radius `r` along every row, edges clamped.
fn box_rows(img: &mut Array2<f32>, r: usize) {
    let w = img.dim().1;
    let norm = 1.0 / (2 * r + 1) as f32;
    img.axis_iter_mut(Axis(0))
        .into_par_iter()
        .for_each(|mut row| {
            let Some(row) = row.as_slice_mut() else {
                return;
            };
            // The row padded by r clamped values on each side.
            let mut pad = Vec::with_capacity(w + 2 * r + 1);
            pad.extend(std::iter::repeat_n(row[0], r));
            pad.extend_from_slice(row);
            pad.extend(std::iter::repeat_n(row[w - 1], r + 1));
            let mut sum: f32 = pad[..2 * r + 1].iter().sum();
            for j in 0..w {
                row[j] = sum * norm;
                sum += pad[j + 2 * r + 1] - pad[j];
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_a_ramp_and_keeps_a_spot() {
        let mut img = Array2::from_shape_fn((64, 64), |(i, j)| (3 * i + j) as f32);
        img[[32, 32]] += 100.0;
        let hp = highpass(&img, 4.0);
        // Away from the clamped edges the ramp is gone.
        assert!(hp[[20, 20]].abs() < 0.5, "{}", hp[[20, 20]]);
        assert!(hp[[32, 32]] > 90.0);
        let flat = Array2::from_elem((16, 16), 7.0f32);
        assert!(highpass(&flat, 3.0).iter().all(|v| v.abs() < 1e-4));
    }
}
