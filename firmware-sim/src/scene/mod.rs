//! Scenes (docs/spec.md §4): a flow ([`flow`]), Gaussian particle images
//! advected with it, and a glare band `I(y) = I0·exp(−y²/2σ²)` along the
//! wall. Light is in thresholds per tick; geometry in pixels of the upright
//! image (row 0 at the top, the wall at the bottom edge); time in ticks.
//!
//! Model only what a scene needs: the static part of the light (background
//! and glare) depends on the row only and is computed once; particles are
//! rendered only inside their 3σ boxes, by a separable Gaussian.

pub mod flow;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use spiv_formats::dense::DenseField;

pub use flow::{Flow, Profile};

/// The named scenes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    /// u = U·y/H under a glare band.
    PaperLinear,
    /// u = U·(y/H)² under a glare band.
    PaperQuadratic,
    /// Logarithmic profile under a glare band.
    PaperLog,
    /// Laminar boundary layer, the paper's experiment (U = 0.988 m/s, δ99 = 14.6 mm).
    Blasius,
    /// One fractional displacement everywhere (bias, peak locking).
    Uniform,
    /// Lamb–Oseen vortex, core radius H/8, peak 6 px per pair.
    Vortex,
    /// Kinematic turbulence: eddies from 8 to 128 px, up to 25 px per pair
    /// (beyond the paper).
    Turbulence,
    /// Large smooth eddies (32 to 128 px) moving up to 40 px per pair.
    LargeShift,
    /// An array of Taylor–Green vortices carried by a uniform drift over the
    /// glare band (beyond the paper): a 2-D flow with glare.
    VortexArray,
    /// Turbulence as a DNS recording holds it (beyond the paper): a
    /// continuous spectrum down to the smallest eddy with a dissipation
    /// roll-off, modes that evolve at their own turnover frequencies
    /// ([`flow::evolving`]), particles crossing a light sheet of finite
    /// thickness ([`Sheet`]); scaled by its rms displacement per pair.
    SpectralTurbulence,
}

impl SceneKind {
    /// Every scene, by name.
    pub const ALL: [(&'static str, SceneKind); 10] = [
        ("paper-linear", SceneKind::PaperLinear),
        ("paper-quadratic", SceneKind::PaperQuadratic),
        ("paper-log", SceneKind::PaperLog),
        ("blasius", SceneKind::Blasius),
        ("uniform", SceneKind::Uniform),
        ("vortex", SceneKind::Vortex),
        ("turbulence", SceneKind::Turbulence),
        ("large-shift", SceneKind::LargeShift),
        ("vortex-array", SceneKind::VortexArray),
        ("spectral-turbulence", SceneKind::SpectralTurbulence),
    ];

    /// The scene of a name, if any.
    pub fn from_name(name: &str) -> Option<SceneKind> {
        Self::ALL.iter().find(|(n, _)| *n == name).map(|&(_, k)| k)
    }

    /// The scene of a name, or the error that lists the names.
    pub fn parse(name: &str) -> Result<SceneKind, crate::Error> {
        Self::from_name(name).ok_or_else(|| crate::Error::UnknownScene(name.to_string()))
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, k)| *k == self)
            .map(|(n, _)| *n)
            .unwrap_or("?")
    }
}

/// Pixel size (mm) and tick (s) of the paper's setup.
pub const PIXEL_MM: f64 = 0.02;
/// Sampling frequency of the spike camera, Hz.
pub const TICK_HZ: f64 = 20_000.0;

/// m/s to px/tick at 0.02 mm/px and 20 kHz.
pub fn ms_to_px_per_tick(v: f64) -> f64 {
    v * 1000.0 / PIXEL_MM / TICK_HZ
}

