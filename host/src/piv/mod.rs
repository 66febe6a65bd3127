//! The PIV engine: multi-pass FFT cross-correlation with image deformation,
//! sub-pixel Gaussian peaks, normalised-median and peak-ratio validation,
//! replacement, an optional mask, and rayon across windows.
//!
//! Pass 1 correlates the images as they are; every later pass deforms both
//! images by the (validated, replaced) field of the pass before — A moved
//! back and B forward by half of it — and adds the residual it finds. A
//! window list `64,32,32` means three passes.

pub mod correlate;
pub mod deform;
pub mod dense;
pub mod filter;
pub mod options;
pub mod peak;
pub mod resample;
pub mod validate;

use std::path::Path;

use ndarray::Array2;
use rayon::prelude::*;
use spiv_formats::image::read_gray;
use spiv_formats::vectors::Vector;
use spiv_formats::FormatError;

pub use resample::Interp;
pub use spiv_formats::grid::Grid;
pub use validate::{State, Validation};

use correlate::{correlate, NoPeak, Plan, Scratch};
pub use peak::Subpixel;

/// Fraction of windows with signal that must pass validation for a pass's
/// field to deform the next pass.
const MIN_SUPPORT: f64 = 0.25;

/// Window of each pass for motion-compensated spike frames, px: 64 → 32,
/// then the 32-px pass three times. Their particles are sharp and dense,
/// and the repeated passes let the deformation converge where a window's
/// particles sit off its centre in a gradient — in glare rows, where the
/// particles nearest the wall drown (`spiv bench paper`, 10 seeds,
/// compensated glare rows, linear profile: 0.064 with three passes, 0.031
/// with five). Noisy frames lose by it: the TFP pair's field went from 3.4
/// to 4.8 % of U on `spiv bench blasius`, and dwell caps set from it
/// streaked the adaptive pair there, so TFP and adaptive frames keep three.
pub const COMPENSATED_WINDOWS: [usize; 5] = [64, 32, 32, 32, 32];

/// Settings of a PIV run.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Settings {
    /// Window side of each pass, px (4..=1024).
    pub windows: Vec<usize>,
    /// Overlap of neighbouring windows, a fraction in [0, 0.9].
    pub overlap: f64,
    /// Resampling of the deformed images.
    pub interp: Interp,
    /// Vector validation.
    pub validation: Validation,
    /// Sweeps of neighbour replacement.
    pub replace_iterations: usize,
    /// Clipped (saturated) pixels, left out of the correlation.
    pub clip: Clip,
    /// High-pass pre-filter: background blur σ, px (0 = off).
    pub highpass: f32,
    /// Sub-pixel estimator.
    pub subpixel: Subpixel,
    /// When the last pass fails as a whole (fewer than a quarter of the
    /// windows validate: eddies below the window, displacements beyond it),
    /// report the dense stage's field ([`dense::DenseMode::Pyramid`]) at the
    /// grid, flagged replaced, instead of nothing. Off in the library's
    /// defaults (the closed loops predict only from what PIV validated); on
    /// in `spiv piv` and the Python `piv`.
    #[serde(default)]
    pub dense_fallback: bool,
}

/// Which pixels count as clipped: a saturated pixel carries no particle, and
/// the edge of a clipped area would correlate at zero displacement.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Clip {
    /// Each image's maximum, when at least 0.1 % of its pixels (and 16)
    /// sit there — an image that reached full scale.
    Auto,
    /// No pixel is clipped.
    Off,
    /// Pixels at or above this gray level.
    Level(f32),
}

impl Clip {
    /// The clipping level of `img`, if any.
    pub fn level(self, img: &Array2<f32>) -> Option<f32> {
        match self {
            Clip::Off => None,
            Clip::Level(l) => Some(l),
            Clip::Auto => {
                let v = img.as_standard_layout();
                let v = v.as_slice().unwrap_or_default();
                let max = correlate::max_of(v, f32::NEG_INFINITY);
                let at = v.iter().filter(|&&x| x == max).count();
                (max > 0.0 && at >= 16 && at * 1000 >= img.len()).then_some(max)
            }
        }
    }
}

