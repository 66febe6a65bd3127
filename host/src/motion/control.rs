//! The loop between pairs: what the estimator asks the core to make of the
//! next pair, from what it measured so far ([`Ask::after`]). A pair with
//! no usable field before it carries its events (the time ladder starts
//! from its short, uncompensated rungs, which nothing blurs); after a
//! usable field, the next pair carries its rung frames warped along that
//! field, and its events too while the dense ensemble measures the flow.
//! The sidecar's loop and `spiv flow` follow the same asks, so the frames
//! are the same either way.

use std::collections::VecDeque;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
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

/// How the estimator's asks reach the core. `spiv flow` delivers each at
/// once ([`Delivery::default`]); a live downlink delivers them late by
/// whole pairs, and loses some (a control the wire's CRC rejects is lost
/// the same way). The core makes each pair with the last ask it has.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Delivery {
    /// Pairs by which an ask arrives late: the ask measured after pair
    /// `i` makes pair `i + 1 + late` on (0: the next pair).
    pub late: usize,
    /// Share of asks lost, 0–1.
    pub loss: f64,
    /// Seed of the losses.
    pub seed: u64,
}

/// The asks on their way to the core ([`Delivery`]).
#[derive(Debug)]
pub struct AskLink {
    delivery: Delivery,
    rng: ChaCha8Rng,
    sent: VecDeque<(usize, Ask)>,
    current: Ask,
    lost: usize,
}

impl AskLink {
    /// Nothing sent yet: the core makes its pairs [`Ask::cold`].
    pub fn new(delivery: Delivery, cfg: &LadderSettings) -> AskLink {
        AskLink {
            delivery,
            rng: ChaCha8Rng::seed_from_u64(delivery.seed),
            sent: VecDeque::new(),
            current: Ask::cold(cfg),
            lost: 0,
        }
    }

    /// What the core makes pair `i` (counted from the loop's first) with.
    pub fn ask_for(&mut self, i: usize) -> &Ask {
        while let Some((at, _)) = self.sent.front() {
            if *at > i {
                break;
            }
            if let Some((_, a)) = self.sent.pop_front() {
                self.current = a;
            }
        }
        &self.current
    }

    /// Sends `ask`, measured after pair `i`.
    pub fn send(&mut self, i: usize, ask: Ask) {
        let loss = self.delivery.loss.clamp(0.0, 1.0);
        if loss > 0.0 && self.rng.gen::<f64>() < loss {
            self.lost += 1;
            return;
        }
        self.sent.push_back((i + 1 + self.delivery.late, ask));
    }

    /// Asks lost so far.
    pub fn lost(&self) -> usize {
        self.lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn marked(reach: u32) -> Ask {
        Ask {
            flow: None,
            rungs: Vec::new(),
            reach,
        }
    }

    /// An ask sent after pair `i` makes pair `i + 1 + late` on; until
    /// then the core keeps the last one it has (cold at first).
    #[test]
    fn asks_arrive_late_by_whole_pairs() {
        let cfg = LadderSettings::default();
        let mut d = AskLink::new(
            Delivery {
                late: 2,
                ..Delivery::default()
            },
            &cfg,
        );
        let mut seen = Vec::new();
        for i in 0..6 {
            seen.push(d.ask_for(i).reach);
            d.send(i, marked(100 + i as u32));
        }
        let cold = cfg.bootstrap_reach;
        assert_eq!(seen, vec![cold, cold, cold, 100, 101, 102]);
        assert_eq!(d.lost(), 0);
    }

    /// Lost asks leave the core on the last one that arrived; the share
    /// lost follows `loss`, and the same seed loses the same asks.
    #[test]
    fn lost_asks_keep_the_last_one() {
        let cfg = LadderSettings::default();
        let run = |seed| {
            let mut d = AskLink::new(
                Delivery {
                    late: 0,
                    loss: 0.25,
                    seed,
                },
                &cfg,
            );
            let mut seen = Vec::new();
            for i in 0..400 {
                seen.push(d.ask_for(i).reach);
                d.send(i, marked(1000 + i as u32));
            }
            (seen, d.lost())
        };
        let (seen, lost) = run(7);
        assert!((70..130).contains(&lost), "{lost} of 400 lost at 25 %");
        // Each pair uses the newest ask that arrived, a stale one exactly
        // where the one before it was lost (the last ask sent is never
        // used).
        let stale = seen.windows(2).filter(|w| w[1] == w[0]).count();
        assert!(stale == lost || stale + 1 == lost, "{stale} {lost}");
        assert!(seen.windows(2).all(|w| w[1] >= w[0]));
        assert_eq!(run(7), (seen, lost));
    }
}