/// Every parameter of a scene; [`SceneParams::new`] gives the defaults of docs/spec.md §4.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneParams {
    /// Which scene.
    pub kind: SceneKind,
    /// Width, px.
    pub width: u16,
    /// Height, px.
    pub height: u16,
    /// Top speed U, px/tick (paper scenes 1.25 = 0.5 m/s; Blasius 2.47 = 0.988 m/s).
    pub top_speed: f64,
    /// Pair separation Δt, ticks.
    pub pair_dt: u32,
    /// Uniform scene: displacement per pair (px right, px down).
    pub shift: (f64, f64),
    /// Vortex: peak displacement per pair, px.
    pub vortex_peak: f64,
    /// Blasius: δ99, px (14.6 mm = 730 px).
    pub delta99: f64,
    /// Background light, thresholds/tick.
    pub background: f64,
    /// Mean particle peak light above background, thresholds/tick (±30 % per particle).
    pub particle_peak: f64,
    /// Particle e⁻² diameters are uniform in this range, px.
    pub diameter: (f64, f64),
    /// Glare peak I0 at the wall, thresholds/tick (0: no glare).
    pub glare_peak: f64,
    /// Glare width σ, px.
    pub glare_sigma: f64,
    /// At least this many particles per 32×32 cell.
    pub per_cell: usize,
    /// Minimum centre spacing, px (8 by default; the paper's 15 as an option).
    pub min_spacing: f64,
    /// Turbulence scenes: the smallest and largest eddy (half a wavelength),
    /// px.
    #[serde(default = "default_eddies")]
    pub eddies: (f64, f64),
    /// Turbulence scenes: Fourier modes of the field.
    #[serde(default = "default_modes")]
    pub modes: usize,
    /// Turbulence scenes: the largest displacement per pair, px.
    #[serde(default = "default_max_shift")]
    pub max_shift: f64,
    /// Turbulence scenes: seed of the field (the scene's seed places the
    /// particles).
    #[serde(default = "default_flow_seed")]
    pub flow_seed: u64,
    /// Vortex array: the side of one vortex cell, px.
    #[serde(default = "default_cell")]
    pub cell: f64,
    /// Vortex array: the drift's speed as a fraction of `top_speed` (its
    /// direction and the array's offset come from `flow_seed`).
    #[serde(default = "default_drift")]
    pub drift: f64,
    /// Spectral turbulence: the rms displacement per pair, px (the field
    /// is scaled by it instead of `max_shift`).
    #[serde(default)]
    pub rms_shift: Option<f64>,
    /// Spectral turbulence: the modes' turnover rate ([`flow::evolving`];
    /// 0: frozen).
    #[serde(default)]
    pub evolution: f64,
    /// The light sheet (`None`: every particle lit in full, as in a 2-D
    /// flow).
    #[serde(default)]
    pub sheet: Option<Sheet>,
}

/// A light sheet of finite thickness: each particle sits at a depth `z`
/// and moves out of plane at its own constant speed `w`, wrapping over
/// `depth`; its light is scaled by exp(−8·z²/thickness²), so it fades out
/// of the sheet and others fade in (out-of-plane loss of pairs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sheet {
    /// e⁻² full thickness of the sheet, px.
    pub thickness: f64,
    /// Depth over which particles wrap, px (centred on the sheet).
    pub depth: f64,
    /// Standard deviation of the particles' out-of-plane speed, px/tick.
    pub w_rms: f64,
}

fn default_eddies() -> (f64, f64) {
    (8.0, 128.0)
}
fn default_modes() -> usize {
    64
}
fn default_max_shift() -> f64 {
    25.0
}
fn default_flow_seed() -> u64 {
    1
}
fn default_cell() -> f64 {
    128.0
}
fn default_drift() -> f64 {
    0.4
}

impl SceneParams {
    /// The defaults (docs/spec.md §4) of scene `kind`.
    pub fn new(kind: SceneKind) -> SceneParams {
        let base = SceneParams {
            kind,
            width: 400,
            height: 250,
            top_speed: ms_to_px_per_tick(0.5),
            pair_dt: 13,
            shift: (0.5, 0.25),
            vortex_peak: 6.0,
            delta99: 14.6 / PIXEL_MM,
            background: 0.01,
            particle_peak: 0.25,
            diameter: (4.0, 6.0),
            glare_peak: 0.65,
            glare_sigma: 25.0,
            per_cell: 4,
            min_spacing: 8.0,
            eddies: default_eddies(),
            modes: default_modes(),
            max_shift: default_max_shift(),
            flow_seed: default_flow_seed(),
            cell: default_cell(),
            drift: default_drift(),
            rms_shift: None,
            evolution: 0.0,
            sheet: None,
        };
        // Turbulence: the spike-flow datasets' layout (256×256 px, pairs
        // 21 ticks apart), no glare, dense seeding for small eddies.
        let turbulent = SceneParams {
            width: 256,
            height: 256,
            pair_dt: 21,
            glare_peak: 0.0,
            per_cell: 12,
            min_spacing: 5.0,
            ..base.clone()
        };
        match kind {
            SceneKind::PaperLinear | SceneKind::PaperQuadratic | SceneKind::PaperLog => base,
            // The paper's laminar validation: no glare, the layer fits 800 rows,
            // Δt keeps the largest displacement near 16 px like the others.
            SceneKind::Blasius => SceneParams {
                height: 800,
                top_speed: ms_to_px_per_tick(0.988),
                pair_dt: 7,
                glare_peak: 0.0,
                ..base
            },
            SceneKind::Uniform | SceneKind::Vortex => SceneParams {
                glare_peak: 0.0,
                ..base
            },
            SceneKind::Turbulence => turbulent,
            // The middle of the span `spiv bench flows` draws its members
            // from: eddies from 8 px, 2 px rms per pair, a 16-px sheet that
            // loses about a tenth of the particles per pair.
            SceneKind::SpectralTurbulence => SceneParams {
                eddies: (8.0, 128.0),
                modes: 96,
                rms_shift: Some(2.0),
                evolution: 1.0,
                sheet: Some(Sheet {
                    thickness: 16.0,
                    depth: 32.0,
                    w_rms: 0.08,
                }),
                ..turbulent
            },
            SceneKind::LargeShift => SceneParams {
                eddies: (32.0, 128.0),
                modes: 24,
                max_shift: 40.0,
                ..turbulent
            },
            // The vortices at 0.3 px/tick (1 px/tick is the fast variant),
            // pairs 10 ticks apart, over the default glare band.
            SceneKind::VortexArray => SceneParams {
                width: 256,
                height: 256,
                top_speed: 0.3,
                pair_dt: 10,
                ..base
            },
        }
    }