impl Default for Settings {
    /// 64 → 32 → 32 px at 50 % overlap (a 16-px grid, the paper's ≈ 4
    /// particles per 32-px window), B-spline deformation.
    fn default() -> Self {
        Settings {
            windows: vec![64, 32, 32],
            overlap: 0.5,
            interp: Interp::Bspline,
            validation: Validation::default(),
            replace_iterations: 4,
            clip: Clip::Auto,
            highpass: 3.0,
            subpixel: Subpixel::Parabolic,
            dense_fallback: false,
        }
    }
}

impl Settings {
    /// The defaults with a peak-ratio floor of 1.2, for spike frames (`spiv
    /// run`, `spiv receive --piv`): they have no frame-camera noise floor,
    /// and their true peaks often stand only 1.2–1.5× above the next one.
    /// The frame camera's pair in `spiv run` and the benches gets the same
    /// (six passes measured no better for it: other-row RMAE 0.004 / 0.005
    /// / 0.003 against 0.003 / 0.006 / 0.002).
    pub fn for_spike_frames() -> Settings {
        Settings {
            validation: Validation {
                min_peak_ratio: 1.2,
                ..Validation::default()
            },
            ..Settings::default()
        }
    }

    /// [`Settings::for_spike_frames`] with [`COMPENSATED_WINDOWS`], for
    /// motion-compensated pairs.
    pub fn for_compensated_frames() -> Settings {
        Settings {
            windows: COMPENSATED_WINDOWS.to_vec(),
            ..Settings::for_spike_frames()
        }
    }

    /// Distance between windows of `size` px at this overlap, px (≥ 1).
    pub fn step(&self, size: usize) -> usize {
        ((size as f64) * (1.0 - self.overlap)).round().max(1.0) as usize
    }

    /// The grid the field of a `w × h` pair lives on (its last pass's), or
    /// `None` when no window fits.
    pub fn grid(&self, w: usize, h: usize) -> Option<Grid> {
        let size = self.windows.last().copied().unwrap_or(32);
        Grid::new(w, h, size, self.step(size))
    }

    /// The centres of the vectors this reports on a `w × h` pair, where
    /// the truth is compared (empty when no window fits).
    pub fn centres(&self, w: u16, h: u16) -> Vec<(f64, f64)> {
        self.grid(usize::from(w), usize::from(h))
            .map(|g| g.centres())
            .unwrap_or_default()
    }
}

/// What can go wrong before any correlation.
#[derive(Debug, thiserror::Error)]
pub enum PivError {
    /// The two images differ in size.
    #[error("images differ in size: {0}x{1} and {2}x{3} px")]
    SizeMismatch(usize, usize, usize, usize),
    /// The mask differs in size from the images.
    #[error("mask is {0}x{1} px but the images are {2}x{3} px")]
    MaskSize(usize, usize, usize, usize),
    /// An image is smaller than a window.
    #[error("images of {0}x{1} px are smaller than the {2} px window")]
    TooSmall(usize, usize, usize),
    /// Bad settings.
    #[error("{0}")]
    Settings(String),
    /// Reading an image.
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// A vector field on the grid of the last pass.
#[derive(Debug, Clone)]
pub struct Field {
    /// The grid.
    pub grid: Grid,
    /// Displacement right, px per pair (0 where invalid).
    pub u: Array2<f64>,
    /// Displacement down, px per pair (0 where invalid).
    pub v: Array2<f64>,
    /// State of each vector.
    pub state: Array2<State>,
    /// Peak ratio of the last pass (0 where no peak).
    pub peak_ratio: Array2<f64>,
    /// Normalised correlation at the peak of the last pass (0 where none).
    pub peak_height: Array2<f64>,
}

impl Field {
    /// The vectors in row-major order, as the CSV writes them.
    pub fn vectors(&self) -> Vec<Vector> {
        let mut out = Vec::with_capacity(self.grid.len());
        for r in 0..self.grid.ny {
            for c in 0..self.grid.nx {
                let (x, y) = self.grid.centre(r, c);
                out.push(Vector {
                    x,
                    y,
                    u: self.u[[r, c]],
                    v: self.v[[r, c]],
                    state: self.state[[r, c]],
                });
            }
        }
        out
    }

    /// Each vector's confidence, row-major as [`Field::vectors`]: (peak
    /// ratio, normalised correlation at the peak), 0 where no peak.
    pub fn scores(&self) -> Vec<(f64, f64)> {
        self.peak_ratio
            .iter()
            .zip(self.peak_height.iter())
            .map(|(&r, &c)| (r, c))
            .collect()
    }

