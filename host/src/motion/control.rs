//! The loop between pairs: what the estimator asks the core to make of the
//! next pair, from what it measured so far ([`Ask::after`]). A pair with
//! no usable field before it carries its events (the time ladder starts
//! from its short, uncompensated rungs, which nothing blurs); after a
//! usable field, the next pair carries its rung frames warped along that
//! field, and its events too while the dense ensemble measures the flow.
//! The sidecar's loop and `spiv flow` follow the same asks, so the frames
//! are the same either way.

use spiv_core::rungs::{Rungs, MAX_RUNGS};

use super::ladder::{per_ticks, LadderSettings, Measurement};
use crate::piv::Field;

/// What the next pair is made with.
#[derive(Debug, Clone)]
pub struct Ask {
    /// The flow its rung frames follow: node velocities, px per tick, on
    /// the ladder's grid (`None`: no rung frames).
    pub flow: Option<Field>,
    /// Separations of the rung frames, ticks, shortest first.
    pub rungs: Vec<u32>,
    /// Ticks on each side of the midpoint whose events it carries (0:
    /// none).
    pub reach: u32,
}

impl Ask {
    /// A pair with no flow to follow: its events within the ladder's
    /// bootstrap reach.
    pub fn cold(cfg: &LadderSettings) -> Ask {
        Ask {
            flow: None,
            rungs: Vec::new(),
            reach: cfg.bootstrap_reach,
        }
    }

    /// What the pair after `m` (measured over `dt` ticks) is made with: its
    /// rung frames along `m`'s field when that field is usable (every
    /// separation of `cfg` longer than its bootstrap rungs), with its events
    /// too when `m` was measured from its events alone or by the dense
    /// ensemble; else its events alone.
    pub fn after(m: &Measurement, dt: f64, cfg: &LadderSettings) -> Ask {
        if !m.field.usable() {
            return Ask::cold(cfg);
        }
        Ask {
            flow: Some(per_ticks(&m.field, 1.0 / dt.max(1e-9))),
            rungs: cfg
                .separations
                .iter()
                .copied()
                .filter(|&s| s > cfg.bootstrap_longest)
                .take(MAX_RUNGS)
                .collect(),
            // Events again after a pair measured from its events alone (its
            // field has not yet been confirmed by a rung along it) and
            // while the dense ensemble measures.
            reach: if m.ensemble || m.confirmed.is_none() {
                cfg.bootstrap_reach
            } else {
                0
            },
        }
    }

    /// Whether the pair carries rung frames.
    pub fn warm(&self) -> bool {
        self.flow.is_some() && !self.rungs.is_empty()
    }

    /// The core's rung request: the separations `fits` keeps (those the
    /// ticks around the pair hold), and the reach.
    pub fn core_rungs(&self, fits: impl Fn(u32) -> bool) -> Rungs {
        let mut r = Rungs::events(u16::try_from(self.reach).unwrap_or(u16::MAX));
        if self.flow.is_none() {
            return r;
        }
        for &s in self.rungs.iter().filter(|&&s| fits(s)) {
            if usize::from(r.count) == MAX_RUNGS {
                break;
            }
            if let Ok(s) = u16::try_from(s) {
                r.separations[usize::from(r.count)] = s;
                r.count += 1;
            }
        }
        r
    }
}