    /// The period of a turbulence field over this image, px: the larger
    /// side plus 64 px (so the image never sees itself wrap), rounded up
    /// to 32.
    pub fn period(&self) -> f64 {
        let side = f64::from(self.width.max(self.height)) + 64.0;
        let unit = match self.kind {
            // The array repeats every two cells.
            SceneKind::VortexArray => 2.0 * self.cell.max(1.0),
            _ => 32.0,
        };
        (side / unit).ceil() * unit
    }

    /// The flow this scene moves its particles with.
    pub fn flow(&self) -> Flow {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let shear = |profile| Flow::Shear {
            profile,
            top: self.top_speed,
            height: h,
            delta99: self.delta99,
        };
        match self.kind {
            SceneKind::PaperLinear => shear(Profile::Linear),
            SceneKind::PaperQuadratic => shear(Profile::Quadratic),
            SceneKind::PaperLog => shear(Profile::Log),
            SceneKind::Blasius => shear(Profile::Blasius),
            SceneKind::Uniform => {
                let dt = f64::from(self.pair_dt.max(1));
                Flow::Uniform {
                    u: self.shift.0 / dt,
                    v: self.shift.1 / dt,
                }
            }
            SceneKind::SpectralTurbulence => {
                let period = self.period();
                let dt = f64::from(self.pair_dt.max(1));
                let modes = flow::turbulence_modes(
                    self.flow_seed,
                    period,
                    2.0 * self.eddies.0,
                    2.0 * self.eddies.1,
                    self.modes,
                    1.0,
                );
                let rms = flow::rms_speed(&modes, period);
                let want = self.rms_shift.unwrap_or(self.max_shift) / dt;
                let scale = if rms > 0.0 { want / rms } else { 0.0 };
                let modes = modes
                    .into_iter()
                    .map(|m| flow::Mode {
                        amp: m.amp * scale,
                        ..m
                    })
                    .collect();
                Flow::Turbulence {
                    period,
                    drift: (0.0, 0.0),
                    modes: flow::evolving(modes, self.evolution, self.flow_seed),
                }
            }
            SceneKind::Turbulence | SceneKind::LargeShift => {
                let period = self.period();
                let dt = f64::from(self.pair_dt.max(1));
                Flow::Turbulence {
                    period,
                    drift: (0.0, 0.0),
                    modes: flow::turbulence_modes(
                        self.flow_seed,
                        period,
                        2.0 * self.eddies.0,
                        2.0 * self.eddies.1,
                        self.modes,
                        self.max_shift / dt,
                    ),
                }
            }
            SceneKind::VortexArray => {
                // Offset and drift direction from the flow's seed.
                let mut rng = ChaCha8Rng::seed_from_u64(self.flow_seed);
                let tau = 2.0 * std::f64::consts::PI;
                let cell = self.cell.max(1.0);
                let off = (rng.gen::<f64>() * 2.0 * cell, rng.gen::<f64>() * 2.0 * cell);
                let a = rng.gen::<f64>() * tau;
                let d = self.drift * self.top_speed;
                Flow::Turbulence {
                    period: self.period(),
                    modes: flow::taylor_green_modes(cell, self.top_speed, off),
                    drift: (d * a.cos(), d * a.sin()),
                }
            }
            SceneKind::Vortex => {
                let rc = h / 8.0;
                let gamma =
                    flow::vortex_gamma(rc, self.vortex_peak, f64::from(self.pair_dt.max(1)));
                Flow::Vortex {
                    cx: w / 2.0,
                    cy: h / 2.0,
                    gamma,
                    rc,
                }
            }
        }
    }
}

/// One particle: its centre at scene tick 0 (px), peak light above
/// background (thresholds/tick), e⁻² diameter (px).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Particle {
    /// Column of the centre at tick 0, px.
    pub x: f64,
    /// Row coordinate of the centre at tick 0, px.
    pub row: f64,
    /// Peak light above background, thresholds/tick.
    pub peak: f64,
    /// e⁻² diameter, px.
    pub diameter: f64,
    /// Depth at tick 0 relative to the light sheet's centre, px (0 without
    /// a sheet).
    #[serde(default)]
    pub z: f64,
    /// Out-of-plane speed, px/tick.
    #[serde(default)]
    pub w: f64,
}

