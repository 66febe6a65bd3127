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
use spiv_core::pairs::{AskEar, Asked};
use spiv_core::rungs::{Rungs, MAX_RUNGS};
use spiv_core::wire::ask::{ask_parts, encode_ask, MAX_ASK_PAYLOAD};
use spiv_core::wire::control::control_header;
use spiv_core::wire::{encode_message, Header, Kind, WireError, MAX_ENCODED};

use crate::compensate::WarpFlow;
use crate::ladder::{LadderSettings, Measurement};
use crate::units::PerTick;

/// What the next pair is made with.
#[derive(Debug, Clone)]
pub struct Ask {
    /// The flow its rung frames follow: node velocities on the ladder's
    /// grid (`None`: no rung frames).
    pub flow: Option<PerTick>,
    /// Separations of the rung frames, ticks, shortest first.
    pub rungs: Vec<u32>,
    /// Ticks on each side of the midpoint whose events it carries (0:
    /// none).
    pub reach: u32,
}

/// The longest separation the pair after `m` asks for: the shortest rung
/// longer than `cfg`'s bootstrap rungs that `m` climbed to and found
/// unusable (tried again: the flow may have eased), or every rung when
/// none failed. A climb thus reaches one rung further per pair at most.
pub fn highest_rung(m: &Measurement, cfg: &LadderSettings) -> u32 {
    m.rungs
        .iter()
        .filter(|r| r.separation > cfg.bootstrap_longest && !r.usable())
        .map(|r| r.separation)
        .min()
        .unwrap_or(u32::MAX)
}

impl Ask {
    /// A pair with no flow to follow: its events within the ladder's
    /// bootstrap reach.
    ///
    /// ```
    /// use spiv_estimator::control::Ask;
    /// use spiv_estimator::ladder::LadderSettings;
    /// let cfg = LadderSettings::default();
    /// let a = Ask::cold(&cfg);
    /// assert!(!a.warm() && a.reach == cfg.bootstrap_reach);
    /// // On the wire: one message of the ask's head, no nodes.
    /// let m = a.messages(1, (64, 48), false).unwrap();
    /// assert_eq!(m.len(), 1);
    /// ```
    pub fn cold(cfg: &LadderSettings) -> Ask {
        Ask {
            flow: None,
            rungs: Vec::new(),
            reach: cfg.bootstrap_reach,
        }
    }

