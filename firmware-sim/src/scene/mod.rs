//! Scenes (SPEC section 4): a horizontal flow over a wall at the bottom edge,
//! Gaussian particle images advected with it, and a glare band
//! `I(y) = I0·exp(−y²/2σ²)` along the wall. Light is in thresholds per tick.
//!
//! Geometry: `y = H − 0.5 − i` is the height above the wall of pixel row `i`
//! (row 0 at the top); flow is left to right; u(y) in pixels per tick.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The velocity profile u(y).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Profile {
    /// u = U·y/H.
    Linear,
    /// u = U·(y/H)².
    Quadratic,
    /// u = U·ln(1 + y/y0)/ln(1 + H/y0), y0 = 5 px.
    Log,
    /// u = U everywhere.
    Uniform,
}

/// One particle: centre at tick 0 (pixels, image coordinates x right, row
/// down), peak light above background (thresholds/tick), e⁻² diameter (px).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Particle {
    /// Column of the centre at tick 0, px.
    pub x: f64,
    /// Row coordinate of the centre (row i has its centre at i + 0.5), px.
    pub row: f64,
    /// Peak light above background, thresholds/tick.
    pub peak: f64,
    /// e⁻² diameter of the Gaussian image, px.
    pub diameter: f64,
}

/// Scene parameters with the SPEC section 4 defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneParams {
    /// Width, px.
    pub width: u16,
    /// Height, px.
    pub height: u16,
    /// Velocity profile.
    pub profile: Profile,
    /// Top speed U, px/tick (0.5 m/s at 0.02 mm/px and 50 µs/tick = 1.25).
    pub top_speed: f64,
    /// Background light, thresholds/tick.
    pub background: f64,
    /// Mean particle peak light above background, thresholds/tick (±30 %).
    pub particle_peak: f64,
    /// Particle e⁻² diameters are uniform in this range, px.
    pub diameter: (f64, f64),
    /// Glare peak I0 at the wall, thresholds/tick.
    pub glare_peak: f64,
    /// Glare width σ, px.
    pub glare_sigma: f64,
    /// At least this many particles per 32×32 cell.
    pub per_cell: usize,
    /// Minimum centre spacing, px.
    pub min_spacing: f64,
}

impl Default for SceneParams {
    fn default() -> Self {
        SceneParams {
            width: 400,
            height: 250,
            profile: Profile::Linear,
            top_speed: 1.25,
            background: 0.01,
            particle_peak: 0.25,
            diameter: (4.0, 6.0),
            glare_peak: 0.65,
            glare_sigma: 25.0,
            per_cell: 4,
            min_spacing: 8.0,
        }
    }
}

/// A seeded scene: its parameters and particles.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The parameters.
    pub params: SceneParams,
    /// The particles, seeded over the region the frames will see (upstream
    /// included, so particles flow in).
    pub particles: Vec<Particle>,
    /// Cells (32×32) of the image that reached `per_cell` particles, of all.
    pub density_reached: (usize, usize),
}

