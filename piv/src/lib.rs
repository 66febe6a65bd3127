//! The PIV engine: multi-pass FFT cross-correlation with image deformation,
//! sub-pixel Gaussian peaks, normalised-median and peak-ratio validation,
//! replacement, an optional mask, and rayon across windows.
//!
//! Pass 1 correlates the images as they are; every later pass deforms both
//! images by the (validated, replaced) field of the pass before — A moved
//! back and B forward by half of it — and adds the residual it finds. A
//! window list `64,32,32` means three passes. Every pass but the last
//! deforms by that field filtered ([`smooth`]), which makes repeated passes
//! converge in a shear; the last one deforms by the field as it stands.
//!
//! A pass on the undeformed images that fails (fewer than a quarter of
//! its windows validate) is a signal, not a verdict: rescue passes measure
//! a coarser field that then predicts it — the same windows over an
//! extended search area in B, windows twice the side, and last the same
//! windows with weak peaks judged by their neighbours (the median test
//! iterated, ridges refused; such vectors are reported as replaced, never
//! valid). An undeformed peak beyond the window's quarter rule is measured
//! again over an area twice the window's side, so that a displacement
//! beyond half the window is found instead of wrapping around.

pub mod correlate;
pub mod deform;
pub mod dense;
pub mod filter;
pub mod options;
pub mod peak;
pub mod resample;
pub mod smooth;
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

use correlate::{NoPeak, Plan, Scratch};
pub use peak::Subpixel;

/// Fraction of windows with signal that must pass validation for a pass's
/// field to deform the next pass.
const MIN_SUPPORT: f64 = 0.25;

/// Window of each pass for motion-compensated spike frames, px: 64 → 32,
/// then the 32-px pass five times more. Their particles are sharp and
/// dense, and the repeated passes let the deformation converge where a
/// window's particles sit off its centre in a gradient — in glare rows,
/// where the particles nearest the wall drown (`spiv bench paper`, 10
/// seeds, compensated glare rows, linear profile: 0.064 with three passes,
/// 0.031 with five; with the 2-D Gaussian peak and the quintic B-spline
/// of [`Settings::for_compensated_frames`], 20 seeds, quadratic profile:
/// 0.079 with five passes, 0.059 with seven, 0.060 with nine). Noisy
/// frames lose by it: the TFP pair's field went from 3.4 to 4.8 % of U on
/// `spiv bench blasius`, and dwell caps set from it streaked the adaptive
/// pair there, so TFP and adaptive frames keep three.
pub const COMPENSATED_WINDOWS: [usize; 7] = [64, 32, 32, 32, 32, 32, 32];

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
    /// windows validate: eddies below the window, displacements beyond it)
    /// or stood only with its weak peaks judged by the neighbours, report
    /// the dense stage's field ([`dense::DenseMode::Pyramid`]) at the
    /// grid, flagged replaced, instead. Off in the library's
    /// defaults (the closed loops predict only from what PIV validated); on
    /// in `spiv piv` and the Python `piv`.
    #[serde(default)]
    pub dense_fallback: bool,
    /// Try the rescue passes when a pass on the undeformed images fails
    /// (module docs). On in the library's defaults, `spiv piv` and the
    /// Python `piv`; off for the closed loops' spike frames
    /// ([`Settings::for_spike_frames`]), which predict only from what a
    /// pass validated on its own: with it on, relaxed vectors appear
    /// where one n_max streaks the paper's adaptive frames
    /// (`docs/results.md#the-constants-and-what-chose-them`).
    #[serde(default = "yes")]
    pub rescue: bool,
    /// The predictor filter's stencil at the grid's edges
    /// ([`smooth::Edge`]): the line in the defaults; the quadratic for the
    /// wide baseline's measurement (`spiv_host::baseline::measure`).
    #[serde(default)]
    pub edge: smooth::Edge,
    /// Compute each reported vector's uncertainty ([`Field::sigma`]). On
    /// in the library's defaults; `spiv piv` and the Python `piv`, whose
    /// outputs carry no uncertainty, turn it off, and their fields hold
    /// [`NO_SIGMA`].
    #[serde(default = "yes")]
    pub uncertainty: bool,
}