impl Particle {
    /// Its light at tick `t` as a fraction of its peak in `sheet`.
    pub fn lit(&self, sheet: &Sheet, t: f64) -> f64 {
        let d = sheet.depth.max(1e-9);
        let z = (self.z + self.w * t + d / 2.0).rem_euclid(d) - d / 2.0;
        let th = sheet.thickness.max(1e-9);
        (-8.0 * z * z / (th * th)).exp()
    }
}

/// A seeded scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The parameters.
    pub params: SceneParams,
    /// The flow.
    pub flow: Flow,
    /// The particles.
    pub particles: Vec<Particle>,
    /// Full 32×32 cells of the image holding at least `per_cell` particles
    /// at tick 0, and all full cells of the image.
    pub density_reached: (usize, usize),
    static_rows: Vec<f32>,
    /// Positions of every particle at every half tick, for fields whose
    /// particles are integrated (turbulence), so a render costs one lookup
    /// per particle instead of an integration from tick 0.
    tracks: Option<Tracks>,
}

/// Particle positions sampled every [`Tracks::STEP`] ticks from tick 0,
/// integrated once (RK4) in parallel over particles.
#[derive(Debug, Clone)]
struct Tracks {
    samples: usize,
    pos: Vec<(f32, f32)>,
}

impl Tracks {
    /// Ticks between samples: linear interpolation between them is within
    /// 0.002 px of the path at the default turbulence's accelerations.
    const STEP: f64 = 0.25;
    /// Most samples kept (2^26 positions, 512 MB): longer runs integrate
    /// each render from tick 0.
    const MAX: usize = 1 << 26;

    fn new(flow: &Flow, particles: &[Particle], last_tick: u32) -> Option<Tracks> {
        use rayon::prelude::*;
        if !matches!(flow, Flow::Turbulence { .. }) {
            return None;
        }
        let samples = ((f64::from(last_tick) + 1.0) / Self::STEP).ceil() as usize + 1;
        if samples.saturating_mul(particles.len()) > Self::MAX {
            return None;
        }
        let pos = particles
            .par_iter()
            .flat_map_iter(|p| {
                let (mut x, mut r) = (p.x, p.row);
                (0..samples).map(move |j| {
                    if j > 0 {
                        let t = Self::STEP * (j - 1) as f64;
                        (x, r) = flow.advect(x, r, t, t + Self::STEP);
                    }
                    (x as f32, r as f32)
                })
            })
            .collect();
        Some(Tracks { samples, pos })
    }

    /// Particle `i` at tick `t`, if `t` is within the samples.
    fn at(&self, i: usize, t: f64) -> Option<(f64, f64)> {
        let s = t / Self::STEP;
        if !(0.0..(self.samples - 1) as f64).contains(&s) {
            return None;
        }
        let j = s.floor() as usize;
        let f = s - j as f64;
        let base = i.checked_mul(self.samples)?;
        let (a, b) = (self.pos.get(base + j)?, self.pos.get(base + j + 1)?);
        Some((
            f64::from(a.0) + f * f64::from(b.0 - a.0),
            f64::from(a.1) + f * f64::from(b.1 - a.1),
        ))
    }
}

/// Side of the seeding cells, px (the paper's 32×32 density rule).
const SEED_CELL: f64 = 32.0;

/// The area to seed, `(x0, x1, r0, r1)` px: the image and an 8-px margin,
/// extended by whole cells up- and downstream by what the flow carries
/// into the image by `last_tick`; one period of a periodic field.
fn seeding_area(params: &SceneParams, flow: &Flow, last_tick: u32) -> (f64, f64, f64, f64) {
    let (w, h) = (f64::from(params.width), f64::from(params.height));
    let (mut umin, mut umax) = (0.0f64, 0.0f64);
    for i in 0..=64 {
        if let Some(u) = flow.profile_u(h * f64::from(i) / 64.0) {
            umin = umin.min(u);
            umax = umax.max(u);
        }
    }
    let t = f64::from(last_tick);
    let margin = 8.0;
    // Seeding cells sit on the image's own 32×32 grid (the rule is about
    // those cells), extended by whole cells up- and downstream.
    let snap_lo = |v: f64| (v / SEED_CELL).floor() * SEED_CELL;
    let x0 = snap_lo(-margin - umax.max(0.0) * t);
    let x1 = w + margin - umin.min(0.0) * t;
    let (r0, r1) = match flow {
        Flow::Uniform { v, .. } => (
            snap_lo(-margin - v.max(0.0) * t),
            h + margin - v.min(0.0) * t,
        ),
        _ => (snap_lo(-margin), h + margin),
    };
    // A periodic field: seed one period; particles wrap around it.
    match flow {
        Flow::Turbulence { period, .. } => (0.0, *period, 0.0, *period),
        _ => (x0, x1, r0, r1),
    }
}