impl Scene {
    /// Seeds particles over `[-upstream, width)` × `[0, height)`: at least
    /// `per_cell` per 32×32 cell, centres at least `min_spacing` apart, with
    /// a bounded number of retries (the paper's rule; SPEC section 4).
    pub fn new(params: SceneParams, seed: u64, upstream: f64) -> Scene {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (w, h) = (f64::from(params.width), f64::from(params.height));
        let x0 = -upstream.max(0.0);
        let cells_x = ((w - x0) / 32.0).ceil() as usize;
        let cells_y = (h / 32.0).ceil() as usize;
        let mut particles: Vec<Particle> = Vec::new();
        let mut reached = 0;
        let spacing2 = params.min_spacing * params.min_spacing;
        for cy in 0..cells_y {
            for cx in 0..cells_x {
                let (cx0, cy0) = (x0 + 32.0 * cx as f64, 32.0 * cy as f64);
                let cw = 32.0f64.min(w - cx0);
                let ch = 32.0f64.min(h - cy0);
                let mut have = particles
                    .iter()
                    .filter(|p| p.x >= cx0 && p.x < cx0 + cw && p.row >= cy0 && p.row < cy0 + ch)
                    .count();
                let mut tries = 0;
                while have < params.per_cell && tries < 2000 {
                    tries += 1;
                    let x = cx0 + rng.gen::<f64>() * cw;
                    let row = cy0 + rng.gen::<f64>() * ch;
                    let near = particles.iter().rev().take(64).any(|p| {
                        let (dx, dy) = (p.x - x, p.row - row);
                        dx * dx + dy * dy < spacing2
                    });
                    if near {
                        continue;
                    }
                    let peak = params.particle_peak * (1.0 + 0.3 * (2.0 * rng.gen::<f64>() - 1.0));
                    let diameter = params.diameter.0
                        + (params.diameter.1 - params.diameter.0) * rng.gen::<f64>();
                    particles.push(Particle {
                        x,
                        row,
                        peak,
                        diameter,
                    });
                    have += 1;
                }
                if have >= params.per_cell && cx0 >= 0.0 {
                    reached += 1;
                }
            }
        }
        let image_cells = (w / 32.0).ceil() as usize * cells_y;
        Scene {
            params,
            particles,
            density_reached: (reached, image_cells),
        }
    }

    /// Height above the wall of a row coordinate (row centre at i + 0.5), px.
    pub fn height_above_wall(&self, row: f64) -> f64 {
        f64::from(self.params.height) - row
    }

    /// u(y), px/tick, y = height above the wall in px.
    pub fn u(&self, y: f64) -> f64 {
        let p = &self.params;
        let h = f64::from(p.height);
        let y = y.clamp(0.0, h);
        match p.profile {
            Profile::Linear => p.top_speed * y / h,
            Profile::Quadratic => p.top_speed * (y / h).powi(2),
            Profile::Log => {
                let y0 = 5.0;
                p.top_speed * (1.0 + y / y0).ln() / (1.0 + h / y0).ln()
            }
            Profile::Uniform => p.top_speed,
        }
    }

    /// Static light of image row `i` (background + glare), thresholds/tick.
    pub fn static_light(&self, i: usize) -> f64 {
        let y = f64::from(self.params.height) - 0.5 - i as f64;
        let s = self.params.glare_sigma;
        self.params.background + self.params.glare_peak * (-(y * y) / (2.0 * s * s)).exp()
    }

    /// Renders the light at time `t` (ticks, centre of the tick) into
    /// `light` (`width × height`, image rows top-down): the static part plus
    /// every particle, each only inside its 3σ box.
    pub fn render(&self, t: f64, light: &mut [f64]) {
        let (w, h) = (
            usize::from(self.params.width),
            usize::from(self.params.height),
        );
        for (i, row) in light.chunks_exact_mut(w).enumerate().take(h) {
            row.fill(self.static_light(i));
        }
        for p in &self.particles {
            let x = p.x + self.u(self.height_above_wall(p.row)) * t;
            let sigma = p.diameter / 4.0;
            let r = 3.0 * sigma;
            let (c0, c1) = ((x - r).floor().max(0.0), (x + r).ceil().min(w as f64));
            let (r0, r1) = (
                (p.row - r).floor().max(0.0),
                (p.row + r).ceil().min(h as f64),
            );
            if c1 <= c0 || r1 <= r0 {
                continue;
            }
            let k = -1.0 / (2.0 * sigma * sigma);
            for i in r0 as usize..r1 as usize {
                let dy = i as f64 + 0.5 - p.row;
                for j in c0 as usize..c1 as usize {
                    let dx = j as f64 + 0.5 - x;
                    light[i * w + j] += p.peak * ((dx * dx + dy * dy) * k).exp();
                }
            }
        }
    }
}
