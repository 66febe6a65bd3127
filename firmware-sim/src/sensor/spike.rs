//! The spike sensor (docs/spec.md §3). Per pixel and tick (light sampled at
//! the tick's centre): `A += Poisson((r + dark)·phi0)` photoelectrons; when
//! `A ≥ phi(x, y)` the pixel emits a spike and resets — to zero (the paper)
//! or by subtracting phi (excess clamped below 2·phi). At most one spike per
//! tick: light above one threshold per tick is the rate limit.
//! `phi = phi0·(1 + eps)`, `eps ~ N(0, sigma_fpn)` per pixel, clamped to
//! ≥ 0.5·phi0; initial charge uniform in `[0, phi)`.
//!
//! Random numbers come from one ChaCha8 stream per row (seeded by the seed,
//! stream = row), and rows run in parallel (rayon), so output depends on the
//! seed only, never on the thread count.
//!
//! Shot noise: exact Poisson (Knuth) below a mean of 10 electrons; above it
//! the normal approximation, drawn from a 4096-entry inverse-CDF table
//! (12 random bits a draw) — at phi0 = 1000 a spike sums ≥ 1000 electrons
//! over many ticks, where the two are indistinguishable, and this is ~10×
//! faster than sampling `rand_distr::Normal` per pixel-tick.

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// What happens to the charge at a spike.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reset {
    /// Charge cleared (the paper).
    Zero,
    /// Threshold subtracted; the excess kept (clamped below 2·phi).
    Subtract,
}

/// Spike sensor parameters with the docs/spec.md §3 defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
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

/// Acklam's rational approximation of the standard normal quantile
/// (relative error < 1.2e-9), for the shot-noise table.
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.38357751867269e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

const NORMAL_BITS: u32 = 12;

fn normal_table() -> &'static [f32] {
    static T: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let n = 1usize << NORMAL_BITS;
        (0..n)
            .map(|i| normal_quantile((i as f64 + 0.5) / n as f64) as f32)
            .collect()
    })
}

/// Exact Poisson by Knuth's product of uniforms (small means only).
fn poisson_small(rng: &mut ChaCha8Rng, mean: f32) -> f32 {
    let l = (-mean).exp();
    let mut k = 0u32;
    let mut p = 1.0f32;
    loop {
        p *= rng.gen::<f32>();
        if p <= l || k > 200 {
            return k as f32;
        }
        k += 1;
    }
}

/// One row of pixels.
#[derive(Debug, Clone)]
struct Row {
    charge: Vec<f32>,
    phi: Vec<f32>,
    rng: ChaCha8Rng,
    bits: Vec<u64>,
    z: Vec<f32>,
    fired: Vec<u8>,
}

/// An integrate-and-fire spike sensor of `width × height` pixels.
#[derive(Debug, Clone)]
pub struct SpikeSensor {
    params: SensorParams,
    width: usize,
    height: usize,
    rows: Vec<Row>,
}

impl SpikeSensor {
    /// A sensor with its thresholds and initial charges drawn from `seed`.
    pub fn new(params: SensorParams, width: u16, height: u16, seed: u64) -> SpikeSensor {
        let (w, h) = (usize::from(width), usize::from(height));
        let fpn = rand_distr::Normal::new(0.0, params.sigma_fpn.max(0.0)).ok();
        let rows = (0..h)
            .map(|i| {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                rng.set_stream(i as u64 + 1);
                let mut phi = Vec::with_capacity(w);
                let mut charge = Vec::with_capacity(w);
                for _ in 0..w {
                    let eps = fpn
                        .map(|d| rand_distr::Distribution::sample(&d, &mut rng))
                        .unwrap_or(0.0);
                    let p = (params.phi0 * (1.0 + eps)).max(0.5 * params.phi0);
                    phi.push(p as f32);
                    charge.push((rng.gen::<f64>() * p) as f32);
                }
                Row {
                    charge,
                    phi,
                    rng,
                    bits: vec![0; w.div_ceil(64)],
                    z: vec![0.0; w],
                    fired: vec![0; w],
                }
            })
            .collect();
        SpikeSensor {
            params,
            width: w,
            height: h,
            rows,
        }
    }

    /// The fixed-pattern threshold of pixel (row `i`, column `j`), electrons.
    pub fn threshold(&self, i: usize, j: usize) -> Option<f32> {
        self.rows.get(i).and_then(|r| r.phi.get(j)).copied()
    }

    /// One tick: integrates `light` (thresholds/tick, upright rows) and writes
    /// the packed Vidar plane into `plane` (`w·h/8` bytes, LSB first; stored
    /// rows bottom-up when `flip`). Returns the number of spikes.
    pub fn tick(&mut self, light: &[f32], flip: bool, plane: &mut [u8]) -> u64 {
        let (w, h) = (self.width, self.height);
        let p = self.params;
        let table = normal_table();
        let spikes: u64 = self
            .rows
            .par_iter_mut()
            .zip(light.par_chunks(w))
            .map(|(row, lrow)| {
                row.draw_normals(table);
                if row.integrate(lrow, &p) {
                    row.integrate_dim(lrow, &p);
                }
                row.pack_bits()
            })
            .sum();
        plane.fill(0);
        for (i, row) in self.rows.iter().enumerate() {
            let stored = if flip { h - 1 - i } else { i };
            spiv_formats::dat::pack_row(&row.bits, stored, w, plane);
        }
        spikes
    }
}

