//! The frame camera (docs/spec.md §3–4): one exposure of `te` ticks ending at
//! the frame's tick, full scale at `fs_light` thresholds/tick (full well =
//! fs_light·phi0·te electrons), shot noise, read noise (default full well/400,
//! ~52 dB like the paper's Phantom), an 8- or 12-bit ADC, and clipping above
//! full scale — the overexposure the paper fights.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::scene::Scene;

/// Frame camera parameters (docs/spec.md §4 defaults).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameCameraParams {
    /// Exposure, ticks (ending at the frame's tick).
    pub te: u32,
    /// Light that reaches full scale, thresholds/tick.
    pub fs_light: f64,
    /// Electrons per threshold (same optics as the spike sensor).
    pub phi0: f64,
    /// Read noise, electrons (`None`: full well / 400).
    pub read_noise: Option<f64>,
    /// ADC bits, 8 or 12.
    pub bits: u8,
}

impl Default for FrameCameraParams {
    fn default() -> Self {
        FrameCameraParams {
            te: 2,
            fs_light: 0.28,
            phi0: 1000.0,
            read_noise: None,
            bits: 12,
        }
    }
}

impl FrameCameraParams {
    /// Full well, electrons.
    pub fn full_well(&self) -> f64 {
        self.fs_light * self.phi0 * f64::from(self.te)
    }
    /// Largest ADC value.
    pub fn max_dn(&self) -> u16 {
        ((1u32 << self.bits.clamp(1, 16)) - 1) as u16
    }
}

/// A frame camera looking at a scene.
#[derive(Debug, Clone)]
pub struct FrameCamera {
    /// Its parameters.
    pub params: FrameCameraParams,
}

impl FrameCamera {
    /// Captures the frame whose exposure ends with tick `tick` (scene ticks
    /// `tick − te + 1 ..= tick`, light sampled at tick centres): digital
    /// numbers `0..=max_dn`, upright rows.
    pub fn capture(&self, scene: &Scene, tick: u32, seed: u64) -> Vec<u16> {
        let p = &self.params;
        let (w, h) = (
            usize::from(scene.params.width),
            usize::from(scene.params.height),
        );
        let mut electrons = vec![0f64; w * h];
        let mut light = vec![0f32; w * h];
        for d in 0..p.te {
            let t = f64::from(tick) - f64::from(d) + 0.5;
            scene.render(t, &mut light);
            for (e, &l) in electrons.iter_mut().zip(&light) {
                *e += f64::from(l) * p.phi0;
            }
        }
        let full = p.full_well();
        let rn = p.read_noise.unwrap_or(full / 400.0);
        let mut rng =
            ChaCha8Rng::seed_from_u64(seed ^ u64::from(tick).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let std = Normal::new(0.0, 1.0).ok();
        let max = f64::from(p.max_dn());
        electrons
            .iter()
            .map(|&mean| {
                let z1 = std.map_or(0.0, |d| d.sample(&mut rng));
                let z2 = std.map_or(0.0, |d| d.sample(&mut rng));
                let e = mean + mean.sqrt() * z1 + rn * z2;
                ((e / full).clamp(0.0, 1.0) * max).round() as u16
            })
            .collect()
    }
}
