//! Synthetic PIV pairs from the simulated camera, with their ground truth.
#![allow(dead_code)]

use ndarray::Array2;
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::frame::{FrameCamera, FrameCameraParams};
use spiv_host::piv::{Field, State};

/// A frame-camera pair of a scene, the scene, and the pair separation.
pub struct Pair {
    pub a: Array2<f32>,
    pub b: Array2<f32>,
    pub scene: Scene,
    pub dt: u32,
}

/// The pair at ticks (64, 64 + dt) of scene `p` with seed `seed`, exposed
/// by the default frame camera without glare.
pub fn pair(p: SceneParams, seed: u64) -> Pair {
    let dt = p.pair_dt;
    let t0 = 64;
    let (w, h) = (usize::from(p.width), usize::from(p.height));
    let scene = Scene::new(p, seed, t0 + dt + 1);
    let cam = FrameCamera {
        params: FrameCameraParams::default(),
    };
    let to = |v: Vec<u16>| Array2::from_shape_fn((h, w), |(i, j)| f32::from(v[i * w + j]));
    let a = to(cam.capture(&scene, t0, seed));
    let b = to(cam.capture(&scene, t0 + dt, seed.wrapping_add(1)));
    Pair { a, b, scene, dt }
}

/// Scene parameters without glare.
pub fn params(kind: SceneKind) -> SceneParams {
    SceneParams {
        glare_peak: 0.0,
        ..SceneParams::new(kind)
    }
}

/// Per-vector errors (u, v) of the field against the scene truth, with the state.
pub fn errors(f: &Field, pair: &Pair) -> Vec<(f64, f64, State)> {
    let vs = f.vectors();
    let pts: Vec<(f64, f64)> = vs.iter().map(|v| (v.x, v.y)).collect();
    let truth = pair.scene.truth(&pts, f64::from(pair.dt));
    vs.iter()
        .zip(truth)
        .map(|(v, t)| (v.u - t.2, v.v - t.3, v.state))
        .collect()
}

/// RMS of the error magnitude over measured (valid or replaced) vectors.
pub fn rms(e: &[(f64, f64, State)]) -> f64 {
    let used: Vec<f64> = e
        .iter()
        .filter(|x| x.2.is_measured())
        .map(|x| x.0 * x.0 + x.1 * x.1)
        .collect();
    (used.iter().sum::<f64>() / used.len().max(1) as f64).sqrt()
}