/// Particles over `area` from `seed`: per cell at least `per_cell`,
/// centres at least `min_spacing` apart, at most 1000 tries per particle.
/// Behind a light sheet `per_cell` and `min_spacing` count the particles
/// in it: the volume holds `depth / thickness` times as many, their
/// projected centres closer by the square root of that.
fn seed_particles(
    params: &SceneParams,
    (x0, x1, r0, r1): (f64, f64, f64, f64),
    seed: u64,
) -> Vec<Particle> {
    let cell = SEED_CELL;
    let (per_cell, min_spacing) = match params.sheet {
        Some(sh) => {
            let f = (sh.depth / sh.thickness.max(1e-9)).max(1.0);
            (
                (params.per_cell as f64 * f).round() as usize,
                params.min_spacing / f.sqrt(),
            )
        }
        None => (params.per_cell, params.min_spacing),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut particles: Vec<Particle> = Vec::new();
    let (nx, ny) = (
        ((x1 - x0) / cell).ceil() as usize,
        ((r1 - r0) / cell).ceil() as usize,
    );
    // A grid of particle indices for the spacing test.
    let mut grid: Vec<Vec<usize>> = vec![Vec::new(); nx * ny];
    let min2 = min_spacing * min_spacing;
    for cy in 0..ny {
        for cx in 0..nx {
            let (cx0, cy0) = (x0 + cell * cx as f64, r0 + cell * cy as f64);
            let (cw, ch) = (cell.min(x1 - cx0), cell.min(r1 - cy0));
            let mut have = grid[cy * nx + cx].len();
            let mut tries = 0;
            while have < per_cell && tries < 1000 * per_cell {
                tries += 1;
                let x = cx0 + rng.gen::<f64>() * cw;
                let row = cy0 + rng.gen::<f64>() * ch;
                let near = (cy.saturating_sub(1)..(cy + 2).min(ny)).any(|gy| {
                    (cx.saturating_sub(1)..(cx + 2).min(nx)).any(|gx| {
                        grid[gy * nx + gx].iter().any(|&i| {
                            let p: &Particle = &particles[i];
                            (p.x - x).powi(2) + (p.row - row).powi(2) < min2
                        })
                    })
                });
                if near {
                    continue;
                }
                let peak = params.particle_peak * (1.0 + 0.3 * (2.0 * rng.gen::<f64>() - 1.0));
                let d =
                    params.diameter.0 + (params.diameter.1 - params.diameter.0) * rng.gen::<f64>();
                // Depth and out-of-plane speed only where a sheet asks
                // (the other scenes' draws stay as they were).
                let (z, w) = match params.sheet {
                    Some(sh) => {
                        let z = (rng.gen::<f64>() - 0.5) * sh.depth;
                        let g = normal(&mut rng);
                        (z, g * sh.w_rms)
                    }
                    None => (0.0, 0.0),
                };
                grid[cy * nx + cx].push(particles.len());
                particles.push(Particle {
                    x,
                    row,
                    peak,
                    diameter: d,
                    z,
                    w,
                });
                have += 1;
            }
        }
    }
    particles
}

/// A standard normal draw (Box–Muller).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1 = rng.gen::<f64>().max(1e-300);
    let u2 = rng.gen::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Density reached over the image's full 32×32 cells at tick 0 (cells cut
/// by the right or bottom edge hold proportionally fewer): `(cells with at
/// least per_cell particles, cells)`.
fn density_reached(params: &SceneParams, particles: &[Particle]) -> (usize, usize) {
    let cell = SEED_CELL;
    let (w, h) = (f64::from(params.width), f64::from(params.height));
    let (icx, icy) = ((w / cell).floor() as usize, (h / cell).floor() as usize);
    let mut per = vec![0usize; icx * icy];
    for p in particles {
        if p.x >= 0.0 && p.x < icx as f64 * cell && p.row >= 0.0 && p.row < icy as f64 * cell {
            per[(p.row / cell) as usize * icx + (p.x / cell) as usize] += 1;
        }
    }
    let ok = per.iter().filter(|&&n| n >= params.per_cell).count();
    (ok, per.len())
}

impl Scene {
    /// Seeds particles for ticks `0..=last_tick`: over the image, plus the
    /// region upstream that the flow carries into it by then. Per 32×32 cell
    /// at least `per_cell`, centres at least `min_spacing` apart, at most 1000
    /// tries per particle (the paper's rule with its bounded retries).
    pub fn new(params: SceneParams, seed: u64, last_tick: u32) -> Scene {
        let flow = params.flow();
        let area = seeding_area(&params, &flow, last_tick);
        let particles = seed_particles(&params, area, seed);
        let density_reached = density_reached(&params, &particles);
        let static_rows = (0..params.height)
            .map(|i| Self::static_light_of(&params, usize::from(i)) as f32)
            .collect();
        let tracks = Tracks::new(&flow, &particles, last_tick);
        Scene {
            params,
            flow,
            particles,
            density_reached,
            static_rows,
            tracks,
        }
    }

    /// Where particle `i` is at tick `t` (px; wrapped into the period of a
    /// periodic field).
    pub fn position(&self, i: usize, t: f64) -> (f64, f64) {
        let p = &self.particles[i];
        let (x, r) = match self.tracks.as_ref().and_then(|tr| tr.at(i, t)) {
            Some(xr) => xr,
            None => self.flow.advect(p.x, p.row, 0.0, t),
        };
        match self.flow {
            Flow::Turbulence { period, .. } => (x.rem_euclid(period), r.rem_euclid(period)),
            _ => (x, r),
        }
    }

    /// The scene tick halfway through the pair of frames at ticks `ka` and
    /// `kb` (each frame centred on the middle of its tick).
    pub fn pair_mid(ka: u64, kb: u64) -> f64 {
        (ka as f64 + kb as f64) / 2.0 + 0.5
    }

    /// The dense ground truth of a pair `dt` ticks apart centred on tick 0
    /// (of any pair of a steady flow; [`Scene::truth_dense_at`] for a
    /// flow that evolves).
    pub fn truth_dense(&self, dt: f64) -> DenseField {
        self.truth_dense_at(0.0, dt)
    }

    /// The dense ground truth of a pair `dt` ticks apart centred on tick
    /// `mid`: the displacement of the particle at each pixel centre
    /// halfway through, px (u right, v down), `width × height` upright.
    pub fn truth_dense_at(&self, mid: f64, dt: f64) -> DenseField {
        use rayon::prelude::*;
        let (w, h) = (
            usize::from(self.params.width),
            usize::from(self.params.height),
        );
        let rows: Vec<Vec<(f32, f32)>> = (0..h)
            .into_par_iter()
            .map(|i| {
                (0..w)
                    .map(|j| {
                        let (u, v) =
                            self.flow
                                .displacement_at(j as f64 + 0.5, i as f64 + 0.5, mid, dt);
                        (u as f32, v as f32)
                    })
                    .collect()
            })
            .collect();
        let mut f = DenseField::zeros(w, h);
        for (k, (u, v)) in rows.into_iter().flatten().enumerate() {
            f.u[k] = u;
            f.v[k] = v;
        }
        f
    }

    fn static_light_of(p: &SceneParams, i: usize) -> f64 {
        let y = f64::from(p.height) - 0.5 - i as f64;
        let s = p.glare_sigma.max(1e-9);
        p.background + p.glare_peak * (-(y * y) / (2.0 * s * s)).exp()
    }

    /// Light of the static part (background + glare) in image row `i`, thresholds/tick.
    pub fn static_light(&self, i: usize) -> f64 {
        self.static_rows.get(i).map_or(0.0, |&v| f64::from(v))
    }

    /// Renders the light at time `t` (ticks) into `light` (`width × height`,
    /// upright rows): the static rows plus every particle near the image.
    pub fn render(&self, t: f64, light: &mut [f32]) {
        let (w, h) = (
            usize::from(self.params.width),
            usize::from(self.params.height),
        );
        for (row, &v) in light.chunks_exact_mut(w).zip(&self.static_rows) {
            row.fill(v);
        }
        let mut ex = [0f32; 32];
        let mut ey = [0f32; 32];
        let period = match self.flow {
            Flow::Turbulence { period, .. } => Some(period),
            _ => None,
        };
        for (i, p) in self.particles.iter().enumerate() {
            let (x, r) = self.position(i, t);
            // A particle near the far edge of a period also shows at the
            // near edge of the image.
            let (x, r) = match period {
                Some(per) if x > per - 16.0 => (x - per, r),
                _ => (x, r),
            };
            let r = match period {
                Some(per) if r > per - 16.0 => r - per,
                _ => r,
            };
            let peak = match &self.params.sheet {
                Some(sh) => p.peak * p.lit(sh, t),
                None => p.peak,
            };
            let sigma = p.diameter / 4.0;
            let rad = (3.0 * sigma).min(15.0);
            let (c0, c1) = ((x - rad).floor().max(0.0), (x + rad).ceil().min(w as f64));
            let (r0, r1) = ((r - rad).floor().max(0.0), (r + rad).ceil().min(h as f64));
            if c1 <= c0 || r1 <= r0 {
                continue;
            }
            let k = -1.0 / (2.0 * sigma * sigma);
            let (c0, c1, r0, r1) = (c0 as usize, c1 as usize, r0 as usize, r1 as usize);
            for (j, e) in (c0..c1).zip(ex.iter_mut()) {
                let d = j as f64 + 0.5 - x;
                *e = (d * d * k).exp() as f32;
            }
            for (i, e) in (r0..r1).zip(ey.iter_mut()) {
                let d = i as f64 + 0.5 - r;
                *e = (peak * (d * d * k).exp()) as f32;
            }
            for (i, &eyi) in (r0..r1).zip(ey.iter()) {
                let row = &mut light[i * w + c0..i * w + c1];
                for (l, &exj) in row.iter_mut().zip(ex.iter()) {
                    *l += eyi * exj;
                }
            }
        }
    }

    /// Ground truth at vector positions `(x, y)` for a pair `dt` ticks
    /// apart centred on tick 0 (of any pair of a steady flow;
    /// [`Scene::truth_at`] for a flow that evolves).
    pub fn truth(&self, points: &[(f64, f64)], dt: f64) -> Vec<(f64, f64, f64, f64)> {
        self.truth_at(points, 0.0, dt)
    }

    /// Ground truth at vector positions `(x, y)` (docs/formats.md: pixel (row i,
    /// column j) has its centre at (x = j, y = i)) for a pair `dt` ticks apart
    /// centred on tick `mid`: `(x, y, u, v)` in px, u right, v down.
    pub fn truth_at(&self, points: &[(f64, f64)], mid: f64, dt: f64) -> Vec<(f64, f64, f64, f64)> {
        points
            .iter()
            .map(|&(x, y)| {
                // Vector coordinates put pixel centres on integers; the scene on half-integers.
                let (u, v) = self.flow.displacement_at(x + 0.5, y + 0.5, mid, dt);
                (x, y, u, v)
            })
            .collect()
    }

    /// [`Scene::truth`] as vector-field rows (flag 0), as PIV writes them.
    pub fn truth_vectors(
        &self,
        points: &[(f64, f64)],
        dt: f64,
    ) -> Vec<spiv_formats::vectors::Vector> {
        self.truth_vectors_at(points, 0.0, dt)
    }

    /// [`Scene::truth_at`] as vector-field rows (flag 0).
    pub fn truth_vectors_at(
        &self,
        points: &[(f64, f64)],
        mid: f64,
        dt: f64,
    ) -> Vec<spiv_formats::vectors::Vector> {
        self.truth_at(points, mid, dt)
            .into_iter()
            .map(|(x, y, u, v)| spiv_formats::vectors::Vector {
                x,
                y,
                u,
                v,
                state: spiv_formats::State::Valid,
            })
            .collect()
    }

    /// The analytic profile u(y) for a pair `dt` ticks apart, one value per
    /// pixel row: `(y up from the wall, u px per pair)`; empty for the vortex.
    pub fn profile(&self, dt: f64) -> Vec<(f64, f64)> {
        let h = f64::from(self.params.height);
        (0..self.params.height)
            .filter_map(|i| {
                let y = h - 0.5 - f64::from(i);
                self.flow.profile_u(y).map(|u| (y, u * dt))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turbulence_tracks_follow_the_flow_and_wrap() {
        let p = SceneParams {
            width: 128,
            height: 128,
            ..SceneParams::new(SceneKind::Turbulence)
        };
        let s = Scene::new(p, 3, 60);
        let per = s.params.period();
        assert_eq!(per, 192.0);
        for (i, q) in s.particles.iter().enumerate().step_by(37) {
            for t in [0.0, 10.3, 33.75, 59.9] {
                let (x, r) = s.position(i, t);
                let (ex, er) = s.flow.advect(q.x, q.row, 0.0, t);
                let d = (x - ex.rem_euclid(per)).hypot(r - er.rem_euclid(per));
                assert!(d < 0.005, "particle {i} at {t}: {d} px off");
                assert!((0.0..per).contains(&x) && (0.0..per).contains(&r));
            }
        }
        // Dense truth agrees with the vector truth where both are taken.
        let dense = s.truth_dense(21.0);
        for (x, y, u, v) in s.truth(&[(10.0, 20.0), (100.0, 64.0)], 21.0) {
            let k = y as usize * 128 + x as usize;
            assert!((f64::from(dense.u[k]) - u).abs() < 1e-4);
            assert!((f64::from(dense.v[k]) - v).abs() < 1e-4);
        }
        // Seeding covers the period evenly (divergence-free: it stays so).
        let inside = |t: f64| {
            (0..s.particles.len())
                .filter(|&i| {
                    let (x, r) = s.position(i, t);
                    x < 96.0 && r < 96.0
                })
                .count() as f64
        };
        let (n0, n1) = (inside(0.0), inside(59.0));
        assert!((n1 - n0).abs() < 0.15 * n0, "{n0} then {n1} in a quarter");
    }

    /// The vortex array is a 2-D flow over the glare band: both components
    /// move, the field repeats over its period, its fastest point is the
    /// vortices' speed plus the drift, and the flow seed moves the array
    /// and turns the drift.
    #[test]
    fn vortex_array_is_two_dimensional_and_seeded_by_its_flow_seed() {
        let p = SceneParams::new(SceneKind::VortexArray);
        assert_eq!((p.width, p.height, p.pair_dt), (256, 256, 10));
        assert!(p.glare_peak > 0.6);
        assert_eq!(p.period(), 512.0);
        let f = p.flow();
        let (mut umax, mut vmax, mut top) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..64 {
            for j in 0..64 {
                let (u, v) = f.velocity(4.0 * j as f64, 4.0 * i as f64);
                umax = umax.max(u.abs());
                vmax = vmax.max(v.abs());
                top = top.max(u.hypot(v));
                let (u2, v2) = f.velocity(4.0 * j as f64 + 512.0, 4.0 * i as f64);
                assert!((u - u2).abs() < 1e-9 && (v - v2).abs() < 1e-9);
            }
        }
        assert!(umax > 0.2 && vmax > 0.2, "{umax} {vmax}");
        assert!(top <= 0.3 * 1.4 + 1e-9 && top > 0.3, "{top}");
        let other = SceneParams {
            flow_seed: 2,
            ..p.clone()
        }
        .flow();
        assert_ne!(f, other);
        let s = Scene::new(p, 1, 160);
        let (ok, all) = s.density_reached;
        assert!(ok as f64 >= 0.95 * all as f64, "{ok}/{all}");
    }

    /// The spectral turbulence moves by its rms displacement per pair,
    /// evolves, and lights its particles by where they are in the sheet:
    /// about as many lit (above e⁻²) as `per_cell` asks, each fading in
    /// and out as it crosses the sheet.
    #[test]
    fn spectral_turbulence_is_as_fast_as_asked_and_lit_by_its_sheet() {
        let p = SceneParams {
            width: 128,
            height: 128,
            ..SceneParams::new(SceneKind::SpectralTurbulence)
        };
        let s = Scene::new(p.clone(), 2, 62);
        assert!(s.flow.evolves());
        let dt = f64::from(p.pair_dt);
        let t = s.truth_dense_at(31.0, dt);
        let rms =
            (t.u.iter()
                .zip(&t.v)
                .map(|(&u, &v)| f64::from(u * u + v * v))
                .sum::<f64>()
                / t.u.len() as f64)
                .sqrt();
        // Over a 128² crop of one period: within a third of the whole.
        assert!((rms - 2.0).abs() < 0.7, "rms {rms} px per pair");
        let other = s.truth_dense_at(0.0, dt);
        assert_ne!(t.u, other.u);
        let sheet = p.sheet.unwrap();
        let lit = |t: f64| {
            s.particles
                .iter()
                .filter(|q| q.lit(&sheet, t) > (-2f64).exp())
                .count()
        };
        let cells = (s.params.period() / 32.0).powi(2);
        let (l0, l1) = (lit(0.0) as f64, lit(60.0) as f64);
        assert!(
            (l0 / cells - 12.0).abs() < 3.0,
            "{l0} lit over {cells} cells"
        );
        assert!((l1 - l0).abs() < 0.1 * l0, "{l0} then {l1}");
        let turned = s
            .particles
            .iter()
            .filter(|q| (q.lit(&sheet, 0.0) > 0.5) != (q.lit(&sheet, 60.0) > 0.5))
            .count();
        assert!(
            turned as f64 > 0.05 * l0,
            "{turned} of {l0} crossed the sheet's edge"
        );
        // Without a sheet every particle is as bright as it was seeded and
        // the frozen scenes draw no depth.
        let plain = Scene::new(SceneParams::new(SceneKind::Turbulence), 2, 10);
        assert!(plain.particles.iter().all(|q| q.z == 0.0 && q.w == 0.0));
    }

    #[test]
    fn seeding_meets_the_density_rule() {
        let s = Scene::new(SceneParams::new(SceneKind::PaperLinear), 1, 141);
        let (ok, all) = s.density_reached;
        assert_eq!(all, 12 * 7);
        assert!(ok as f64 >= 0.95 * all as f64, "{ok}/{all}");
        for (i, a) in s.particles.iter().enumerate() {
            for b in &s.particles[i + 1..] {
                assert!((a.x - b.x).hypot(a.row - b.row) >= 8.0);
            }
        }
    }

    #[test]
    fn glare_and_particles_render() {
        let s = Scene::new(SceneParams::new(SceneKind::PaperLinear), 2, 0);
        let mut light = vec![0f32; 400 * 250];
        s.render(0.0, &mut light);
        // Bottom row: background + glare peak (y = 0.5).
        assert!((s.static_light(249) - 0.66).abs() < 1e-3);
        assert!((s.static_light(0) - 0.01).abs() < 1e-6);
        let max = light.iter().cloned().fold(0.0, f32::max);
        assert!(max > 0.3, "a particle on the glare should exceed it: {max}");
    }

    #[test]
    fn names_round_trip() {
        for (n, k) in SceneKind::ALL {
            assert_eq!(SceneKind::from_name(n), Some(k));
            assert_eq!(k.name(), n);
        }
        assert_eq!(SceneKind::from_name("nope"), None);
        let e = SceneKind::parse("nope").unwrap_err().to_string();
        assert!(
            e.starts_with("unknown scene 'nope' (one of: paper-linear, "),
            "{e}"
        );
    }
}
