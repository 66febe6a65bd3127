//! Velocity fields of the scenes (docs/spec.md §4), in pixels per tick, image
//! coordinates: `x` right, `row` down (row i has its centre at i + 0.5), the
//! wall at the bottom edge, `y = H − row` the height above it.
//!
//! Particles are advected exactly: shear flows move each particle along its
//! row at u(y); the vortex turns each particle about the centre at its own
//! angular velocity. So positions at any tick come in closed form, and the
//! ground truth is the true displacement of a particle, not a sampled velocity.

use serde::{Deserialize, Serialize};

/// The velocity profile of a shear flow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Profile {
    /// u = U·y/H.
    Linear,
    /// u = U·(y/H)².
    Quadratic,
    /// u = U·ln(1 + y/y0)/ln(1 + H/y0), y0 = 5 px.
    Log,
    /// u/U = f'(η), η = 4.91·y/δ99 (laminar boundary layer).
    Blasius,
}

/// A velocity field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Flow {
    /// Horizontal shear over the wall: u(y), v = 0.
    Shear {
        /// Profile.
        profile: Profile,
        /// Top speed U, px/tick.
        top: f64,
        /// Image height H, px.
        height: f64,
        /// δ99 of the Blasius profile, px (unused by the others).
        delta99: f64,
    },
    /// The same displacement everywhere (px/tick right and down).
    Uniform {
        /// px/tick, right.
        u: f64,
        /// px/tick, down.
        v: f64,
    },
    /// Kinematic turbulence (beyond the paper): a divergence-free field of
    /// random Fourier modes of the stream function
    /// ψ = Σ a·cos(kx·x + ky·row + φ − ω·t), u = ∂ψ/∂row, v = −∂ψ/∂x
    /// (frozen where every ω is 0; [`evolving`] gives each mode its own
    /// frequency, so the field changes as particles cross it), periodic
    /// over `period` px in both directions (every k a multiple of
    /// 2π/period), with a Kolmogorov-like spectrum ([`turbulence_modes`]).
    /// Particles are advected by RK4 (steps of [`RK4_STEP`] ticks).
    /// A uniform `drift` adds to the modes (an array of Taylor–Green
    /// vortices carried along, [`taylor_green_modes`]).
    Turbulence {
        /// Period of the field in x and rows, px.
        period: f64,
        /// The modes.
        modes: Vec<Mode>,
        /// Uniform velocity added everywhere, px/tick (right, down).
        #[serde(default)]
        drift: (f64, f64),
    },
    /// Lamb–Oseen vortex: v_θ(r) = Γ/(2πr)·(1 − exp(−r²/rc²)).
    Vortex {
        /// Centre column, px.
        cx: f64,
        /// Centre row coordinate, px.
        cy: f64,
        /// Circulation Γ, px²/tick.
        gamma: f64,
        /// Core radius rc, px.
        rc: f64,
    },
}

/// One Fourier mode of a turbulence stream function:
/// ψ = `amp`·cos(`kx`·x + `ky`·row + `phase` − `omega`·t).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Mode {
    /// Wavenumber along x, rad/px.
    pub kx: f64,
    /// Wavenumber along rows, rad/px.
    pub ky: f64,
    /// Amplitude of ψ, px²/tick.
    pub amp: f64,
    /// Phase at tick 0, rad.
    pub phase: f64,
    /// Angular frequency, rad/tick (0: the mode is frozen).
    #[serde(default)]
    pub omega: f64,
}

/// RK4 step of the turbulence advection, ticks (the error at the smallest
/// eddies of the default scene is below 10⁻⁴ px per pair).
pub const RK4_STEP: f64 = 0.25;

