//! A simulation as a user asks for it (`spiv simulate`'s options, the
//! Python binding's keywords), checked once for both: every size is
//! bounded before anything is simulated.

use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::Request;
use spiv_formats::MAX_FRAME_PIXELS;

use crate::Error;

/// Longest turbulence simulation, ticks.
pub const MAX_TURBULENCE_TICKS: u32 = 10_000;

/// What to simulate; `None` takes the scene's default.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulateRequest {
    /// Scene: paper-linear, paper-quadratic, paper-log, blasius, uniform,
    /// vortex.
    pub scene: String,
    /// Seed of particles and noise.
    pub seed: u64,
    /// Width, px (≥ 8; `width·height` a multiple of 8, at most
    /// [`MAX_FRAME_PIXELS`]).
    pub width: Option<u16>,
    /// Height, px.
    pub height: Option<u16>,
    /// Planes (1..=1_000_000; default the pair and 64 ticks each side).
    pub ticks: Option<u32>,
    /// Pair separation, ticks (1..=1_000_000).
    pub dt: Option<u32>,
    /// Displacement of the `uniform` scene per pair, px (right, down),
    /// each within ±1000.
    pub shift: Option<(f64, f64)>,
    /// Minimum particle spacing, px (0..=64).
    pub spacing: Option<f64>,
    /// Top speed of the shear flows and the vortex array, px/tick
    /// (0..=64).
    pub speed: Option<f64>,
    /// Seed of the turbulence field and of the vortex array's offset and
    /// drift direction.
    pub flow_seed: Option<u64>,
    /// Spectral turbulence: the member `spiv bench flows` draws from this
    /// seed ([`crate::bench::flows::spectral_member`]), its flow seed too
    /// unless `flow_seed` is given.
    pub member: Option<u64>,
}

impl SimulateRequest {
    /// The default scene with `seed`.
    pub fn new(scene: &str, seed: u64) -> SimulateRequest {
        SimulateRequest {
            scene: scene.into(),
            seed,
            width: None,
            height: None,
            ticks: None,
            dt: None,
            shift: None,
            spacing: None,
            speed: None,
            flow_seed: None,
            member: None,
        }
    }

    /// The simulator's request, or the first value out of range.
    pub fn request(&self) -> Result<Request, Error> {
        let bad = |m: String| Err(Error::Request(m));
        let kind = SceneKind::parse(&self.scene).map_err(|e| Error::Request(e.to_string()))?;
        let mut p = match self.member {
            None => SceneParams::new(kind),
            Some(m) if kind == SceneKind::SpectralTurbulence => SceneParams {
                flow_seed: m,
                ..crate::bench::flows::spectral_member(m).params()
            },
            Some(_) => {
                return bad(format!(
                    "--member applies to spectral-turbulence, not {}",
                    self.scene
                ))
            }
        };
        p.width = self.width.unwrap_or(p.width);
        p.height = self.height.unwrap_or(p.height);
        let px = u64::from(p.width) * u64::from(p.height);
        if p.width < 8 || p.height < 8 || px % 8 != 0 {
            return bad(format!(
                "--width {} --height {}: both at least 8 and width*height a multiple of 8",
                p.width, p.height
            ));
        }
        if px > MAX_FRAME_PIXELS {
            return bad(format!(
                "--width {} --height {}: {px} px, at most {MAX_FRAME_PIXELS}",
                p.width, p.height
            ));
        }
        if let Some(dt) = self.dt {
            if !(1..=1_000_000).contains(&dt) {
                return bad("--dt must be in 1..=1000000 ticks".into());
            }
            p.pair_dt = dt;
        }
        if let Some((u, v)) = self.shift {
            if kind != SceneKind::Uniform {
                return bad("--shift applies to the uniform scene".into());
            }
            if !(u.is_finite() && v.is_finite() && u.abs() <= 1000.0 && v.abs() <= 1000.0) {
                return bad("--shift U,V: two numbers within ±1000 px".into());
            }
            p.shift = (u, v);
        }
        if let Some(s) = self.spacing {
            if !(0.0..=64.0).contains(&s) {
                return bad(format!("--spacing {s}: expected 0..=64 px"));
            }
            p.min_spacing = s;
        }
        if let Some(u) = self.speed {
            let has_speed = matches!(
                kind,
                SceneKind::PaperLinear
                    | SceneKind::PaperQuadratic
                    | SceneKind::PaperLog
                    | SceneKind::Blasius
                    | SceneKind::VortexArray
            );
            if !has_speed {
                return bad(format!(
                    "--speed applies to the shear scenes and vortex-array, not {}",
                    self.scene
                ));
            }
            if !(u.is_finite() && (0.0..=64.0).contains(&u)) {
                return bad(format!("--speed {u}: expected 0..=64 px/tick"));
            }
            p.top_speed = u;
        }
        if let Some(f) = self.flow_seed {
            p.flow_seed = f;
        }
        if self.ticks == Some(0) || self.ticks.is_some_and(|t| t > 1_000_000) {
            return bad("--ticks must be in 1..=1000000".into());
        }
        // Turbulence particles are integrated, not moved in closed form:
        // their tracks are kept for at most this many ticks.
        let integrated = matches!(
            kind,
            SceneKind::Turbulence
                | SceneKind::LargeShift
                | SceneKind::VortexArray
                | SceneKind::SpectralTurbulence
        );
        if integrated && self.ticks.is_some_and(|t| t > MAX_TURBULENCE_TICKS) {
            return bad(format!(
                "--ticks must be in 1..={MAX_TURBULENCE_TICKS} for the {} scene",
                self.scene
            ));
        }
        let mut req = Request::new(p, self.seed);
        req.ticks = self.ticks;
        Ok(req)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_bounded_before_anything_is_simulated() {
        let mut r = SimulateRequest::new("paper-linear", 1);
        assert!(r.request().is_ok());
        r.width = Some(65528);
        r.height = Some(65528);
        assert!(r.request().unwrap_err().to_string().contains("at most"));
        let mut r = SimulateRequest::new("paper-linear", 1);
        r.shift = Some((1.0, 0.0));
        assert!(r.request().unwrap_err().to_string().contains("uniform"));
        assert!(SimulateRequest::new("nope", 1).request().is_err());
    }

    /// `--member` makes the bench's member of the spectral turbulence
    /// (and only of it), and its ticks are bounded as the other integrated
    /// scenes' are.
    #[test]
    fn a_member_is_the_benchs_and_bounded() {
        let mut r = SimulateRequest::new("spectral-turbulence", 3);
        r.member = Some(107);
        let p = r.request().unwrap().scene;
        let fam = crate::bench::flows::families()
            .into_iter()
            .find(|f| f.scene == SceneKind::SpectralTurbulence)
            .unwrap();
        assert_eq!(p, fam.params(107));
        r.ticks = Some(MAX_TURBULENCE_TICKS + 1);
        assert!(r.request().unwrap_err().to_string().contains("--ticks"));
        let mut r = SimulateRequest::new("turbulence", 3);
        r.member = Some(1);
        assert!(r.request().unwrap_err().to_string().contains("--member"));
    }
}