fn yes() -> bool {
    true
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
            rescue: true,
            edge: smooth::Edge::Line,
            uncertainty: true,
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
    /// Without the rescue passes: the closed loops predict only from what
    /// a pass validated on its own.
    pub fn for_spike_frames() -> Settings {
        Settings {
            validation: Validation {
                min_peak_ratio: 1.2,
                ..Validation::default()
            },
            rescue: false,
            ..Settings::default()
        }
    }

    /// [`Settings::for_spike_frames`] with [`COMPENSATED_WINDOWS`], the
    /// 2-D Gaussian peak and quintic B-spline deformation, for
    /// motion-compensated pairs. Their particles are segmented and mapped
    /// to full scale: flat-topped, with sharp edges, so their correlation
    /// peak is broad and not a parabola, and the 9-point Gaussian
    /// regression over its 3 × 3 (Nobach & Honkanen 2005) places it better;
    /// the quintic spline resamples those edges with less error than the
    /// cubic one. The other frames keep the parabola, which does better
    /// on TFP pairs (`docs/results.md#the-constants-and-what-chose-them`).
    pub fn for_compensated_frames() -> Settings {
        Settings {
            windows: COMPENSATED_WINDOWS.to_vec(),
            interp: Interp::Bspline5,
            subpixel: Subpixel::Gaussian2d,
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
    /// Standard uncertainty of each vector's (u, v), px: from the
    /// correlation statistics of the last pass where it measured the
    /// vector ([`correlate::uncertainty`]), from the neighbours where it
    /// replaced it ([`validate::replaced_uncertainty`]); infinite where
    /// invalid.
    pub sigma: Array2<(f64, f64)>,
}

impl Field {
    /// A field on `grid` that measured nothing: every vector invalid at
    /// zero, with no peak and no uncertainty.
    ///
    /// ```
    /// use spiv_piv::{Field, Grid};
    /// let f = Field::unmeasured(Grid::new(64, 64, 32, 16).unwrap());
    /// assert_eq!(f.counts(), (0, 0, 9));
    /// assert!(!f.usable());
    /// ```
    pub fn unmeasured(grid: Grid) -> Field {
        let shape = (grid.ny, grid.nx);
        Field {
            grid,
            u: Array2::zeros(shape),
            v: Array2::zeros(shape),
            state: Array2::from_elem(shape, State::Invalid),
            peak_ratio: Array2::zeros(shape),
            peak_height: Array2::zeros(shape),
            sigma: Array2::from_elem(shape, NO_SIGMA),
        }
    }

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

    /// The field at every pixel of an `h × w` image, as a predictor: the
    /// windows without a measured vector take their measured neighbours'
    /// ([`validate::extended`]; as zeros they would pull their neighbours'
    /// predictor towards zero over a grid step), then Catmull-Rom between
    /// window centres ([`deform::dense`]).
    pub fn predictor(&self, h: usize, w: usize) -> (Array2<f32>, Array2<f32>) {
        let (u, v) = validate::extended(&self.u, &self.v, &self.state);
        deform::dense(&self.grid, &u, &v, h, w)
    }

    /// [`Field::predictor`] row by row ([`deform::Dense`]).
    fn predictor_rows(&self, h: usize, w: usize) -> deform::Dense {
        let (u, v) = validate::extended(&self.u, &self.v, &self.state);
        deform::Dense::new(&self.grid, &u, &v, (h, w))
    }

    /// Whether the field is usable ([`usable`]).
    pub fn usable(&self) -> bool {
        let (valid, replaced, _) = self.counts();
        is_usable(valid, valid + replaced, self.grid.len())
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

/// The one rule for whether a field measured the flow well enough to
/// predict it or to count as a measurement: at least half of its vectors
/// measured (valid or replaced) and at least a quarter valid (passed every
/// test on their own, PIV's own support rule for a pass), so that the
/// replaced ones are filled between measurements, not made up.
pub fn usable(vectors: &[Vector]) -> bool {
    let valid = vectors.iter().filter(|v| v.state == State::Valid).count();
    let measured = vectors.iter().filter(|v| v.state.is_measured()).count();
    is_usable(valid, measured, vectors.len())
}

/// [`usable`] on a field's counts of (valid, replaced, invalid) vectors
/// ([`Field::counts`]).
///
/// ```
/// use spiv_piv::usable_counts;
/// assert!(usable_counts((30, 30, 40)));
/// assert!(!usable_counts((20, 40, 40)));
/// ```
pub fn usable_counts((valid, replaced, invalid): (usize, usize, usize)) -> bool {
    is_usable(valid, valid + replaced, valid + replaced + invalid)
}

fn is_usable(valid: usize, measured: usize, all: usize) -> bool {
    let all = all.max(1) as f64;
    valid as f64 >= MIN_SUPPORT * all && 2 * measured >= all as usize
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
    if let Some(w) = s.windows.windows(2).find(|w| w[1] > w[0]) {
        return Err(PivError::Settings(format!(
            "windows {} then {} px: each pass refines the last, so a window may not grow",
            w[0], w[1]
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
///
/// A random dot pattern moved 3 px right and 1 px down:
///
/// ```
/// use ndarray::Array2;
/// use spiv_piv::{piv, Settings, State};
///
/// let dots = |dx: f32, dy: f32| {
///     let mut seed = 7u32;
///     let mut img = Array2::<f32>::zeros((96, 96));
///     for _ in 0..300 {
///         seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
///         let x = (seed >> 8) as f32 / 16_777_216.0 * 96.0 + dx;
///         seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
///         let y = (seed >> 8) as f32 / 16_777_216.0 * 96.0 + dy;
///         for ((r, c), v) in img.indexed_iter_mut() {
///             let d2 = (c as f32 - x).powi(2) + (r as f32 - y).powi(2);
///             *v += 200.0 * (-d2 / 2.0).exp();
///         }
///     }
///     img
/// };
/// let field = piv(&dots(0.0, 0.0), &dots(3.0, 1.0), None, &Settings::default()).unwrap();
/// let mid = (field.u.nrows() / 2, field.u.ncols() / 2);
/// assert_eq!(field.state[mid], State::Valid);
/// assert!((field.u[mid] - 3.0).abs() < 0.1 && (field.v[mid] - 1.0).abs() < 0.1);
/// ```
pub fn piv(
    a: &Array2<f32>,
    b: &Array2<f32>,
    mask: Option<&Array2<bool>>,
    s: &Settings,
) -> Result<Field, PivError> {
    piv_predicted(a, b, mask, s, None)
}

/// [`piv`] with a predicted field (any grid, px per pair of `a` and `b`)
/// that deforms the first pass, as a previous pass's field deforms the
/// next: the passes then measure what the prediction missed.
pub fn piv_predicted(
    a: &Array2<f32>,
    b: &Array2<f32>,
    mask: Option<&Array2<bool>>,
    s: &Settings,
    initial: Option<&Field>,
) -> Result<Field, PivError> {
    piv_ensemble(&[(a, b)], mask, s, initial)
}

/// Ensemble PIV (Meinhart, Wereley & Santiago 2000): several pairs of the
/// same flow, each pair `(a, b)` the same displacement apart, measured as
/// one. Every window's correlation planes of all pairs are summed before
/// the peak is found, so particles too sparse or too dim for any one pair
/// add up to one strong peak; the passes, validation and replacement are
/// [`piv_predicted`]'s, each pass deforming every pair by the same field.
/// Clipped areas of any image are left out of every pair. One pair is
/// plain PIV.
pub fn piv_ensemble(
    pairs: &[(&Array2<f32>, &Array2<f32>)],
    mask: Option<&Array2<bool>>,
    s: &Settings,
    initial: Option<&Field>,
) -> Result<Field, PivError> {
    let (h, w) = checked_size(pairs, mask, s)?;
    let raw = pairs[0];
    // The clipped areas come from the raw images: found beside the
    // high-pass.
    let (filtered, base) = rayon::join(
        || prefiltered(pairs, s),
        || excluded_pixels(pairs, mask, s, (h, w)),
    );
    let images: Vec<(&Array2<f32>, &Array2<f32>)> = if filtered.is_empty() {
        pairs.to_vec()
    } else {
        filtered.iter().map(|(a, b)| (a, b)).collect()
    };
    let resamplers = (s.windows.len() > 1 || initial.is_some()).then(|| {
        images
            .par_iter()
            .map(|&(a, b)| {
                rayon::join(
                    || resample::Resampler::new(a, s.interp),
                    || resample::Resampler::new(b, s.interp),
                )
            })
            .collect()
    });
    let passes = Passes {
        base,
        images,
        resamplers,
        mask,
        s,
        size: (h, w),
    };
    let m = passes.measure(initial)?;
    Ok(concluded(
        m.field,
        m.support,
        m.weak,
        m.good.as_ref(),
        raw,
        s,
    ))
}

/// What [`Passes::measure`] leaves: the reported pass's field and its
/// support, whether it judged its peaks by the neighbours, and the last
/// field that passed (any grid).
struct Measured {
    field: Field,
    support: f64,
    weak: bool,
    good: Option<Field>,
}

impl Passes<'_> {
    /// Every pass of the settings' windows, from `initial` if given: each
    /// pass but the last deforms by the filtered predictor, a failed pass
    /// on undeformed images is rescued by coarser passes, and a failed pass
    /// after a good one on the same grid leaves that one standing.
    fn measure(&self, initial: Option<&Field>) -> Result<Measured, PivError> {
        measured(&|by, spec| self.run(by, spec), self.s, self.size, initial)
    }
}

/// [`Passes::measure`] with the pass given as `run`.
fn measured(
    run: &PassFn<'_>,
    s: &Settings,
    (h, w): (usize, usize),
    initial: Option<&Field>,
) -> Result<Measured, PivError> {
    let mut prev: Option<(Field, f64)> = None;
    let mut predictor: Option<Field> = initial.cloned();
    // The last field that passed (any grid): what a failed last pass
    // degrades to.
    let mut good: Option<Field> = None;
    // Once a rescue needed the neighbours to judge weak peaks, so do the
    // passes after it: the frames' peaks do not grow stronger.
    let mut relaxed = false;
    // Whether the reported pass judged its peaks by the neighbours (then
    // none of its vectors is valid).
    let mut weak = false;
    let npass = s.windows.len();
    // What the standing pass was run on, to run it again with its
    // uncertainties should a failed last pass leave it standing.
    let mut prev_input: Option<(Option<Field>, PassSpec)> = None;
    for (pi, &size) in s.windows.iter().enumerate() {
        let last = pi + 1 == npass;
        let spec = PassSpec {
            relaxed,
            sigma: last && s.uncertainty,
            ..PassSpec::plain(size)
        };
        // Every pass but the last deforms by the filtered predictor
        // (`smooth`); the last one measures the residual of the field as
        // it stands, so that what it reports is not smoothed.
        let filtered = match &predictor {
            Some(f) if pi + 1 < npass => Some(smooth::filtered(f, s.edge)),
            _ => None,
        };
        let by = filtered.or_else(|| predictor.clone());
        let (mut field, mut support) = run(by.as_ref(), spec)?;
        let mut input = (by, spec);
        let good_same_grid = prev
            .as_ref()
            .is_some_and(|(f, sup)| *sup >= MIN_SUPPORT && f.grid == field.grid);
        if s.rescue && support < MIN_SUPPORT && predictor.is_none() && !good_same_grid {
            // A pass on the undeformed images failed: a signal, not a
            // verdict. Larger displacements than the window's quarter rule
            // or too few particles per window both fail so; the rescue
            // passes measure a coarser field, which then predicts (deforms)
            // this pass again.
            if let Some((coarse, how)) = rescue(run, size, w, h)? {
                relaxed |= how.relaxed;
                let spec = PassSpec {
                    relaxed,
                    sigma: last && s.uncertainty,
                    ..PassSpec::plain(size)
                };
                let (f2, s2) = run(Some(&coarse), spec)?;
                if s2 >= MIN_SUPPORT {
                    (field, support) = (f2, s2);
                    input = (Some(coarse.clone()), spec);
                }
                good = Some(coarse);
            }
        }
        // A pass where fewer than a quarter of the windows with signal
        // passed validation has failed (e.g. displacements beyond the
        // window): its replaced field would only spread noise. After a
        // good pass on the same grid (a repeated final window), that pass
        // stands: it stays the predictor and the result. Otherwise the
        // next pass starts again from the undeformed images.
        if support < MIN_SUPPORT && good_same_grid {
            continue;
        }
        if support >= MIN_SUPPORT {
            good = Some(field.clone());
        }
        predictor = (support >= MIN_SUPPORT).then(|| field.clone());
        weak = relaxed;
        prev = Some((field, support));
        prev_input = Some(input);
    }
    let (mut field, support) = prev.ok_or_else(|| PivError::Settings("no windows given".into()))?;
    if let Some((by, spec)) = prev_input.filter(|(_, r)| s.uncertainty && !r.sigma) {
        // The last pass failed and an earlier one on its grid stands:
        // the same pass again (the same vectors), with uncertainties.
        field = run(
            by.as_ref(),
            PassSpec {
                sigma: true,
                ..spec
            },
        )?
        .0;
    }
    Ok(Measured {
        field,
        support,
        weak,
        good,
    })
}

/// The images' size after checking that every image, and the mask, has
/// the first image's size and that `s` fits it.
fn checked_size(
    pairs: &[(&Array2<f32>, &Array2<f32>)],
    mask: Option<&Array2<bool>>,
    s: &Settings,
) -> Result<(usize, usize), PivError> {
    let Some(&(a0, _)) = pairs.first() else {
        return Err(PivError::Settings("no image pair given".into()));
    };
    let dim = a0.dim();
    for (a, b) in pairs.iter().flat_map(|(a, b)| [(a0, *a), (a0, *b)]) {
        if a.dim() != b.dim() {
            let ((ha, wa), (hb, wb)) = (a.dim(), b.dim());
            return Err(PivError::SizeMismatch(wa, ha, wb, hb));
        }
    }
    if let Some(m) = mask {
        if m.dim() != dim {
            return Err(PivError::MaskSize(m.dim().1, m.dim().0, dim.1, dim.0));
        }
    }
    check(s, dim)?;
    Ok(dim)
}

/// Pixels every pass leaves out: the user's mask and clipped pixels of
/// any raw image (a clipped area is large next to a residual
/// displacement, so its undeformed outline serves every pass); `None`
/// when there are none.
fn excluded_pixels(
    pairs: &[(&Array2<f32>, &Array2<f32>)],
    mask: Option<&Array2<bool>>,
    s: &Settings,
    (h, w): (usize, usize),
) -> Option<Array2<bool>> {
    let grow = 3 * (s.highpass.max(0.0).round() as usize);
    let clipped: Vec<Array2<bool>> = pairs
        .par_iter()
        .flat_map_iter(|&(a, b)| [a, b])
        .filter_map(|img| filter::clipped_areas(img, s.clip.level(img), grow))
        .collect();
    (mask.is_some() || !clipped.is_empty()).then(|| {
        let mut ex = mask
            .cloned()
            .unwrap_or_else(|| Array2::from_elem((h, w), false));
        for c in &clipped {
            ex.zip_mut_with(c, |e, &c| *e |= c);
        }
        ex
    })
}

/// The pairs high-passed by `s.highpass` (empty when it is off: the
/// passes then correlate the images as given).
fn prefiltered(
    pairs: &[(&Array2<f32>, &Array2<f32>)],
    s: &Settings,
) -> Vec<(Array2<f32>, Array2<f32>)> {
    if s.highpass <= 0.0 {
        return Vec::new();
    }
    pairs
        .par_iter()
        .map(|&(a, b)| {
            rayon::join(
                || filter::highpass(a, s.highpass),
                || filter::highpass(b, s.highpass),
            )
        })
        .collect()
}

/// What every pass of one [`piv_ensemble`] call shares.
struct Passes<'a> {
    /// The pairs as correlated (high-passed or as given).
    images: Vec<(&'a Array2<f32>, &'a Array2<f32>)>,
    /// Their resamplers, when a pass deforms.
    resamplers: Option<Vec<(resample::Resampler, resample::Resampler)>>,
    /// Pixels every pass leaves out ([`excluded_pixels`]).
    base: Option<Array2<bool>>,
    /// The user's mask.
    mask: Option<&'a Array2<bool>>,
    s: &'a Settings,
    /// Height and width, px.
    size: (usize, usize),
}

impl Passes<'_> {
    /// One pass of `spec.size`-px windows on the images deformed by `by`
    /// (or as they are): its field and support.
    fn run(&self, by: Option<&Field>, spec: PassSpec) -> Result<(Field, f64), PivError> {
        let (h, w) = self.size;
        let size = spec.size;
        let step = self.s.step(size);
        let grid = Grid::new(w, h, size, step).ok_or(PivError::TooSmall(w, h, size))?;
        let (deformed, pred, outside) = match by {
            None => (Vec::new(), None, self.base.clone()),
            Some(f) => {
                let d = f.predictor_rows(h, w);
                let Some(rs) = &self.resamplers else {
                    return Err(PivError::Settings("internal: no resampler".into()));
                };
                let mut outside = self.base.clone();
                let mut deformed = Vec::with_capacity(rs.len());
                for (ra, rb) in rs {
                    let (da, db, out) = deform::deform(ra, rb, &d);
                    match &mut outside {
                        Some(o) => o.zip_mut_with(&out, |o, &x| *o |= x),
                        None => outside = Some(out),
                    }
                    deformed.push((da, db));
                }
                (deformed, Some(centres(&d, &grid)), outside)
            }
        };
        let now: Vec<(&Array2<f32>, &Array2<f32>)> = if deformed.is_empty() {
            self.images.clone()
        } else {
            deformed.iter().map(|(a, b)| (a, b)).collect()
        };
        let excluded = outside.as_ref().or(self.mask);
        Ok(pass(
            &now,
            self.mask,
            excluded,
            grid,
            spec,
            pred.as_ref(),
            self.s,
        ))
    }
}

/// The reported field from the last pass (`support`: the share of windows
/// with signal that passed; `weak`: its peaks were judged by the
/// neighbours). A last pass that failed as a whole, or stood only weakly,
/// gives way to the dense stage on the first raw pair when
/// `s.dense_fallback` is on (it measures below the window and beyond its
/// quarter rule; its field at the grid is reported as replaced, windows
/// without signal stay invalid); else to the last good pass's field
/// (`good`, flagged replaced where windows have signal); else nothing is
/// reported as measured — what passed its tests are chance matches
/// (overlapping windows share particles, so two neighbours can agree by
/// chance).
fn concluded(
    mut field: Field,
    support: f64,
    weak: bool,
    good: Option<&Field>,
    raw: (&Array2<f32>, &Array2<f32>),
    s: &Settings,
) -> Field {
    let (h, w) = raw.0.dim();
    if (support < MIN_SUPPORT || weak) && s.dense_fallback {
        // On raw images: their high-pass would remove the particles' own
        // low frequencies, which guide the dense stage's coarse levels.
        let f = dense::dense_flow(raw.0, raw.1, None, &dense::DenseMode::Pyramid.settings());
        dense::fill(&mut field, &f);
    } else if let (true, Some(g)) = (support < MIN_SUPPORT, good) {
        degrade_to(&mut field, g, h, w);
    } else if support < MIN_SUPPORT {
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
        field.sigma.fill(NO_SIGMA);
    }
    field
}

/// The uncertainty of a vector that was not measured, px.
pub const NO_SIGMA: (f64, f64) = (f64::INFINITY, f64::INFINITY);

/// A pass on the images deformed by a field (or as they are), giving its
/// field and support.
type PassFn<'a> = dyn Fn(Option<&Field>, PassSpec) -> Result<(Field, f64), PivError> + 'a;

/// How one pass correlates and validates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PassSpec {
    /// Window side, px.
    size: usize,
    /// Side of the area of B searched, px (≥ size).
    search: usize,
    /// The peak ratio is judged by the neighbours, not by the floor: a
    /// vector with a weak peak stands when the normalised median test,
    /// applied until nothing more fails, keeps it.
    relaxed: bool,
    /// Undeformed peaks beyond the quarter rule are measured again over
    /// an area twice the window's side (rescue passes only: on a pass that
    /// validates, the wider view adds nothing but a chance to lock onto a
    /// stray bright feature, such as a hot pixel of the paper's adaptive
    /// frames 40 px from its twin).
    recheck: bool,
    /// The peaks' uncertainties are computed: on the last pass, whose
    /// field is reported (a coarser field that stands in for a failed one
    /// is reported without them); the passes before it skip them.
    sigma: bool,
}

impl PassSpec {
    fn plain(size: usize) -> PassSpec {
        PassSpec {
            size,
            search: size,
            relaxed: false,
            recheck: false,
            sigma: false,
        }
    }
}

/// The rescue passes of a failed pass of `size`-px windows, tried in turn
/// on the undeformed images until one passes:
/// 1. the same windows searched over an area twice their side in B
///    (OpenPIV's extended search area: the quarter rule then holds for
///    displacements up to half the window);
/// 2. windows twice the side (more particles per window);
/// 3. the same windows with the peak ratio judged by the neighbours
///    (frames whose true peaks stand barely above the next, as spike
///    frames' do), the median test iterated.
///
/// Passes that do not fit the image are skipped. The winner is a coarse
/// field that predicts the pass again (the multigrid predictor); `None`
/// when every rescue pass fails too.
fn rescue(
    run: &PassFn<'_>,
    size: usize,
    w: usize,
    h: usize,
) -> Result<Option<(Field, PassSpec)>, PivError> {
    let fits = |r: &PassSpec| r.search <= w.min(h) && r.search <= MAX_SEARCH;
    let specs = [
        PassSpec {
            search: 2 * size,
            ..PassSpec::plain(size)
        },
        PassSpec::plain(2 * size),
        PassSpec {
            relaxed: true,
            ..PassSpec::plain(size)
        },
    ];
    for spec in specs.into_iter().filter(fits) {
        let spec = PassSpec {
            recheck: true,
            ..spec
        };
        let (f, support) = run(None, spec)?;
        if support >= MIN_SUPPORT {
            return Ok(Some((f, spec)));
        }
    }
    Ok(None)
}

/// The widest correlation peak a relaxed pass measures, Gaussian σ in
/// px. A particle image of σ 1–1.5 px correlates to a peak of σ 1.4–2.1
/// px; a streak's correlation is a ridge many px long.
const MAX_PEAK_WIDTH: f64 = 4.0;

/// Sweeps of the median test on a relaxed pass.
const RELAXED_SWEEPS: usize = 4;

/// The largest search area a rescue pass correlates, px.
const MAX_SEARCH: usize = 1024;

/// The predictor `d` at every window centre of `grid` (the mean of the
/// central 2×2 pixels for even windows), px.
fn centres(d: &deform::Dense, grid: &Grid) -> Array2<(f64, f64)> {
    let n = grid.size;
    let w = d.size().1;
    let mut out = Array2::from_elem((grid.ny, grid.nx), (0.0, 0.0));
    let (mut u1, mut v1, mut u2, mut v2) = (vec![0.0; w], vec![0.0; w], vec![0.0; w], vec![0.0; w]);
    for r in 0..grid.ny {
        let (_, y0) = grid.origin(r, 0);
        d.row(y0 + (n - 1) / 2, &mut u1, &mut v1);
        d.row(y0 + n / 2, &mut u2, &mut v2);
        for c in 0..grid.nx {
            let (x0, _) = grid.origin(r, c);
            let (j1, j2) = (x0 + (n - 1) / 2, x0 + n / 2);
            let m = |a: &[f32], b: &[f32]| 0.25 * f64::from(a[j1] + a[j2] + b[j1] + b[j2]);
            out[[r, c]] = (m(&u1, &u2), m(&v1, &v2));
        }
    }
    out
}

/// Fills `field` (a failed pass) from `from` (a field that passed, on
/// another grid), interpolated at its centres and flagged replaced, where
/// its windows have signal; the rest stays invalid.
fn degrade_to(field: &mut Field, from: &Field, h: usize, w: usize) {
    let (du, dv) = from.predictor(h, w);
    let grid = field.grid;
    for r in 0..grid.ny {
        for c in 0..grid.nx {
            let (x, y) = grid.centre(r, c);
            let (i, j) = (
                (y.round() as usize).min(h - 1),
                (x.round() as usize).min(w - 1),
            );
            let signal = field.state[[r, c]] != State::Invalid || field.peak_height[[r, c]] > 0.0;
            if signal {
                field.u[[r, c]] = f64::from(du[[i, j]]);
                field.v[[r, c]] = f64::from(dv[[i, j]]);
                field.state[[r, c]] = State::Replaced;
            } else {
                field.u[[r, c]] = 0.0;
                field.v[[r, c]] = 0.0;
                field.state[[r, c]] = State::Invalid;
            }
            // A coarser pass's value at this window: no statistics of its own.
            field.sigma[[r, c]] = NO_SIGMA;
        }
    }
}

/// One pass on (possibly deformed) images; `pred` is the dense predictor
/// the images were deformed by; `mask` holds the user's masked pixels (a
/// window whose centre is masked has no vector) and `excluded` every pixel
/// the correlation leaves out (the mask and, after deformation, pixels with
/// no data).
fn pass(
    pairs: &[(&Array2<f32>, &Array2<f32>)],
    mask: Option<&Array2<bool>>,
    excluded: Option<&Array2<bool>>,
    grid: Grid,
    spec: PassSpec,
    pred: Option<&Array2<(f64, f64)>>,
    s: &Settings,
) -> (Field, f64) {
    let n = grid.size;
    let (h, w) = pairs[0].0.dim();
    // An extended search area (`search` > n, the caller checked it fits
    // the image): B's `search`-px area around the window, A's window at
    // its place inside it, the rest of A at the window's mean (zero after
    // the correlation removes the mean).
    let search = if spec.search > n && spec.search <= w.min(h) {
        spec.search
    } else {
        n
    };
    let plan = Plan::new(search);
    let wide = (spec.recheck && pred.is_none() && search == n && 2 * n <= w.min(h))
        .then(|| Plan::new(2 * n));
    let ctx = PassWindows {
        pairs,
        mask,
        excluded,
        grid: &grid,
        plan: &plan,
        wide: wide.as_ref(),
        pred,
        spec,
        s,
    };
    let results: Vec<WindowResult> = (0..grid.len())
        .into_par_iter()
        .map_init(
            || (Ensemble::new(&plan), None::<Ensemble>),
            |(sc, wide_sc), k| ctx.window(k, sc, wide_sc),
        )
        .collect();
    assembled(grid, results, spec, s)
}

/// What a pass's windows share.
struct PassWindows<'a> {
    pairs: &'a [(&'a Array2<f32>, &'a Array2<f32>)],
    mask: Option<&'a Array2<bool>>,
    excluded: Option<&'a Array2<bool>>,
    grid: &'a Grid,
    plan: &'a Plan,
    /// The plan of the area twice the window's side that re-checks peaks
    /// beyond the quarter rule on undeformed images.
    wide: Option<&'a Plan>,
    pred: Option<&'a Array2<(f64, f64)>>,
    spec: PassSpec,
    s: &'a Settings,
}

impl PassWindows<'_> {
    /// Window `k` of the grid (row-major), with the scratch of this thread.
    fn window(&self, k: usize, sc: &mut Ensemble, wide_sc: &mut Option<Ensemble>) -> WindowResult {
        let (grid, n) = (self.grid, self.grid.size);
        let (r, c) = (k / grid.nx, k % grid.nx);
        let (x0, y0) = grid.origin(r, c);
        let (xc, yc) = (x0 + n / 2, y0 + n / 2);
        if self
            .mask
            .is_some_and(|m| m[[yc.min(m.dim().0 - 1), xc.min(m.dim().1 - 1)]])
        {
            return (0.0, 0.0, 0.0, 0.0, Some(NoPeak::NoSignal), NO_SIGMA);
        }
        let region = Region {
            pairs: self.pairs,
            excluded: self.excluded,
            origin: (x0, y0),
            n,
        };
        let mut peak = region.correlate(self.plan, sc, self.s.subpixel, self.spec.sigma);
        // Undeformed, a peak beyond the quarter rule may be an alias (a
        // displacement beyond half the window wraps around) or a match by
        // chance: the window is measured again over an area twice its
        // side, which sees it whole. The wider view wins only where it
        // disagrees and its peak stands out more (an alias is a weak
        // match; the wider area holds every particle of the window).
        if let (Ok(p), Some(plan2)) = (&peak, self.wide) {
            if p.dx.hypot(p.dy) > n as f64 / 4.0 {
                let sc2 = wide_sc.get_or_insert_with(|| Ensemble::new(plan2));
                if let Ok(q) = region.correlate(plan2, sc2, self.s.subpixel, self.spec.sigma) {
                    let differs = (q.dx - p.dx).hypot(q.dy - p.dy) > 1.0;
                    if differs && q.ratio > p.ratio && q.width <= MAX_PEAK_WIDTH {
                        peak = Ok(q);
                    }
                }
            }
        }
        let (pu, pv) = self.pred.map_or((0.0, 0.0), |p| p[[r, c]]);
        match peak {
            // After deformation the residual must be small: a correction
            // beyond a quarter window means the predictor was wrong here,
            // so the peak is not trusted.
            Ok(p) if self.pred.is_some() && p.dx.hypot(p.dy) > n as f64 / 4.0 => (
                pu + p.dx,
                pv + p.dy,
                0.0,
                p.height,
                Some(NoPeak::NoPeak),
                NO_SIGMA,
            ),
            // A ridge (a streak's correlation, flat along the streak) has
            // no position to measure: where the peak ratio is judged by the
            // neighbours, a cluster of ridges would agree on wherever noise
            // put their maxima (near zero, next to a static glare).
            Ok(p) if self.spec.relaxed && p.width > MAX_PEAK_WIDTH => (
                pu + p.dx,
                pv + p.dy,
                p.ratio,
                p.height,
                Some(NoPeak::NoPeak),
                NO_SIGMA,
            ),
            Ok(p) => (pu + p.dx, pv + p.dy, p.ratio, p.height, None, p.sigma),
            Err(e) => (pu, pv, 0.0, 0.0, Some(e), NO_SIGMA),
        }
    }
}

/// A pass's field from its windows' results: states from the peaks and
/// the peak ratio, the normalised median test (repeated on a relaxed
/// pass), the share of windows with signal that passed (the support),
/// replacement and the replaced vectors' uncertainties.
fn assembled(grid: Grid, results: Vec<WindowResult>, spec: PassSpec, s: &Settings) -> (Field, f64) {
    let min_ratio = if spec.relaxed {
        1.0
    } else {
        s.validation.min_peak_ratio
    };
    let shape = (grid.ny, grid.nx);
    let mut u = Array2::zeros(shape);
    let mut v = Array2::zeros(shape);
    let mut ratio = Array2::zeros(shape);
    let mut height = Array2::zeros(shape);
    let mut state = Array2::from_elem(shape, State::Valid);
    let mut replaceable = Array2::from_elem(shape, true);
    let mut sigma = Array2::from_elem(shape, NO_SIGMA);
    for (k, (du, dv, pr, ph, err, sg)) in results.into_iter().enumerate() {
        let idx = [k / grid.nx, k % grid.nx];
        u[idx] = du;
        v[idx] = dv;
        ratio[idx] = pr;
        height[idx] = ph;
        sigma[idx] = sg;
        match err {
            Some(NoPeak::NoSignal) => {
                state[idx] = State::Invalid;
                replaceable[idx] = false;
            }
            Some(NoPeak::NoPeak) => state[idx] = State::Invalid,
            None if pr < min_ratio => state[idx] = State::Invalid,
            None => {}
        }
    }
    // Relaxed: until nothing more fails (a cluster of chance peaks loses
    // its support one ring at a time), at most a few sweeps.
    let sweeps = if spec.relaxed { RELAXED_SWEEPS } else { 1 };
    for _ in 0..sweeps {
        let rejected = validate::median_test(
            &u,
            &v,
            &mut state,
            s.validation.median_threshold,
            s.validation.median_eps,
        );
        if rejected == 0 {
            break;
        }
    }
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
    validate::replaced_uncertainty(&u, &v, &state, &mut sigma);
    if spec.relaxed {
        // Weak peaks the neighbours confirm are used (they deform the next
        // pass and are reported) but never called valid: valid keeps
        // meaning a peak that stands on its own and agrees with its
        // neighbours, so a relaxed pass cannot pass clusters of vectors
        // locked near zero on streaked frames.
        for st in state.iter_mut() {
            if *st == State::Valid {
                *st = State::Replaced;
            }
        }
    }
    let field = Field {
        grid,
        u,
        v,
        state,
        peak_ratio: ratio,
        peak_height: height,
        sigma,
    };
    (field, support)
}

/// What one window of a pass found: displacement (u, v), peak ratio and
/// height, why it has no peak (if so), and its uncertainty.
type WindowResult = (f64, f64, f64, f64, Option<NoPeak>, (f64, f64));

/// One window of a pass: where it sits in the (possibly deformed) pairs.
struct Region<'i> {
    pairs: &'i [(&'i Array2<f32>, &'i Array2<f32>)],
    /// Pixels the correlation leaves out.
    excluded: Option<&'i Array2<bool>>,
    /// Top-left pixel of the window, (x, y).
    origin: (usize, usize),
    /// Window side, px.
    n: usize,
}

/// A thread's buffers for one window size: the correlation scratch and
/// the sum of an ensemble's correlation planes.
struct Ensemble {
    sc: Scratch,
    sum: Vec<f32>,
}

impl Ensemble {
    fn new(plan: &Plan) -> Ensemble {
        Ensemble {
            sc: Scratch::new(plan),
            sum: vec![0.0; plan.size() * plan.size()],
        }
    }
}

impl Region<'_> {
    /// Correlates the window of each A with the area of its B of `plan`'s
    /// side around it (the window itself when that equals `n`; larger
    /// areas must fit the image): the displacement of B relative to A,
    /// px. One pair is [`correlate`]; several sum their normalised planes
    /// (pairs whose windows have no signal add nothing), and the peak's
    /// uncertainty adds the pairs' variances. Without `sigma` the
    /// uncertainty is not computed and left at [`NO_SIGMA`].
    fn correlate(
        &self,
        plan: &Plan,
        en: &mut Ensemble,
        method: Subpixel,
        sigma: bool,
    ) -> Result<correlate::Peak, NoPeak> {
        if let [(a, b)] = self.pairs {
            self.fill(a, b, plan, &mut en.sc);
            let p = correlate::plane(plan, &mut en.sc)?;
            let (peak, at) = correlate::locate(plan.size(), en.sc.plane(), p.norm, method)?;
            if !sigma {
                return Ok(correlate::Peak {
                    sigma: NO_SIGMA,
                    ..peak
                });
            }
            return Ok(correlate::with_uncertainty(plan, &mut en.sc, peak, at, p));
        }
        let n = plan.size();
        en.sum.fill(0.0);
        let mut used = 0usize;
        for (a, b) in self.pairs {
            self.fill(a, b, plan, &mut en.sc);
            match correlate::plane(plan, &mut en.sc) {
                Ok(p) => {
                    let k = p.norm as f32;
                    for (t, &c) in en.sum.iter_mut().zip(en.sc.plane()) {
                        *t += c * k;
                    }
                    used += 1;
                }
                Err(NoPeak::NoSignal) => continue,
                Err(e) => return Err(e),
            }
        }
        if used == 0 {
            return Err(NoPeak::NoSignal);
        }
        let norm = 1.0 / used as f64;
        let (mut peak, at) = correlate::locate(n, &en.sum, norm, method)?;
        if !sigma {
            peak.sigma = NO_SIGMA;
            return Ok(peak);
        }
        // The asymmetry's variance over the pairs, each normalised as its
        // plane entered the sum.
        let (mut vu, mut vv) = (0.0, 0.0);
        for (a, b) in self.pairs {
            self.fill(a, b, plan, &mut en.sc);
            if let Ok(p) = correlate::plane(plan, &mut en.sc) {
                let (su, sv) = correlate::spread(&mut en.sc, n, at, p.means);
                vu += (su * p.direct).powi(2);
                vv += (sv * p.direct).powi(2);
            }
        }
        let sd = (vu.sqrt() * norm, vv.sqrt() * norm);
        peak.sigma = correlate::peak_uncertainty(n, &en.sum, norm, at, sd);
        Ok(peak)
    }

    /// Copies the window of `a` and the searched area of `b` (and their
    /// excluded pixels) into the scratch buffers.
    fn fill(&self, a: &Array2<f32>, b: &Array2<f32>, plan: &Plan, sc: &mut Scratch) {
        let (excluded, n) = (self.excluded, self.n);
        let (x0, y0) = self.origin;
        let (h, w) = a.dim();
        let search = plan.size();
        // The area of B searched (the window itself, or `search`
        // px around it, kept inside the image); the scratch
        // buffers hold it.
        let around =
            |o: usize, len: usize| (o + n / 2).saturating_sub(search / 2).min(len - search);
        let (bx, by) = if search > n {
            (around(x0, w), around(y0, h))
        } else {
            (x0, y0)
        };
        sc.masked.clear();
        if let Some(m) = excluded {
            // Most windows hold no excluded pixel: a scan of the
            // window's row slices (vectorised) says so.
            let rows = || (by..by + search).map(|i| m.row(i));
            let any = rows().any(|r| match r.as_slice() {
                Some(r) => any_true(&r[bx..bx + search]),
                None => (bx..bx + search).any(|j| r[j]),
            });
            if any {
                for row in rows() {
                    sc.masked.extend((0..search).map(|j| row[bx + j]));
                }
            }
        }
        let k = search;
        for i in 0..k {
            let ra = a.row(by + i);
            let rb = b.row(by + i);
            let (da, db) = (&mut sc.a[i * k..(i + 1) * k], &mut sc.b[i * k..(i + 1) * k]);
            match (ra.as_slice(), rb.as_slice()) {
                (Some(ra), Some(rb)) => {
                    copy_row(da, &ra[bx..bx + k]);
                    copy_row(db, &rb[bx..bx + k]);
                }
                _ => {
                    for j in 0..k {
                        da[j] = ra[bx + j];
                        db[j] = rb[bx + j];
                    }
                }
            }
        }
        if search > n {
            pad_outside(&mut sc.a, &sc.masked, search, (x0 - bx, y0 - by), n);
        }
    }
}

/// `dst.copy_from_slice(src)`, inlined for the common window sides: a
/// library `memcpy` call per 32-sample row cost more than the copy.
#[inline(always)]
fn copy_row(dst: &mut [f32], src: &[f32]) {
    fn fixed<const N: usize>(dst: &mut [f32], src: &[f32]) -> bool {
        match (<&mut [f32; N]>::try_from(dst), <&[f32; N]>::try_from(src)) {
            (Ok(d), Ok(s)) => {
                *d = *s;
                true
            }
            _ => false,
        }
    }
    if !(fixed::<32>(dst, src) || fixed::<64>(dst, src) || fixed::<16>(dst, src)) {
        dst.copy_from_slice(src);
    }
}

/// Whether any of `v` is true: an OR over blocks of 32 (vectorises, where
/// `contains` on bools tests one at a time).
fn any_true(v: &[bool]) -> bool {
    let mut blocks = v.chunks_exact(32);
    let hit = blocks.any(|b| b.iter().fold(0u8, |acc, &x| acc | u8::from(x)) != 0);
    hit || blocks.remainder().contains(&true)
}

/// Sets the pixels of the `k × k` buffer `a` outside the `n × n` window
/// at `(ox, oy)` to the window's mean over its unmasked pixels, so that
/// they add nothing to the correlation once the mean is removed.
fn pad_outside(a: &mut [f32], masked: &[bool], k: usize, (ox, oy): (usize, usize), n: usize) {
    let inside = |i: usize, j: usize| (oy..oy + n).contains(&i) && (ox..ox + n).contains(&j);
    let (mut sum, mut cnt) = (0.0f64, 0usize);
    for i in oy..oy + n {
        for j in ox..ox + n {
            if !masked.get(i * k + j).copied().unwrap_or(false) {
                sum += f64::from(a[i * k + j]);
                cnt += 1;
            }
        }
    }
    let mean = (sum / cnt.max(1) as f64) as f32;
    for (idx, x) in a.iter_mut().enumerate() {
        if !inside(idx / k, idx % k) {
            *x = mean;
        }
    }
}

/// An upright `w × h` gray image as PIV input.
pub fn to_f32(data: &[u16], w: usize, h: usize) -> Array2<f32> {
    Array2::from_shape_fn((h, w), |(i, j)| f32::from(data[i * w + j]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;

    /// A stand-in for a pass on a 128² image: the support `supports[k]`
    /// for the k-th call, uncertainties only where the spec asks for them.
    /// Returns the passes it was called with.
    fn passes(windows: &[usize], supports: &[f64]) -> (Measured, Vec<PassSpec>) {
        let s = Settings {
            windows: windows.to_vec(),
            rescue: false,
            ..Settings::default()
        };
        let calls = RefCell::new(Vec::new());
        let run = |_: Option<&Field>, spec: PassSpec| {
            let k = calls.borrow().len();
            calls.borrow_mut().push(spec);
            let grid = Grid::new(128, 128, spec.size, s.step(spec.size)).expect("grid");
            let mut f = Field::unmeasured(grid);
            if spec.sigma {
                f.sigma.fill((0.05, 0.05));
            }
            Ok((f, supports[k]))
        };
        let m = measured(&run, &s, (128, 128), None).expect("measured");
        (m, calls.into_inner())
    }

    #[test]
    fn only_the_last_pass_computes_uncertainties() {
        let (m, calls) = passes(&[64, 32, 32], &[1.0, 1.0, 1.0]);
        let asked: Vec<bool> = calls.iter().map(|r| r.sigma).collect();
        assert_eq!(asked, [false, false, true]);
        assert!(m.field.sigma.iter().all(|&(a, b)| a == 0.05 && b == 0.05));
    }

    #[test]
    fn a_pass_left_standing_is_run_again_with_uncertainties() {
        // The last 32-px pass fails: the one before it stands, and is run
        // once more (same spec, same input) to give its uncertainties.
        let (m, calls) = passes(&[64, 32, 32], &[1.0, 1.0, 0.0, 1.0]);
        let asked: Vec<(usize, bool)> = calls.iter().map(|r| (r.size, r.sigma)).collect();
        assert_eq!(asked, [(64, false), (32, false), (32, true), (32, true)]);
        assert_eq!(m.field.grid.size, 32);
        assert!(m.field.sigma.iter().all(|&(a, _)| a == 0.05));
    }
}
