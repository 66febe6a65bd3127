//! PIV settings from names and numbers, as a user gives them: the `spiv
//! piv` options and the Python binding's keywords share this one parser,
//! so both accept and refuse the same values with the same messages.

use super::{Clip, Interp, PivError, Settings, Subpixel, Validation};

/// What a user asks of a PIV run (the CLI's defaults in
/// [`PivOptions::default`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PivOptions {
    /// Window side of each pass, px (4..=1024); the list sets the passes.
    pub windows: Vec<usize>,
    /// Overlap of neighbouring windows, 0..=0.9.
    pub overlap: f64,
    /// Deformation resampling: bspline, bspline5, bicubic or bilinear.
    pub interp: String,
    /// Normalised median test threshold (0 disables).
    pub median_threshold: f64,
    /// Clipped areas: "auto", "off", or a gray level.
    pub clip: String,
    /// High-pass pre-filter σ, px (0 = off, at most 1000).
    pub highpass: f32,
    /// Sub-pixel estimator: parabolic, gaussian or gaussian2d.
    pub subpixel: String,
    /// Minimum correlation peak ratio (1 disables).
    pub min_peak_ratio: f64,
    /// Report the dense stage's field where the last pass failed as a
    /// whole ([`Settings::dense_fallback`]).
    pub dense_fallback: bool,
}

impl Default for PivOptions {
    fn default() -> Self {
        PivOptions {
            windows: vec![64, 32, 32],
            overlap: 0.5,
            interp: "bspline".into(),
            median_threshold: 2.0,
            clip: "auto".into(),
            highpass: 3.0,
            subpixel: "parabolic".into(),
            min_peak_ratio: 1.5,
            dense_fallback: true,
        }
    }
}

impl PivOptions {
    /// The settings, or the first value out of range. Windows and overlap
    /// are checked again by [`super::piv`] against the images' size.
    pub fn settings(&self) -> Result<Settings, PivError> {
        let bad = |m: String| Err(PivError::Settings(m));
        let clip = match self.clip.as_str() {
            "auto" => Clip::Auto,
            "off" => Clip::Off,
            v => match v.parse::<f32>() {
                Ok(l) if l.is_finite() => Clip::Level(l),
                _ => return bad(format!("--clip {v}: expected auto, off or a gray level")),
            },
        };
        if !(0.0..=1000.0).contains(&self.highpass) {
            return bad(format!(
                "--highpass {}: expected 0..=1000 px",
                self.highpass
            ));
        }
        let subpixel = match self.subpixel.as_str() {
            "gaussian" => Subpixel::Gaussian,
            "parabolic" => Subpixel::Parabolic,
            "gaussian2d" => Subpixel::Gaussian2d,
            v => return bad(format!("--subpixel {v}: gaussian, gaussian2d or parabolic")),
        };
        let interp = match self.interp.as_str() {
            "bspline" => Interp::Bspline,
            "bspline5" => Interp::Bspline5,
            "bicubic" => Interp::Bicubic,
            "bilinear" => Interp::Bilinear,
            v => {
                return bad(format!(
                    "--interp {v}: bspline, bspline5, bicubic or bilinear"
                ))
            }
        };
        if !self.median_threshold.is_finite() || self.median_threshold < 0.0 {
            return bad(format!(
                "--median-threshold {}: expected a number ≥ 0",
                self.median_threshold
            ));
        }
        if !self.min_peak_ratio.is_finite() || self.min_peak_ratio < 1.0 {
            return bad(format!(
                "--min-peak-ratio {}: expected a number ≥ 1",
                self.min_peak_ratio
            ));
        }
        Ok(Settings {
            subpixel,
            clip,
            highpass: self.highpass,
            windows: self.windows.clone(),
            overlap: self.overlap,
            interp,
            validation: Validation {
                median_threshold: self.median_threshold,
                min_peak_ratio: self.min_peak_ratio,
                ..Validation::default()
            },
            dense_fallback: self.dense_fallback,
            ..Settings::default()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_libraries_defaults_with_the_dense_fallback() {
        let s = PivOptions::default().settings().unwrap();
        assert!(s.dense_fallback);
        assert_eq!(
            Settings {
                dense_fallback: false,
                ..s
            },
            Settings::default()
        );
    }

    #[test]
    fn bad_values_are_refused_with_the_option_named() {
        for (o, name) in [
            (
                PivOptions {
                    clip: "x".into(),
                    ..Default::default()
                },
                "--clip",
            ),
            (
                PivOptions {
                    highpass: -1.0,
                    ..Default::default()
                },
                "--highpass",
            ),
            (
                PivOptions {
                    subpixel: "x".into(),
                    ..Default::default()
                },
                "--subpixel",
            ),
            (
                PivOptions {
                    interp: "x".into(),
                    ..Default::default()
                },
                "--interp",
            ),
            (
                PivOptions {
                    median_threshold: f64::NAN,
                    ..Default::default()
                },
                "--median-threshold",
            ),
            (
                PivOptions {
                    min_peak_ratio: 0.5,
                    ..Default::default()
                },
                "--min-peak-ratio",
            ),
        ] {
            let e = o.settings().unwrap_err().to_string();
            assert!(e.starts_with(name), "{e}");
        }
        let clip = PivOptions {
            clip: "200".into(),
            ..Default::default()
        };
        assert_eq!(clip.settings().unwrap().clip, Clip::Level(200.0));
    }
}
