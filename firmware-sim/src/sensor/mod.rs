//! The spike sensor (SPEC section 3): per pixel and tick,
//! `A += Poisson((r + dark)·phi0)`; when `A ≥ phi(x, y)` the pixel emits a
//! spike and resets (to zero, or by subtracting phi). At most one spike per
//! tick. `phi = phi0·(1 + eps)`, `eps ~ N(0, sigma_fpn)` per pixel (clamped to
//! ≥ 0.5·phi0); initial charge uniform in `[0, phi)`. Random numbers come
//! from one ChaCha stream per row, so results do not depend on threads.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};

/// What happens to the charge at a spike.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reset {
    /// Charge cleared (the paper).
    Zero,
    /// Threshold subtracted; the excess kept (clamped below 2·phi).
    Subtract,
}

/// Spike sensor parameters with the SPEC section 3 defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorParams {
    /// Photoelectrons per threshold, phi0.
    pub phi0: f64,
    /// Dark charge, thresholds/tick.
    pub dark: f64,
    /// Relative threshold spread σ_fpn.
    pub sigma_fpn: f64,
    /// Reset mode.
    pub reset: Reset,
}

impl Default for SensorParams {
    fn default() -> Self {
        SensorParams {
            phi0: 1000.0,
            dark: 0.005,
            sigma_fpn: 0.03,
            reset: Reset::Zero,
        }
    }
}

/// An integrate-and-fire spike sensor of `width × height` pixels.
#[derive(Debug, Clone)]
pub struct SpikeSensor {
    params: SensorParams,
    width: usize,
    height: usize,
    charge: Vec<f64>,
    phi: Vec<f64>,
    rngs: Vec<ChaCha8Rng>,
}

/// Photoelectrons of one tick: Poisson, by the normal approximation above
/// a mean of 30 (relative error of the variance there is nil; it is ~20×
/// faster than exact sampling at the default phi0 = 1000).
fn photoelectrons(rng: &mut ChaCha8Rng, mean: f64) -> f64 {
    if mean <= 0.0 {
        0.0
    } else if mean < 30.0 {
        Poisson::new(mean).map(|d| d.sample(rng)).unwrap_or(0.0)
    } else {
        let n: f64 = Normal::new(mean, mean.sqrt())
            .map(|d| d.sample(rng))
            .unwrap_or(mean);
        n.round().max(0.0)
    }
}

impl SpikeSensor {
    /// A sensor with its fixed-pattern thresholds and initial charges drawn
    /// from `seed`.
    pub fn new(params: SensorParams, width: u16, height: u16, seed: u64) -> SpikeSensor {
        let (w, h) = (usize::from(width), usize::from(height));
        let mut rngs: Vec<ChaCha8Rng> = (0..h)
            .map(|i| {
                let mut r = ChaCha8Rng::seed_from_u64(seed);
                r.set_stream(i as u64 + 1);
                r
            })
            .collect();
        let fpn = Normal::new(0.0, params.sigma_fpn.max(0.0)).ok();
        let mut phi = vec![0.0; w * h];
        let mut charge = vec![0.0; w * h];
        for (i, rng) in rngs.iter_mut().enumerate() {
            for j in 0..w {
                let eps = fpn.map(|d| d.sample(rng)).unwrap_or(0.0);
                let p = (params.phi0 * (1.0 + eps)).max(0.5 * params.phi0);
                phi[i * w + j] = p;
                charge[i * w + j] = rng.gen::<f64>() * p;
            }
        }
        SpikeSensor {
            params,
            width: w,
            height: h,
            charge,
            phi,
            rngs,
        }
    }

    /// One tick: integrates `light` (thresholds/tick, image rows top-down)
    /// and writes the packed Vidar plane into `plane` (`w·h/8` bytes; stored
    /// rows bottom-up when `flip`, LSB first). Returns the spike count.
    pub fn tick(&mut self, light: &[f64], flip: bool, plane: &mut [u8]) -> u32 {
        let (w, h) = (self.width, self.height);
        plane.fill(0);
        let mut spikes = 0;
        let p = self.params;
        for i in 0..h {
            let stored = if flip { h - 1 - i } else { i };
            let rng = &mut self.rngs[i];
            for j in 0..w {
                let k = i * w + j;
                let r = light.get(k).copied().unwrap_or(0.0).max(0.0);
                let a = self.charge[k] + photoelectrons(rng, (r + p.dark) * p.phi0);
                let phi = self.phi[k];
                if a >= phi {
                    let bit = stored * w + j;
                    plane[bit / 8] |= 1 << (bit % 8);
                    spikes += 1;
                    self.charge[k] = match p.reset {
                        Reset::Zero => 0.0,
                        Reset::Subtract => (a - phi).min(phi * (1.0 - 1e-9)),
                    };
                } else {
                    self.charge[k] = a;
                }
            }
        }
        spikes
    }
}

/// Simulates `ticks` planes of `scene` starting at scene tick `first`, packed
/// in the camera's layout (flipped). Returns the planes back to back.
pub fn simulate(
    scene: &crate::scene::Scene,
    params: SensorParams,
    seed: u64,
    first: u32,
    ticks: u32,
) -> Vec<u8> {
    let (w, h) = (scene.params.width, scene.params.height);
    let plane_bytes = usize::from(w) * usize::from(h) / 8;
    let mut sensor = SpikeSensor::new(params, w, h, seed ^ 0x5eed_5e45);
    let mut light = vec![0.0; usize::from(w) * usize::from(h)];
    let mut out = vec![0u8; plane_bytes * ticks as usize];
    for (t, plane) in out.chunks_exact_mut(plane_bytes).enumerate() {
        scene.render(f64::from(first) + t as f64 + 0.5, &mut light);
        sensor.tick(&light, true, plane);
    }
    out
}