    /// What the pair after `m` is made with: its
    /// rung frames along `m`'s field when that field is usable, with its
    /// events too when `m` was measured from its events alone or by the
    /// dense ensemble; else its events alone. The rung frames are those of
    /// every separation of `cfg` longer than its bootstrap rungs up to the
    /// shortest at which `m`'s climb stopped ([`highest_rung`]): the ladder
    /// climbs no further than the first rung that fails, so a longer one
    /// would cross the wire unread.
    pub fn after(m: &Measurement, cfg: &LadderSettings) -> Ask {
        if !m.field.usable() {
            return Ask::cold(cfg);
        }
        let top = highest_rung(m, cfg);
        Ask {
            flow: Some(m.field.per_tick()),
            rungs: cfg
                .separations
                .iter()
                .copied()
                .filter(|&s| s > cfg.bootstrap_longest && s <= top)
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

    /// The ask as the wire carries it to a `width × height` sensor (stored
    /// rows bottom-up when `flip`), for the pairs from `from_pair` on: its
    /// messages ([`spiv_core::wire::ask`]), the flow in the core's fixed
    /// point on the field's grid (at most eight separations; none without
    /// a flow). Refused when the grid is larger than an ask carries.
    pub fn messages(
        &self,
        from_pair: u32,
        (width, height): (u16, u16),
        flip: bool,
    ) -> Result<Vec<Vec<u8>>, crate::Error> {
        let mut rungs = Rungs::events(u16::try_from(self.reach).unwrap_or(u16::MAX));
        let flow = match &self.flow {
            Some(f) if !self.rungs.is_empty() => WarpFlow::from_field(f, usize::from(height), flip),
            _ => WarpFlow::still(),
        };
        if !flow.is_still() {
            for s in self.rungs.iter().filter_map(|&s| u16::try_from(s).ok()) {
                if usize::from(rungs.count) == MAX_RUNGS {
                    break;
                }
                rungs.separations[usize::from(rungs.count)] = s;
                rungs.count += 1;
            }
        }
        let view = flow.view();
        let mut payload = vec![0u8; MAX_ASK_PAYLOAD];
        let mut wire = vec![0u8; MAX_ENCODED];
        let mut out = Vec::new();
        for (k, part) in ask_parts(&view).enumerate() {
            let len = encode_ask(from_pair, &rungs, &view, part, &mut payload)?;
            let header = Header {
                kind: Kind::Ask,
                frame_id: from_pair,
                ..control_header(k as u32, width, height)
            };
            let n = encode_message(&header, &payload[..len], &mut wire)?;
            out.push(wire[..n].to_vec());
        }
        if out.is_empty() {
            return Err(WireError::Payload.into());
        }
        Ok(out)
    }
}

/// An ask as the core holds it once the wire delivered it: its rungs and
/// reach, and the flow its rung frames follow in the core's fixed point
/// (stored order) — with the field the estimator sent it from, which the
/// host keeps (the ladder's start for the pairs made along it).
#[derive(Debug, Clone)]
pub struct Heard {
    /// The first pair the ask applies to.
    pub from_pair: u32,
    /// Separations (none without a flow) and the events' reach.
    pub rungs: Rungs,
    /// The flow the rung frames follow, as the wire carried it.
    pub flow: WarpFlow,
    /// The field it was sent from (`None` without a flow).
    pub start: Option<PerTick>,
}

impl Heard {
    /// What a core holds before any ask: events within the ladder's
    /// bootstrap reach ([`Ask::cold`]).
    ///
    /// ```
    /// use spiv_estimator::control::Heard;
    /// use spiv_estimator::ladder::LadderSettings;
    /// let cfg = LadderSettings::default();
    /// let h = Heard::cold(&cfg);
    /// assert!(h.flow.is_still() && h.start.is_none());
    /// assert_eq!(u32::from(h.rungs.reach), cfg.bootstrap_reach);
    /// assert_eq!(h.rungs.count, 0);
    /// ```
    pub fn cold(cfg: &LadderSettings) -> Heard {
        Heard {
            from_pair: 0,
            rungs: Rungs::events(u16::try_from(cfg.bootstrap_reach).unwrap_or(u16::MAX)),
            flow: WarpFlow::still(),
            start: None,
        }
    }

    /// `ask` through the wire at once (no loss): what a core hears of it,
    /// for a `width × height` sensor (bottom-up when `flip`).
    pub fn of(ask: &Ask, size: (u16, u16), flip: bool) -> Result<Heard, crate::Error> {
        let mut link = AskLink::new(Delivery::default(), &LadderSettings::default(), size, flip);
        link.send(0, ask.clone())?;
        Ok(link.ask_for(1).clone())
    }

    /// The ask as the sidecar's state reads it.
    pub fn asked(&self) -> Asked<'_> {
        Asked {
            from_pair: self.from_pair,
            rungs: self.rungs,
            flow: self.flow.view(),
        }
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
    /// Share of ask messages lost, 0–1.
    pub loss: f64,
    /// Share of ask messages with a byte corrupted on the way, 0–1 (the
    /// core's CRC check refuses them).
    pub corrupt: f64,
    /// Seed of the losses and corruptions.
    pub seed: u64,
}

/// The asks on their way to the core ([`Delivery`]): each sent as its
/// wire messages ([`Ask::messages`]), which arrive late, are lost or
/// corrupted as the delivery says, and are heard by the sidecar's own
/// ear ([`AskEar`]: the stream decoder (CRC), the payload's checks and the
/// parts put together in order). An ask whose parts did not all arrive
/// intact is not heard; the core keeps the last one it heard.
#[derive(Debug)]
pub struct AskLink {
    delivery: Delivery,
    rng: ChaCha8Rng,
    size: (u16, u16),
    flip: bool,
    /// Messages in flight: the pair they arrive for, their bytes.
    sent: VecDeque<(usize, Vec<u8>)>,
    /// The fields the asks in flight were sent from, by `from_pair`.
    starts: VecDeque<(u32, Option<PerTick>)>,
    /// The sidecar's ear.
    ear: AskEar,
    current: Heard,
    lost: usize,
}

impl AskLink {
    /// Nothing sent yet: the core makes its pairs [`Heard::cold`]; asks go
    /// to a `width × height` sensor (stored rows bottom-up when `flip`).
    pub fn new(delivery: Delivery, cfg: &LadderSettings, size: (u16, u16), flip: bool) -> AskLink {
        let reach = u16::try_from(cfg.bootstrap_reach).unwrap_or(u16::MAX);
        AskLink {
            delivery,
            rng: ChaCha8Rng::seed_from_u64(delivery.seed),
            size,
            flip,
            sent: VecDeque::new(),
            starts: VecDeque::new(),
            ear: AskEar::new(size, reach),
            current: Heard::cold(cfg),
            lost: 0,
        }
    }

    /// What the core makes pair `i` (counted from the loop's first) with:
    /// the newest ask heard by then.
    pub fn ask_for(&mut self, i: usize) -> &Heard {
        let mut newest = None;
        while self.sent.front().is_some_and(|(at, _)| *at <= i) {
            if let Some((_, m)) = self.sent.pop_front() {
                newest = self.ear.hear(&m).or(newest);
            }
        }
        if let Some(from_pair) = newest {
            self.heard(from_pair);
        }
        &self.current
    }

    /// The ear heard a new ask for the pairs from `from_pair` on: it is
    /// what the core makes them with, with the field it was sent from.
    fn heard(&mut self, from_pair: u32) {
        while self.starts.front().is_some_and(|(p, _)| *p < from_pair) {
            self.starts.pop_front();
        }
        let start = match self.starts.front() {
            Some((p, f)) if *p == from_pair => f.clone(),
            _ => None,
        };
        let asked = self.ear.asked();
        self.current = Heard {
            from_pair,
            rungs: asked.rungs,
            flow: WarpFlow::from_core(&asked.flow),
            start,
        };
    }

    /// Sends `ask`, measured after pair `i`: it applies from pair `i + 1`
    /// and arrives for pair `i + 1 + late`. Refused when the wire cannot
    /// carry it ([`Ask::messages`]).
    pub fn send(&mut self, i: usize, ask: Ask) -> Result<(), crate::Error> {
        let from = u32::try_from(i + 1).map_err(|_| WireError::Field)?;
        let messages = ask.messages(from, self.size, self.flip)?;
        let start = ask.flow.filter(|_| !ask.rungs.is_empty());
        self.starts.push_back((from, start));
        let (loss, corrupt) = (
            self.delivery.loss.clamp(0.0, 1.0),
            self.delivery.corrupt.clamp(0.0, 1.0),
        );
        for mut m in messages {
            if loss > 0.0 && self.rng.gen::<f64>() < loss {
                self.lost += 1;
                continue;
            }
            if corrupt > 0.0 && self.rng.gen::<f64>() < corrupt && m.len() > 1 {
                let k = self.rng.gen_range(0..m.len() - 1);
                m[k] ^= 1 << self.rng.gen_range(0..8);
            }
            self.sent.push_back((i + 1 + self.delivery.late, m));
        }
        Ok(())
    }

    /// Ask messages lost so far.
    pub fn lost(&self) -> usize {
        self.lost
    }

    /// Ask messages the core refused so far (corrupted, or parts of an ask
    /// that could not be put together).
    pub fn refused(&self) -> usize {
        self.ear.refused as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spiv_piv::{Field, Grid, State};

    const SIZE: (u16, u16) = (64, 48);

    fn marked(reach: u32) -> Ask {
        Ask {
            flow: None,
            rungs: Vec::new(),
            reach,
        }
    }

    fn link(delivery: Delivery, cfg: &LadderSettings) -> AskLink {
        AskLink::new(delivery, cfg, SIZE, false)
    }

    /// A measurement with a usable field whose climb went over `rungs`
    /// (separation, and whether the rung's field was usable).
    fn climbed(rungs: &[(u32, bool)]) -> Measurement {
        let grid = Grid::new(64, 48, 16, 8).unwrap();
        let mut field = Field::unmeasured(grid);
        field.state.fill(State::Valid);
        let n = grid.len();
        Measurement {
            field: crate::units::PerPair::new(field, crate::units::Ticks(10.0)),
            separation: ndarray::Array2::zeros((grid.ny, grid.nx)),
            rungs: rungs
                .iter()
                .map(|&(separation, ok)| crate::ladder::Rung {
                    separation,
                    counts: if ok { (n, 0, 0) } else { (0, 0, n) },
                    kept: 0,
                    ms: 0.0,
                })
                .collect(),
            frames: None,
            dense: None,
            confirmed: Some(true),
            ensemble: false,
        }
    }

    /// The next pair carries the rungs up to the first that failed, tried
    /// again, and every rung when none failed; the bootstrap rungs' own
    /// failures do not count.
    #[test]
    fn asks_stop_at_the_rung_that_failed() {
        let cfg = LadderSettings::default();
        let ask = |r: &[(u32, bool)]| Ask::after(&climbed(r), &cfg).rungs;
        let all: Vec<u32> = cfg
            .separations
            .iter()
            .copied()
            .filter(|&s| s > cfg.bootstrap_longest)
            .collect();
        assert_eq!(ask(&[(16, true), (32, true), (64, true), (128, true)]), all);
        assert_eq!(ask(&[(16, true), (32, false)]), vec![16, 32]);
        assert_eq!(ask(&[(16, false)]), vec![16]);
        // The events' climb: 8 failing is a bootstrap rung; 32 stops it.
        assert_eq!(ask(&[(4, true), (8, false), (16, true)]), all);
        assert_eq!(
            ask(&[(4, true), (8, true), (16, true), (32, false), (16, true)]),
            vec![16, 32]
        );
        // No usable field: events alone.
        let mut m = climbed(&[(16, true)]);
        m.field.state.fill(State::Invalid);
        assert!(!Ask::after(&m, &cfg).warm());
    }

    /// An ask sent after pair `i` makes pair `i + 1 + late` on; until
    /// then the core keeps the last one it has (cold at first).
    #[test]
    fn asks_arrive_late_by_whole_pairs() {
        let cfg = LadderSettings::default();
        let mut d = link(
            Delivery {
                late: 2,
                ..Delivery::default()
            },
            &cfg,
        );
        let mut seen = Vec::new();
        for i in 0..6 {
            seen.push(u32::from(d.ask_for(i).rungs.reach));
            d.send(i, marked(100 + i as u32)).unwrap();
        }
        let cold = cfg.bootstrap_reach;
        assert_eq!(seen, vec![cold, cold, cold, 100, 101, 102]);
        assert_eq!((d.lost(), d.refused()), (0, 0));
    }

    /// Lost or corrupted asks leave the core on the last one it heard; the
    /// shares follow the delivery's, and the same seed loses the same.
    #[test]
    fn lost_and_corrupted_asks_keep_the_last_one() {
        let cfg = LadderSettings::default();
        let run = |seed, loss, corrupt| {
            let mut d = link(
                Delivery {
                    late: 0,
                    loss,
                    corrupt,
                    seed,
                },
                &cfg,
            );
            let mut seen = Vec::new();
            for i in 0..400 {
                seen.push(d.ask_for(i).rungs.reach);
                d.send(i, marked(1000 + i as u32)).unwrap();
            }
            (seen, d.lost(), d.refused())
        };
        let (seen, lost, refused) = run(7, 0.25, 0.0);
        assert!((70..130).contains(&lost), "{lost} of 400 lost at 25 %");
        assert_eq!(refused, 0);
        // Each pair uses the newest ask heard, a stale one exactly where
        // the one before it was lost (the last ask sent is never used).
        let stale = seen.windows(2).filter(|w| w[1] == w[0]).count();
        assert!(stale == lost || stale + 1 == lost, "{stale} {lost}");
        assert!(seen.windows(2).all(|w| w[1] >= w[0]));
        assert_eq!(run(7, 0.25, 0.0), (seen, lost, refused));
        // Corrupted messages never apply: the CRC refuses them.
        let (seen, lost, refused) = run(8, 0.0, 0.2);
        assert_eq!(lost, 0);
        assert!(
            (50..110).contains(&refused),
            "{refused} of 400 refused at 20 %"
        );
        let stale = seen.windows(2).filter(|w| w[1] == w[0]).count();
        assert!(
            stale <= refused && stale + 1 >= refused.min(stale + 1),
            "{stale} {refused}"
        );
        assert!(seen.windows(2).all(|w| w[1] >= w[0]));
    }

    /// A field goes down the wire as the core's fixed-point flow on its
    /// grid, with the rungs; the host keeps the field as the start.
    #[test]
    fn a_field_is_heard_as_the_cores_flow() {
        let grid = Grid::new(usize::from(SIZE.0), usize::from(SIZE.1), 16, 8).unwrap();
        let mut f = Field::unmeasured(grid);
        for ((r, c), u) in f.u.indexed_iter_mut() {
            *u = 0.01 * (r as f64) + 0.002 * c as f64;
        }
        f.v.fill(-0.05);
        f.state.fill(State::Valid);
        let ask = Ask {
            flow: Some(PerTick(f.clone())),
            rungs: vec![16, 32, 64],
            reach: 0,
        };
        for flip in [false, true] {
            let heard = Heard::of(&ask, SIZE, flip).unwrap();
            let want = WarpFlow::from_field(&f, usize::from(SIZE.1), flip);
            assert_eq!(heard.flow.view().vx, want.view().vx);
            assert_eq!(heard.flow.view().ay, want.view().ay);
            assert_eq!(heard.flow.nodes(), want.nodes());
            assert_eq!(heard.rungs.separations(), &[16, 32, 64]);
            assert_eq!(heard.start.as_ref().map(|s| s.u.clone()), Some(f.u.clone()));
            // The pair at tick 100 holding ticks 40..200: its 64-tick rung does not fit.
            let (r, _) = spiv_core::rungs::pair_plan(40..200, 100, &heard.rungs, false, 32);
            assert_eq!(r.separations(), &[16, 32]);
        }
        // No flow: events only, whatever rungs were named.
        let cold = Heard::of(&Ask { flow: None, ..ask }, SIZE, false).unwrap();
        assert!(cold.flow.is_still() && cold.start.is_none());
        let (r, ev) =
            spiv_core::rungs::pair_plan(0..400, 100, &cold.rungs, cold.flow.is_still(), 32);
        assert_eq!((r.count, ev), (0, Some((68, 132))));
    }
}