/// Modes of a turbulence field periodic over `period` px: `n` wavevectors
/// with integer indices (so the field is periodic), their wavelengths
/// log-spread over `[l_min, l_max]` px, random directions and phases from
/// `seed`; amplitudes of a Kolmogorov-like spectrum (E(k) ∝ k^(−5/3), so
/// with log-spaced k each mode's speed ∝ k^(−1/3)) with a dissipation
/// roll-off exp(−(k·l_min/2π)²) at the smallest eddies, scaled so the
/// fastest point of the field moves `max_speed` px/tick.
pub fn turbulence_modes(
    seed: u64,
    period: f64,
    l_min: f64,
    l_max: f64,
    n: usize,
    max_speed: f64,
) -> Vec<Mode> {
    use rand::{Rng, SeedableRng};
    let tau = 2.0 * std::f64::consts::PI;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (k_lo, k_hi) = (period / l_max.max(1.0), period / l_min.max(1.0));
    let mut modes: Vec<Mode> = Vec::with_capacity(n);
    for i in 0..n {
        // Index magnitude log-spaced from k_lo to k_hi (the field's own
        // harmonics of the period), random direction, snapped to integers.
        let f = if n > 1 {
            i as f64 / (n - 1) as f64
        } else {
            0.0
        };
        let m = (k_lo.max(1.0) * (k_hi.max(1.0) / k_lo.max(1.0)).powf(f)).max(1.0);
        let a = rng.gen::<f64>() * tau;
        let (mut nx, ny) = ((m * a.cos()).round(), (m * a.sin()).round());
        if nx == 0.0 && ny == 0.0 {
            nx = 1.0;
        }
        let (kx, ky) = (tau * nx / period, tau * ny / period);
        let k = kx.hypot(ky);
        modes.push(Mode {
            kx,
            ky,
            amp: k.powf(-1.0 / 3.0) * (-(k * l_min / tau).powi(2)).exp() / k,
            phase: rng.gen::<f64>() * tau,
            omega: 0.0,
        });
    }
    let probe = Flow::Turbulence {
        period,
        modes: modes.clone(),
        drift: (0.0, 0.0),
    };
    // The fastest point on a 1-px lattice over one period.
    let cells = period.ceil().max(1.0) as usize;
    let mut top: f64 = 0.0;
    for i in 0..cells {
        for j in 0..cells {
            let (u, v) = probe.velocity(j as f64, i as f64);
            top = top.max(u.hypot(v));
        }
    }
    let scale = if top > 0.0 { max_speed / top } else { 0.0 };
    for m in &mut modes {
        m.amp *= scale;
    }
    modes
}

/// The two modes of an array of Taylor–Green vortices of `cell` px (half a
/// wavelength: neighbouring cells turn opposite ways) whose fastest point
/// moves `speed` px/tick: ψ = (U/k)·sin(k(x + x0))·sin(k(row + y0)), k =
/// π/`cell`, so u = U·sin(k(x + x0))·cos(k(row + y0)) and v = −U·cos(k(x +
/// x0))·sin(k(row + y0)), written as ½(U/k)·[cos(k(x + x0) − k(row + y0)) −
/// cos(k(x + x0) + k(row + y0))]. Periodic over any multiple of 2·`cell`.
pub fn taylor_green_modes(cell: f64, speed: f64, (x0, y0): (f64, f64)) -> Vec<Mode> {
    let k = std::f64::consts::PI / cell.max(1.0);
    let a = 0.5 * speed / k;
    vec![
        Mode {
            kx: k,
            ky: -k,
            amp: a,
            phase: k * (x0 - y0),
            omega: 0.0,
        },
        Mode {
            kx: k,
            ky: k,
            amp: -a,
            phase: k * (x0 + y0),
            omega: 0.0,
        },
    ]
}

/// `modes` made to evolve: each mode gets the frequency of its own eddy
/// turnover, ω = ±`rate`·|k|·u_k (u_k = `amp`·|k|, its peak speed), the
/// sign and a factor uniform in [0.5, 1.5] drawn from `seed`. A mode then
/// travels along its wavevector at `rate`·u_k (times that factor), so small
/// eddies are swept and decorrelate faster than large ones, as in a
/// turbulent flow; the field stays divergence-free.
pub fn evolving(mut modes: Vec<Mode>, rate: f64, seed: u64) -> Vec<Mode> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x6576_6f6c_7665);
    for m in &mut modes {
        let k2 = m.kx * m.kx + m.ky * m.ky;
        let sign = if rng.gen::<bool>() { 1.0 } else { -1.0 };
        m.omega = sign * rate * (0.5 + rng.gen::<f64>()) * m.amp.abs() * k2;
    }
    modes
}

/// The root-mean-square speed of `modes` at tick 0 over one `period`
/// (sampled on a 2-px lattice), px/tick.
pub fn rms_speed(modes: &[Mode], period: f64) -> f64 {
    let probe = Flow::Turbulence {
        period,
        modes: modes.to_vec(),
        drift: (0.0, 0.0),
    };
    let cells = (period / 2.0).ceil().max(1.0) as usize;
    let mut sum = 0.0;
    for i in 0..cells {
        for j in 0..cells {
            let (u, v) = probe.velocity(2.0 * j as f64, 2.0 * i as f64);
            sum += u * u + v * v;
        }
    }
    (sum / (cells * cells) as f64).sqrt()
}