impl Row {
    /// The row's normal draws for this tick, 5 per 64-bit word of its
    /// generator, from the quantile `table`.
    fn draw_normals(&mut self, table: &[f32]) {
        for five in self.z.chunks_mut(5) {
            let mut bits = self.rng.next_u64();
            for v in five {
                *v = table[(bits & ((1 << NORMAL_BITS) - 1)) as usize];
                bits >>= NORMAL_BITS;
            }
        }
    }

    /// Branch-free integrate-and-fire of every pixel of the row under
    /// `light` (thresholds per tick), photon noise as a normal draw
    /// (vectorises). Whether a pixel got under 10 electrons a tick, where
    /// the normal is a poor model ([`Row::integrate_dim`]).
    fn integrate(&mut self, light: &[f32], p: &SensorParams) -> bool {
        let (phi0, dark) = (p.phi0 as f32, p.dark as f32);
        let zero_reset = p.reset == Reset::Zero;
        let mut small = false;
        for ((((c, &ph), &r), &zz), f) in self
            .charge
            .iter_mut()
            .zip(self.phi.iter())
            .zip(light)
            .zip(self.z.iter())
            .zip(self.fired.iter_mut())
        {
            let mean = (r.max(0.0) + dark) * phi0;
            small |= mean < 10.0;
            let a = *c + (mean + mean.sqrt() * zz).max(0.0);
            let spike = a >= ph;
            let after = if zero_reset {
                0.0
            } else {
                (a - ph).min(ph * 0.999_999)
            };
            *c = if spike { after } else { a };
            *f = u8::from(spike);
        }
        small
    }

    /// Dim pixels (under 10 electrons a tick) integrated again with exact
    /// Poisson draws: [`Row::integrate`]'s step undone, then redone.
    fn integrate_dim(&mut self, light: &[f32], p: &SensorParams) {
        let (phi0, dark) = (p.phi0 as f32, p.dark as f32);
        let zero_reset = p.reset == Reset::Zero;
        for ((((c, &ph), &r), &zz), f) in self
            .charge
            .iter_mut()
            .zip(self.phi.iter())
            .zip(light)
            .zip(self.z.iter())
            .zip(self.fired.iter_mut())
        {
            let mean = (r.max(0.0) + dark) * phi0;
            if mean >= 10.0 {
                continue;
            }
            if *f == 1 {
                // It fired with the approximation; its charge before is
                // unknown, so keep the spike (rare: a dim pixel fires once
                // per ≥ 100 ticks).
                continue;
            }
            let c0 = *c - (mean + mean.sqrt() * zz).max(0.0);
            let a = c0 + poisson_small(&mut self.rng, mean);
            if a >= ph {
                *f = 1;
                *c = if zero_reset {
                    0.0
                } else {
                    (a - ph).min(ph * 0.999_999)
                };
            } else {
                *c = a;
            }
        }
    }

    /// The row's spikes packed into words (bit `k` of word `j` is pixel
    /// `64j + k`); returns how many.
    fn pack_bits(&mut self) -> u64 {
        let mut n = 0u64;
        for (word, f64s) in self.bits.iter_mut().zip(self.fired.chunks(64)) {
            let mut w = 0u64;
            for (k, &f) in f64s.iter().enumerate() {
                w |= u64::from(f) << k;
            }
            n += u64::from(w.count_ones());
            *word = w;
        }
        n
    }
}

/// Simulates `ticks` planes of `scene` from scene tick `first`, in the
/// camera's layout (flipped), back to back. The sensor is seeded from `seed`.
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
    let mut light = vec![0f32; usize::from(w) * usize::from(h)];
    let mut out = vec![0u8; plane_bytes * ticks as usize];
    for (t, plane) in out.chunks_exact_mut(plane_bytes).enumerate() {
        scene.render(f64::from(first) + t as f64 + 0.5, &mut light);
        sensor.tick(&light, true, plane);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles() {
        assert!(normal_quantile(0.5).abs() < 1e-12);
        assert!((normal_quantile(0.975) - 1.959964).abs() < 1e-5);
        assert!((normal_quantile(0.001) + 3.090232).abs() < 1e-5);
        let t = normal_table();
        let mean: f64 = t.iter().map(|&v| f64::from(v)).sum::<f64>() / t.len() as f64;
        let var: f64 = t.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / t.len() as f64;
        assert!(
            mean.abs() < 1e-6 && (var - 1.0).abs() < 2e-3,
            "mean {mean} var {var}"
        );
    }
}
