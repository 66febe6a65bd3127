//! `spiv bench turbulence`: window PIV and the dense stage on
//! the turbulence and large-shift scenes, for the frame camera's pair and
//! the core's TFP pair of the same spikes, against the dense truth: mean
//! end-point error (EPE), outliers, time. OpenPIV runs beside them in
//! `bench/openpiv_compare.sh`.

use std::time::Instant;

use ndarray::Array2;
use spiv_core::Params;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_formats::dense::DenseField;

use crate::piv::dense::{for_piv, DenseMode, Flow};
use crate::piv::{deform, piv, to_f32, Settings};
use crate::reconstruct::{frame_from_planes, Method, Planes};
use crate::Error;

/// One method on one pair.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TurbulenceRow {
    /// Scene name.
    pub scene: String,
    /// "frame camera" or "spike TFP 8".
    pub frames: String,
    /// What ran.
    pub method: String,
    /// Vectors (or pixels) the method reports as measured, of all.
    pub measured: (usize, usize),
    /// Mean EPE over every pixel of the field interpolated to pixels (or
    /// the dense field), px per pair; `None` when nothing was measured.
    pub epe: Option<f64>,
    /// Pixels whose error exceeds 3 px, fraction.
    pub outliers: Option<f64>,
    /// Mean displacement of the truth, px per pair.
    pub mean_displacement: f64,
    /// Wall time, ms.
    pub ms: f64,
}

fn epe_and_outliers(f: &Flow, truth: &DenseField) -> (f64, f64) {
    let d = f.to_field();
    let out =
        d.u.iter()
            .zip(&d.v)
            .zip(truth.u.iter().zip(&truth.v))
            .filter(|((u, v), (tu, tv))| (*u - *tu).hypot(*v - *tv) > 3.0)
            .count();
    (
        d.epe(truth, None).unwrap_or(f64::NAN),
        out as f64 / d.u.len().max(1) as f64,
    )
}

/// The rows for `seed`: per scene, per pair, window PIV with the library's
/// defaults, with the dense fallback, and the dense stage.
pub fn turbulence_rows(seed: u64) -> Result<Vec<TurbulenceRow>, Error> {
    let mut rows = Vec::new();
    for kind in [SceneKind::Turbulence, SceneKind::LargeShift] {
        let p = SceneParams::new(kind);
        let name = kind.name().to_string();
        let req = Request::new(p.clone(), seed);
        let (data, sim) = simulate_planes(&req)?;
        let (w, h) = (p.width, p.height);
        let pair = sim.meta.capture.pair;
        let dt = f64::from(pair[1] - pair[0]);
        let truth = sim.scene.truth_dense(dt);
        let mean = truth
            .u
            .iter()
            .zip(&truth.v)
            .map(|(&u, &v)| f64::from(u).hypot(f64::from(v)))
            .sum::<f64>()
            / truth.u.len().max(1) as f64;
        let planes = Planes::simulated(w, h, data);
        let tfp = |k: u32| -> Result<Array2<f32>, Error> {
            let f = frame_from_planes(&planes, u64::from(k), Method::Tfp, 8, &Params::default())?;
            Ok(to_f32(&f.data, usize::from(w), usize::from(h)))
        };
        let cam = |f: &Vec<u16>| to_f32(f, usize::from(w), usize::from(h));
        let pairs = [
            ("frame camera", cam(&sim.frames[0]), cam(&sim.frames[1])),
            ("spike TFP 8", tfp(pair[0])?, tfp(pair[1])?),
        ];
        for (frames, a, b) in pairs {
            let row = |method: &str, measured, ef: Option<(f64, f64)>, ms| TurbulenceRow {
                scene: name.clone(),
                frames: frames.to_string(),
                method: method.to_string(),
                measured,
                epe: ef.map(|e| e.0),
                outliers: ef.map(|e| e.1),
                mean_displacement: mean,
                ms,
            };
            for (method, fallback) in [("window PIV 64,32,32", false), ("  + dense fallback", true)]
            {
                let s = Settings {
                    dense_fallback: fallback,
                    ..Settings::default()
                };
                let t0 = Instant::now();
                let f = piv(&a, &b, None, &s)?;
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                let (valid, replaced, _) = f.counts();
                let measured = valid + replaced;
                let ef = (measured > 0).then(|| {
                    let (u, v) = deform::dense(&f.grid, &f.u, &f.v, usize::from(h), usize::from(w));
                    epe_and_outliers(&Flow { u, v }, &truth)
                });
                rows.push(row(method, (measured, f.grid.len()), ef, ms));
            }
            let t0 = Instant::now();
            let f = piv(&a, &b, None, &Settings::default())?;
            let (flow, mode) = for_piv(&a, &b, &f);
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            let px = usize::from(w) * usize::from(h);
            let method = match mode {
                DenseMode::Refine => "dense (refined from PIV)",
                DenseMode::Pyramid => "dense (pyramid from rest)",
            };
            rows.push(row(
                method,
                (px, px),
                Some(epe_and_outliers(&flow, &truth)),
                ms,
            ));
        }
    }
    Ok(rows)
}