/// Blasius solution `f'(η)` on η ∈ [0, 10], step 0.01, with `f''(0)`.
#[derive(Debug, Clone)]
pub struct Blasius {
    /// f''(0), ≈ 0.332057.
    pub fpp0: f64,
    fp: Vec<f64>,
}

const BLASIUS_STEP: f64 = 0.01;
const BLASIUS_END: f64 = 10.0;

fn blasius_shoot(fpp0: f64, store: Option<&mut Vec<f64>>) -> f64 {
    // f''' + ½ f f'' = 0 as a first-order system, classic RK4.
    let rhs = |s: [f64; 3]| [s[1], s[2], -0.5 * s[0] * s[2]];
    let mut s = [0.0, 0.0, fpp0];
    let h = BLASIUS_STEP;
    let n = (BLASIUS_END / h).round() as usize;
    let mut out = store;
    if let Some(v) = out.as_deref_mut() {
        v.clear();
        v.push(s[1]);
    }
    for _ in 0..n {
        let add =
            |a: [f64; 3], b: [f64; 3], k: f64| [a[0] + k * b[0], a[1] + k * b[1], a[2] + k * b[2]];
        let k1 = rhs(s);
        let k2 = rhs(add(s, k1, h / 2.0));
        let k3 = rhs(add(s, k2, h / 2.0));
        let k4 = rhs(add(s, k3, h));
        for i in 0..3 {
            s[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        if let Some(v) = out.as_deref_mut() {
            v.push(s[1]);
        }
    }
    s[1]
}

impl Blasius {
    /// Solves by shooting on f''(0) until f'(10) = 1 (bisection to 1e-12).
    pub fn solve() -> Blasius {
        let (mut lo, mut hi) = (0.1, 1.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if blasius_shoot(mid, None) > 1.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let fpp0 = 0.5 * (lo + hi);
        let mut fp = Vec::new();
        blasius_shoot(fpp0, Some(&mut fp));
        Blasius { fpp0, fp }
    }

    /// f'(η), linear between samples, 1 beyond η = 10.
    pub fn fprime(&self, eta: f64) -> f64 {
        if eta <= 0.0 {
            return 0.0;
        }
        let x = eta / BLASIUS_STEP;
        let i = x.floor() as usize;
        match (self.fp.get(i), self.fp.get(i + 1)) {
            (Some(&a), Some(&b)) => a + (b - a) * (x - i as f64),
            _ => 1.0,
        }
    }
}

fn blasius() -> &'static Blasius {
    static B: std::sync::OnceLock<Blasius> = std::sync::OnceLock::new();
    B.get_or_init(Blasius::solve)
}

impl Flow {
    /// u(y) of a shear flow (px/tick), y = height above the wall in px.
    fn shear_u(profile: Profile, top: f64, h: f64, delta99: f64, y: f64) -> f64 {
        let y = y.clamp(0.0, h);
        match profile {
            Profile::Linear => top * y / h,
            Profile::Quadratic => top * (y / h).powi(2),
            Profile::Log => top * (1.0 + y / 5.0).ln() / (1.0 + h / 5.0).ln(),
            Profile::Blasius => top * blasius().fprime(4.91 * y / delta99),
        }
    }

    /// Angular velocity of the vortex at radius r (rad/tick).
    fn omega(gamma: f64, rc: f64, r: f64) -> f64 {
        if r < 1e-9 {
            return gamma / (2.0 * std::f64::consts::PI * rc * rc);
        }
        gamma / (2.0 * std::f64::consts::PI * r * r) * (1.0 - (-(r * r) / (rc * rc)).exp())
    }

    /// Where a particle at `(x, row)` at tick `t0` is at tick `t1`.
    pub fn advect(&self, x: f64, row: f64, t0: f64, t1: f64) -> (f64, f64) {
        let dt = t1 - t0;
        if let Flow::Turbulence { .. } = self {
            return self.rk4(x, row, t0, dt);
        }
        match *self {
            Flow::Shear {
                profile,
                top,
                height,
                delta99,
            } => (
                x + Self::shear_u(profile, top, height, delta99, height - row) * dt,
                row,
            ),
            Flow::Uniform { u, v } => (x + u * dt, row + v * dt),
            Flow::Vortex { cx, cy, gamma, rc } => {
                let (dx, dy) = (x - cx, row - cy);
                let r = dx.hypot(dy);
                let a = Self::omega(gamma, rc, r) * dt;
                let (s, c) = a.sin_cos();
                (cx + c * dx - s * dy, cy + s * dx + c * dy)
            }
            Flow::Turbulence { .. } => (x, row),
        }
    }

    /// The velocity at `(x, row)` at tick 0, px/tick (right, down): at
    /// every tick for the steady flows.
    pub fn velocity(&self, x: f64, row: f64) -> (f64, f64) {
        self.velocity_at(x, row, 0.0)
    }

    /// The velocity at `(x, row)` at tick `t`, px/tick (right, down).
    pub fn velocity_at(&self, x: f64, row: f64, t: f64) -> (f64, f64) {
        match self {
            Flow::Turbulence { modes, drift, .. } => {
                let (mut u, mut v) = *drift;
                for m in modes {
                    let s = (m.kx * x + m.ky * row + (m.phase - m.omega * t)).sin() * m.amp;
                    u -= m.ky * s;
                    v += m.kx * s;
                }
                (u, v)
            }
            _ => {
                let (x1, r1) = self.advect(x, row, 0.0, 1e-3);
                ((x1 - x) * 1e3, (r1 - row) * 1e3)
            }
        }
    }

    /// RK4 from tick `t0` over `dt` ticks (either sign) in steps of at
    /// most [`RK4_STEP`].
    fn rk4(&self, x: f64, row: f64, t0: f64, dt: f64) -> (f64, f64) {
        let n = (dt.abs() / RK4_STEP).ceil().max(1.0);
        let h = dt / n;
        let (mut px, mut pr) = (x, row);
        for s in 0..n as usize {
            let t = t0 + h * s as f64;
            let k1 = self.velocity_at(px, pr, t);
            let k2 = self.velocity_at(px + 0.5 * h * k1.0, pr + 0.5 * h * k1.1, t + 0.5 * h);
            let k3 = self.velocity_at(px + 0.5 * h * k2.0, pr + 0.5 * h * k2.1, t + 0.5 * h);
            let k4 = self.velocity_at(px + h * k3.0, pr + h * k3.1, t + h);
            px += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            pr += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        }
        (px, pr)
    }

    /// The true displacement over `dt` ticks of the particle that is at
    /// `(x, row)` halfway through (px right, px down): symmetric about the
    /// pair's midpoint, as a PIV window centred there measures it. For a
    /// pair centred on tick 0 ([`Flow::displacement_at`] for any other):
    /// every pair of a steady flow.
    pub fn displacement(&self, x: f64, row: f64, dt: f64) -> (f64, f64) {
        self.displacement_at(x, row, 0.0, dt)
    }

    /// [`Flow::displacement`] for a pair centred on tick `mid`.
    pub fn displacement_at(&self, x: f64, row: f64, mid: f64, dt: f64) -> (f64, f64) {
        let (xa, ra) = self.advect(x, row, mid, mid - dt / 2.0);
        let (xb, rb) = self.advect(x, row, mid, mid + dt / 2.0);
        (xb - xa, rb - ra)
    }

    /// Whether the field changes with time (a mode with a frequency).
    pub fn evolves(&self) -> bool {
        matches!(self, Flow::Turbulence { modes, .. } if modes.iter().any(|m| m.omega != 0.0))
    }

    /// The profile u(y) of a shear flow in px/tick (`None` for other flows).
    pub fn profile_u(&self, y: f64) -> Option<f64> {
        match *self {
            Flow::Shear {
                profile,
                top,
                height,
                delta99,
            } => Some(Self::shear_u(profile, top, height, delta99, y)),
            Flow::Uniform { u, .. } => Some(u),
            Flow::Vortex { .. } | Flow::Turbulence { .. } => None,
        }
    }

    /// The largest displacement over `dt` ticks anywhere in a `w × h` image, px.
    pub fn max_displacement(&self, w: f64, h: f64, dt: f64) -> f64 {
        let mut m: f64 = 0.0;
        for i in 0..=32 {
            for j in 0..=32 {
                let (dx, dy) = self.displacement(w * j as f64 / 32.0, h * i as f64 / 32.0, dt);
                m = m.max(dx.hypot(dy));
            }
        }
        m
    }
}

/// Γ of a Lamb–Oseen vortex of core radius `rc` whose fastest particles move
/// `peak` px in `dt` ticks.
pub fn vortex_gamma(rc: f64, peak: f64, dt: f64) -> f64 {
    // max of (1 − e^{−s²})/s over s = r/rc, found numerically (≈ 0.6382 at s ≈ 1.1209).
    let m = (1..20000)
        .map(|i| {
            let s = i as f64 * 1e-4 * 5.0;
            (1.0 - (-s * s).exp()) / s
        })
        .fold(0.0, f64::max);
    peak / dt * 2.0 * std::f64::consts::PI * rc / m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blasius_wall_shear_matches_the_literature() {
        let b = Blasius::solve();
        assert!((b.fpp0 - 0.332057).abs() < 1e-5, "f''(0) = {}", b.fpp0);
        // η = 4.91 is the 99 % thickness.
        assert!((b.fprime(4.91) - 0.99).abs() < 2e-3, "{}", b.fprime(4.91));
        assert!((b.fprime(10.0) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn vortex_turns_at_the_requested_peak() {
        let rc = 250.0 / 8.0;
        let g = vortex_gamma(rc, 6.0, 13.0);
        let f = Flow::Vortex {
            cx: 200.0,
            cy: 125.0,
            gamma: g,
            rc,
        };
        let m = f.max_displacement(400.0, 250.0, 13.0);
        assert!((m - 6.0).abs() < 0.05, "peak {m}");
        // Rotation keeps the radius.
        let (x, r) = f.advect(230.0, 125.0, 0.0, 500.0);
        assert!(((x - 200.0).hypot(r - 125.0) - 30.0).abs() < 1e-9);
    }

    fn turbulence() -> Flow {
        Flow::Turbulence {
            period: 320.0,
            modes: turbulence_modes(1, 320.0, 16.0, 256.0, 64, 25.0 / 21.0),
            drift: (0.0, 0.0),
        }
    }

    /// The Taylor–Green modes give the closed form, turn opposite ways in
    /// neighbouring cells, and carry the drift.
    #[test]
    fn taylor_green_array_is_the_closed_form_plus_drift() {
        let (cell, speed, off) = (128.0, 0.3, (17.0, -40.0));
        let f = Flow::Turbulence {
            period: 512.0,
            modes: taylor_green_modes(cell, speed, off),
            drift: (0.1, -0.05),
        };
        let k = std::f64::consts::PI / cell;
        for (x, r) in [(3.0, 5.0), (100.5, 211.0), (300.0, 17.25), (511.0, 480.0)] {
            let (u, v) = f.velocity(x, r);
            let (sx, cx) = (k * (x + off.0)).sin_cos();
            let (sy, cy) = (k * (r + off.1)).sin_cos();
            assert!((u - (0.1 + speed * sx * cy)).abs() < 1e-12, "u at {x},{r}");
            assert!(
                (v - (-0.05 - speed * cx * sy)).abs() < 1e-12,
                "v at {x},{r}"
            );
            let (u2, v2) = f.velocity(x + 512.0, r - 512.0);
            assert!((u - u2).abs() < 1e-9 && (v - v2).abs() < 1e-9);
        }
    }

    #[test]
    fn turbulence_is_divergence_free_periodic_and_as_fast_as_asked() {
        let f = turbulence();
        let e = 1e-4;
        let mut top: f64 = 0.0;
        for i in 0..40 {
            for j in 0..40 {
                let (x, r) = (j as f64 * 8.03, i as f64 * 7.97);
                let div = (f.velocity(x + e, r).0 - f.velocity(x - e, r).0
                    + f.velocity(x, r + e).1
                    - f.velocity(x, r - e).1)
                    / (2.0 * e);
                let (u, v) = f.velocity(x, r);
                assert!(div.abs() < 1e-6 * (1.0 + u.hypot(v)), "div {div}");
                let (u2, v2) = f.velocity(x + 320.0, r - 320.0);
                assert!((u - u2).abs() < 1e-9 && (v - v2).abs() < 1e-9);
                top = top.max(u.hypot(v));
            }
        }
        // The scaling's lattice max, seen on a coarser lattice.
        assert!(
            top <= 25.0 / 21.0 + 1e-9 && top > 0.8 * 25.0 / 21.0,
            "top {top}"
        );
        let m = f.max_displacement(256.0, 256.0, 21.0);
        assert!(m > 15.0 && m < 27.0, "largest displacement {m} px per pair");
    }

    #[test]
    fn turbulence_advection_converges_and_reverses() {
        let f = turbulence();
        let (x, r) = f.advect(100.0, 80.0, 0.0, 21.0);
        // Half the step: the same path within 10⁻⁴ px.
        let n = 21 * 8;
        let (mut a, mut b) = (100.0, 80.0);
        for _ in 0..n {
            (a, b) = f.rk4(a, b, 0.0, 21.0 / n as f64);
        }
        assert!((x - a).hypot(r - b) < 1e-4, "{x},{r} vs {a},{b}");
        // Back again.
        let (x0, r0) = f.advect(x, r, 21.0, 0.0);
        assert!((x0 - 100.0).hypot(r0 - 80.0) < 1e-6);
    }

    /// Modes with frequencies: the field changes with time, stays
    /// divergence-free at every tick, and a path integrated forward comes
    /// back when integrated backward from where it ended; at frequency 0
    /// the field is the frozen one at every tick.
    #[test]
    fn evolving_modes_change_the_field_and_keep_it_divergence_free() {
        let frozen = turbulence();
        let Flow::Turbulence { period, modes, .. } = frozen.clone() else {
            unreachable!()
        };
        let f = Flow::Turbulence {
            period,
            modes: evolving(modes.clone(), 1.0, 3),
            drift: (0.0, 0.0),
        };
        assert!(f.evolves() && !frozen.evolves());
        let e = 1e-4;
        let mut moved: f64 = 0.0;
        for i in 0..12 {
            for j in 0..12 {
                let (x, r, t) = (j as f64 * 21.3, i as f64 * 19.7, 40.0 + i as f64);
                let div = (f.velocity_at(x + e, r, t).0 - f.velocity_at(x - e, r, t).0
                    + f.velocity_at(x, r + e, t).1
                    - f.velocity_at(x, r - e, t).1)
                    / (2.0 * e);
                let (u, v) = f.velocity_at(x, r, t);
                assert!(div.abs() < 1e-6 * (1.0 + u.hypot(v)), "div {div}");
                let (u0, v0) = f.velocity_at(x, r, 0.0);
                moved = moved.max((u - u0).hypot(v - v0));
                assert_eq!(frozen.velocity_at(x, r, t), frozen.velocity(x, r));
                assert_eq!(f.velocity_at(x, r, 0.0), f.velocity(x, r));
            }
        }
        assert!(moved > 0.1 * 25.0 / 21.0, "the field moved {moved} px/tick");
        // Forward from tick 30 to 51, then back.
        let (x, r) = f.advect(100.0, 80.0, 30.0, 51.0);
        let (x0, r0) = f.advect(x, r, 51.0, 30.0);
        assert!((x0 - 100.0).hypot(r0 - 80.0) < 1e-6);
        // The frozen field's displacement is the same for any pair's middle;
        // the evolving one's is not.
        assert_eq!(
            frozen.displacement_at(50.0, 60.0, 33.5, 21.0),
            frozen.displacement(50.0, 60.0, 21.0)
        );
        let (a, b) = (
            f.displacement_at(50.0, 60.0, 33.5, 21.0),
            f.displacement_at(50.0, 60.0, 0.0, 21.0),
        );
        assert!((a.0 - b.0).hypot(a.1 - b.1) > 0.05, "{a:?} {b:?}");
    }

    /// [`rms_speed`] is the root mean square of the field's speed: a
    /// single mode's speed varies as |sin|, whose rms is 1/√2 of its peak.
    #[test]
    fn rms_speed_of_one_mode() {
        let k = std::f64::consts::TAU / 64.0;
        let m = Mode {
            kx: k,
            ky: 0.0,
            amp: 2.0 / k,
            phase: 0.3,
            omega: 0.0,
        };
        let rms = rms_speed(&[m], 128.0);
        assert!((rms - 2.0 / 2f64.sqrt()).abs() < 1e-9, "{rms}");
    }

    #[test]
    fn shear_profiles() {
        let f = Flow::Shear {
            profile: Profile::Linear,
            top: 1.25,
            height: 250.0,
            delta99: 730.0,
        };
        let (dx, dy) = f.displacement(10.0, 0.0, 13.0);
        assert!((dx - 16.25).abs() < 1e-12 && dy == 0.0);
        let f = Flow::Shear {
            profile: Profile::Log,
            top: 1.0,
            height: 250.0,
            delta99: 730.0,
        };
        assert!((f.profile_u(250.0).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(f.profile_u(0.0).unwrap(), 0.0);
    }
}