    /// Counts of (valid, replaced, invalid) vectors.
    pub fn counts(&self) -> (usize, usize, usize) {
        let mut n = (0, 0, 0);
        for s in &self.state {
            match s {
                State::Valid => n.0 += 1,
                State::Replaced => n.1 += 1,
                State::Invalid => n.2 += 1,
            }
        }
        n
    }
}

/// Reads a PNG/TIFF/BMP, 8- or 16-bit gray (colour is converted), as gray
/// values in its own scale.
pub fn load_image(path: &Path) -> Result<Array2<f32>, PivError> {
    let g = read_gray(path)?;
    let (w, h) = (g.width as usize, g.height as usize);
    Ok(Array2::from_shape_fn((h, w), |(i, j)| {
        f32::from(g.data[i * w + j])
    }))
}

/// Reads a mask image: pixels above 0 are excluded.
pub fn load_mask(path: &Path) -> Result<Array2<bool>, PivError> {
    Ok(load_image(path)?.mapv(|v| v > 0.0))
}

fn check(s: &Settings, (h, w): (usize, usize)) -> Result<(), PivError> {
    if s.windows.is_empty() {
        return Err(PivError::Settings("no windows given".into()));
    }
    if let Some(bad) = s.windows.iter().find(|&&n| !(4..=1024).contains(&n)) {
        return Err(PivError::Settings(format!(
            "window {bad} px: expected 4..=1024"
        )));
    }
    if !(0.0..=0.9).contains(&s.overlap) {
        return Err(PivError::Settings(format!(
            "overlap {}: expected 0..=0.9",
            s.overlap
        )));
    }
    let v = &s.validation;
    if !(v.median_threshold >= 0.0 && v.median_eps >= 0.0 && v.min_peak_ratio >= 0.0) {
        return Err(PivError::Settings(
            "validation thresholds must be non-negative numbers".into(),
        ));
    }
    let big = s.windows.iter().copied().max().unwrap_or(0);
    if w < big || h < big {
        return Err(PivError::TooSmall(w, h, big));
    }
    Ok(())
}

/// Runs PIV on a pair; the field lives on the last pass's grid.
pub fn piv(
    a: &Array2<f32>,
    b: &Array2<f32>,
    mask: Option<&Array2<bool>>,
    s: &Settings,
) -> Result<Field, PivError> {
    if a.dim() != b.dim() {
        let ((ha, wa), (hb, wb)) = (a.dim(), b.dim());
        return Err(PivError::SizeMismatch(wa, ha, wb, hb));
    }
    if let Some(m) = mask {
        if m.dim() != a.dim() {
            return Err(PivError::MaskSize(
                m.dim().1,
                m.dim().0,
                a.dim().1,
                a.dim().0,
            ));
        }
    }
    check(s, a.dim())?;
    let (h, w) = a.dim();
    // Pixels every pass leaves out: the user's mask and clipped pixels of
    // either raw image (a clipped area is large next to a residual
    // displacement, so its undeformed outline serves every pass).
    let (la, lb) = (s.clip.level(a), s.clip.level(b));
    let grow = 3 * (s.highpass.max(0.0).round() as usize);
    let (ca, cb) = rayon::join(
        || filter::clipped_areas(a, la, grow),
        || filter::clipped_areas(b, lb, grow),
    );
    let base = (mask.is_some() || ca.is_some() || cb.is_some()).then(|| {
        let mut ex = mask
            .cloned()
            .unwrap_or_else(|| Array2::from_elem((h, w), false));
        for c in [&ca, &cb].into_iter().flatten() {
            ex.zip_mut_with(c, |e, &c| *e |= c);
        }
        ex
    });
    // The dense fallback works on the raw images (their high-pass removes
    // the particles' own low frequencies, which guide its coarse levels:
    // turbulence EPE 2.4 px raw, 5.0 px high-passed).
    let raw = (a, b);
    let (fa, fb);
    let (a, b) = if s.highpass > 0.0 {
        (fa, fb) = rayon::join(
            || filter::highpass(a, s.highpass),
            || filter::highpass(b, s.highpass),
        );
        (&fa, &fb)
    } else {
        (a, b)
    };
    let mut prev: Option<(Field, f64)> = None;
    let mut predictor: Option<Field> = None;
    let resamplers = (s.windows.len() > 1).then(|| {
        rayon::join(
            || resample::Resampler::new(a, s.interp),
            || resample::Resampler::new(b, s.interp),
        )
    });
    for &size in &s.windows {
        let step = s.step(size);
        let grid = Grid::new(w, h, size, step).ok_or(PivError::TooSmall(w, h, size))?;
        let (pa, pb, pred, outside) = match &predictor {
            None => (None, None, None, base.clone()),
            Some(f) => {
                let (du, dv) = deform::dense(&f.grid, &f.u, &f.v, h, w);
                let (ra, rb) = resamplers
                    .as_ref()
                    .ok_or_else(|| PivError::Settings("internal: no resampler".into()))?;
                let (da, db, mut outside) = deform::deform(ra, rb, &du, &dv);
                if let Some(m) = &base {
                    outside.zip_mut_with(m, |o, &m| *o |= m);
                }
                (Some(da), Some(db), Some((du, dv)), Some(outside))
            }
        };
        let (ia, ib) = (pa.as_ref().unwrap_or(a), pb.as_ref().unwrap_or(b));
        let excluded = outside.as_ref().or(mask);
        let (field, support) = pass(ia, ib, mask, excluded, grid, pred.as_ref(), s);
        // A pass where fewer than a quarter of the windows with signal
        // passed validation has failed (e.g. displacements beyond the
        // window): its replaced field would only spread noise. After a
        // good pass on the same grid (a repeated final window), that pass
        // stands: it stays the predictor and the result. Otherwise the
        // next pass starts again from the undeformed images.
        let good_same_grid = prev
            .as_ref()
            .is_some_and(|(f, sup)| *sup >= MIN_SUPPORT && f.grid == field.grid);
        if support < MIN_SUPPORT && good_same_grid {
            continue;
        }
        predictor = (support >= MIN_SUPPORT).then(|| field.clone());
        prev = Some((field, support));
    }
    let (mut field, support) = prev.ok_or_else(|| PivError::Settings("no windows given".into()))?;
    if support < MIN_SUPPORT && s.dense_fallback {
        // The last pass failed as a whole: the dense stage measures below
        // the window and beyond its quarter rule. Its field at the grid is
        // reported as replaced (measured, not by correlation); windows
        // without signal stay invalid.
        let f = dense::dense_flow(raw.0, raw.1, None, &dense::DenseMode::Pyramid.settings());
        dense::fill(&mut field, &f);
    } else if support < MIN_SUPPORT {
        // The last pass failed as a whole: what passed its tests are chance
        // matches (overlapping windows share particles, so two neighbours
        // can agree by chance). Nothing is reported as measured.
        for ((st, u), v) in field
            .state
            .iter_mut()
            .zip(field.u.iter_mut())
            .zip(field.v.iter_mut())
        {
            *st = State::Invalid;
            *u = 0.0;
            *v = 0.0;
        }
    }
    Ok(field)
}

/// One pass on (possibly deformed) images; `pred` is the dense predictor
/// the images were deformed by; `mask` holds the user's masked pixels (a
/// window whose centre is masked has no vector) and `excluded` every pixel
/// the correlation leaves out (the mask and, after deformation, pixels with
/// no data).
fn pass(
    a: &Array2<f32>,
    b: &Array2<f32>,
    mask: Option<&Array2<bool>>,
    excluded: Option<&Array2<bool>>,
    grid: Grid,
    pred: Option<&(Array2<f32>, Array2<f32>)>,
    s: &Settings,
) -> (Field, f64) {
    let plan = Plan::new(grid.size);
    let n = grid.size;
    let results: Vec<(f64, f64, f64, f64, Option<NoPeak>)> = (0..grid.len())
        .into_par_iter()
        .map_init(
            || Scratch::new(&plan),
            |sc, k| {
                let (r, c) = (k / grid.nx, k % grid.nx);
                let (x0, y0) = grid.origin(r, c);
                let (xc, yc) = (x0 + n / 2, y0 + n / 2);
                if mask.is_some_and(|m| m[[yc.min(m.dim().0 - 1), xc.min(m.dim().1 - 1)]]) {
                    return (0.0, 0.0, 0.0, 0.0, Some(NoPeak::NoSignal));
                }
                sc.masked.clear();
                if let Some(m) = excluded {
                    // Most windows hold no excluded pixel: a scan of the
                    // window's row slices (vectorised) says so.
                    let rows = || (y0..y0 + n).map(|i| m.row(i));
                    let any = rows().any(|r| match r.as_slice() {
                        Some(r) => r[x0..x0 + n].contains(&true),
                        None => (x0..x0 + n).any(|j| r[j]),
                    });
                    if any {
                        for row in rows() {
                            sc.masked.extend((0..n).map(|j| row[x0 + j]));
                        }
                    }
                }
                for i in 0..n {
                    let ra = a.row(y0 + i);
                    let rb = b.row(y0 + i);
                    let (da, db) = (&mut sc.a[i * n..(i + 1) * n], &mut sc.b[i * n..(i + 1) * n]);
                    match (ra.as_slice(), rb.as_slice()) {
                        (Some(ra), Some(rb)) => {
                            da.copy_from_slice(&ra[x0..x0 + n]);
                            db.copy_from_slice(&rb[x0..x0 + n]);
                        }
                        _ => {
                            for j in 0..n {
                                da[j] = ra[x0 + j];
                                db[j] = rb[x0 + j];
                            }
                        }
                    }
                }
                let (pu, pv) = match pred {
                    None => (0.0, 0.0),
                    Some((du, dv)) => {
                        // The predictor at the window centre (mean of the
                        // central 2×2 for even windows).
                        let (i1, j1) = (y0 + (n - 1) / 2, x0 + (n - 1) / 2);
                        let (i2, j2) = (y0 + n / 2, x0 + n / 2);
                        let m = |f: &Array2<f32>| {
                            0.25 * f64::from(f[[i1, j1]] + f[[i1, j2]] + f[[i2, j1]] + f[[i2, j2]])
                        };
                        (m(du), m(dv))
                    }
                };
                match correlate(&plan, sc, s.subpixel) {
                    // After deformation the residual must be small: a
                    // correction beyond a quarter window means the
                    // predictor was wrong here, so the peak is not trusted.
                    Ok(p) if pred.is_some() && p.dx.hypot(p.dy) > n as f64 / 4.0 => {
                        (pu + p.dx, pv + p.dy, 0.0, p.height, Some(NoPeak::NoPeak))
                    }
                    Ok(p) => (pu + p.dx, pv + p.dy, p.ratio, p.height, None),
                    Err(e) => (pu, pv, 0.0, 0.0, Some(e)),
                }
            },
        )
        .collect();
    let shape = (grid.ny, grid.nx);
    let mut u = Array2::zeros(shape);
    let mut v = Array2::zeros(shape);
    let mut ratio = Array2::zeros(shape);
    let mut height = Array2::zeros(shape);
    let mut state = Array2::from_elem(shape, State::Valid);
    let mut replaceable = Array2::from_elem(shape, true);
    for (k, (du, dv, pr, ph, err)) in results.into_iter().enumerate() {
        let idx = [k / grid.nx, k % grid.nx];
        u[idx] = du;
        v[idx] = dv;
        ratio[idx] = pr;
        height[idx] = ph;
        match err {
            Some(NoPeak::NoSignal) => {
                state[idx] = State::Invalid;
                replaceable[idx] = false;
            }
            Some(NoPeak::NoPeak) => state[idx] = State::Invalid,
            None if pr < s.validation.min_peak_ratio => state[idx] = State::Invalid,
            None => {}
        }
    }
    validate::median_test(
        &u,
        &v,
        &mut state,
        s.validation.median_threshold,
        s.validation.median_eps,
    );
    let with_signal = replaceable.iter().filter(|&&r| r).count();
    let valid = state.iter().filter(|&&st| st == State::Valid).count();
    let support = valid as f64 / with_signal.max(1) as f64;
    validate::replace(
        &mut u,
        &mut v,
        &mut state,
        &replaceable,
        s.replace_iterations,
    );
    let field = Field {
        grid,
        u,
        v,
        state,
        peak_ratio: ratio,
        peak_height: height,
    };
    (field, support)
}

/// An upright `w × h` gray image as PIV input.
pub fn to_f32(data: &[u16], w: usize, h: usize) -> Array2<f32> {
    Array2::from_shape_fn((h, w), |(i, j)| f32::from(data[i * w + j]))
}
