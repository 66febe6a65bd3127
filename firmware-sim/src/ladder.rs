//! The simulated sidecar's live loop of the time ladder: planes go through
//! the core's static-light model and event ring ([`PairMaker`]); each pair,
//! once the ring holds the ticks its longest rung needs, is made as the
//! last ask heard on the downlink says ([`AskEar`]) and sent up the link
//! as a pair head and its parts ([`spiv_core::rungs::send_pair`]).
//!
//! A pair with no ask before it carries its events within the cold reach
//! (the host's ladder starts from its short, uncompensated rungs); after
//! an ask with a flow, its rung frames warped along that flow. `spiv
//! flow` runs the same maker in process, so with every ask heard before
//! the next pair is made (`--control-wait`) the host measures exactly the
//! vectors `spiv flow` measures on the same recording.
//!
//! The driver loop: [`LadderFirmware::take`] each plane, then
//! [`LadderFirmware::step`] until it has nothing to do (a pair is due only
//! between planes, so a paced downlink waits for the host there), then
//! [`LadderFirmware::end`] and the same steps, then
//! [`LadderFirmware::finish`].

use std::collections::VecDeque;

use spiv_core::rungs::{lead, ring_depth, PairCost, BOOTSTRAP_REACH, LONGEST_RUNG};

use crate::firmware::Link;
use crate::Error;
use spiv_core::pairs::{AskEar, PairMaker, PairSender, LIGHT_TRAIN};

/// What the live loop makes and when.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LadderConfig {
    /// Ticks between the two frames of a pair the host reports (the unit
    /// of its field), 1..=65535.
    pub dt: u32,
    /// Ticks between pairs (≥ `dt`).
    pub every: u32,
    /// Tick of the first pair's first frame (its midpoint is `⌈dt/2⌉`
    /// later).
    pub first: u32,
    /// Pairs to send (`None`: until the planes end).
    pub pairs: Option<u32>,
    /// The longest rung the host asks for, ticks: the ring holds that
    /// many ticks on each side of a midpoint.
    pub longest: u16,
    /// Ticks on each side of the midpoint whose events a pair carries
    /// before any ask with a flow.
    pub cold_reach: u16,
}

impl LadderConfig {
    /// Pairs `dt` ticks apart, one every `4·dt` ticks, the first's
    /// midpoint at tick [`BOOTSTRAP_REACH`] (the cold reach of events
    /// before it); rungs up to [`LONGEST_RUNG`].
    pub fn new(dt: u32) -> LadderConfig {
        LadderConfig {
            dt,
            every: dt.saturating_mul(4),
            first: u32::from(BOOTSTRAP_REACH).saturating_sub(dt.div_ceil(2)),
            pairs: None,
            longest: LONGEST_RUNG,
            cold_reach: BOOTSTRAP_REACH,
        }
    }

    /// The midpoint of pair `i`, ticks (`None` past 32 bits).
    pub fn mid(&self, i: u32) -> Option<u32> {
        i.checked_mul(self.every)?
            .checked_add(self.first)?
            .checked_add(self.dt.div_ceil(2))
    }

    /// Checks the numbers: `dt` 1..=65535, `every ≥ dt`, rungs 2..=255.
    pub fn check(&self) -> Result<(), Error> {
        if !(1..=u32::from(u16::MAX)).contains(&self.dt) {
            return Err(Error::Schedule("dt must be 1..=65535 ticks"));
        }
        if self.every < self.dt {
            return Err(Error::Schedule("pairs every fewer ticks than dt"));
        }
        if !(2..=255).contains(&self.longest) {
            return Err(Error::Schedule("the longest rung must be 2..=255 ticks"));
        }
        Ok(())
    }
}

/// What the loop sent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LadderCounts {
    /// Planes taken.
    pub planes: u32,
    /// Pairs sent.
    pub pairs: u32,
    /// Of those, pairs with rung frames.
    pub warm: u32,
    /// Bytes of every pair, by what they carry.
    pub cost: PairCost,
    /// Messages sent.
    pub messages: u64,
    /// Events the ring could not hold, and ticks it dropped for room.
    pub lost: (u32, u32),
}

/// The live loop with its memory and its link.
#[derive(Debug)]
pub struct LadderFirmware<L: Link> {
    cfg: LadderConfig,
    maker: PairMaker,
    out: PairSender,
    ear: AskEar,
    link: L,
    /// Planes held until the light model is trained, then planes waiting
    /// to go into the ring.
    queue: VecDeque<Vec<u8>>,
    trained: bool,
    ended: bool,
    next: u32,
    counts: LadderCounts,
}

/// The core's sender writes through this.
struct CoreLink<'a, L: Link>(&'a mut L);

impl<L: Link> spiv_core::wire::sender::Link for CoreLink<'_, L> {
    type Error = std::io::Error;
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.0.send(message)
    }
}

impl<L: Link> LadderFirmware<L> {
    /// A loop for a `width × height` sensor whose first plane is tick 0,
    /// sending to `link`.
    pub fn new((width, height): (u16, u16), cfg: LadderConfig, link: L) -> Result<Self, Error> {
        cfg.check()?;
        let depth = ring_depth(cfg.longest, cfg.cold_reach) as usize;
        Ok(LadderFirmware {
            maker: PairMaker::new((width, height), 0, depth)?,
            out: PairSender::new((width, height))?,
            ear: AskEar::new((width, height), cfg.cold_reach),
            cfg,
            link,
            queue: VecDeque::new(),
            trained: false,
            ended: false,
            next: 0,
            counts: LadderCounts::default(),
        })
    }

    /// Takes bytes from the downlink (ask messages from the host, any
    /// chunking).
    pub fn hear(&mut self, bytes: &[u8]) {
        self.ear.hear(bytes);
    }

    /// Asks heard whole, and parts or asks refused.
    pub fn heard(&self) -> (u64, u64) {
        (self.ear.heard, self.ear.refused)
    }

    /// Takes the next plane (stored row order). The first [`LIGHT_TRAIN`]
    /// planes after the first are held: the static-light model is trained
    /// on them played backwards (as a sidecar that ran before the stream
    /// would have seen the light), then every plane goes into the ring in
    /// order ([`LadderFirmware::step`]).
    pub fn take(&mut self, plane: &[u8]) -> Result<(), Error> {
        self.counts.planes = self.counts.planes.saturating_add(1);
        self.queue.push_back(plane.to_vec());
        if !self.trained && self.queue.len() > LIGHT_TRAIN {
            self.train()?;
        }
        Ok(())
    }

    fn train(&mut self) -> Result<(), Error> {
        let planes: Vec<&[u8]> = self.queue.iter().skip(1).map(Vec::as_slice).collect();
        self.maker.train(&planes, LIGHT_TRAIN)?;
        self.trained = true;
        Ok(())
    }

    /// The planes ended: the pairs they hold are made with what the ring
    /// holds.
    pub fn end(&mut self) -> Result<(), Error> {
        if !self.trained {
            self.train()?;
        }
        self.ended = true;
        Ok(())
    }

    /// The pair the next [`LadderFirmware::step`] sends, if one is due:
    /// the ring holds its ticks (or the planes ended) and it is scheduled.
    pub fn pair_due(&self) -> Option<u32> {
        let i = self.next;
        if self.cfg.pairs.is_some_and(|n| i >= n) || !self.trained {
            return None;
        }
        let mid = self.cfg.mid(i)?;
        let end = self.maker.ticks().end;
        let ready = u64::from(mid) + u64::from(lead(self.cfg.longest, self.cfg.cold_reach));
        let fits = u64::from(mid) - u64::from(self.cfg.dt.div_ceil(2)) + u64::from(self.cfg.dt)
            < u64::from(end);
        if u64::from(end) >= ready || (self.ended && self.queue.is_empty() && fits) {
            Some(i)
        } else {
            None
        }
    }

    /// Does one thing: sends the pair due, or puts the next waiting plane
    /// into the ring. `false` when there is nothing to do until the next
    /// plane (or ever, once ended).
    pub fn step(&mut self) -> Result<bool, Error> {
        if let Some(i) = self.pair_due() {
            self.send_pair(i)?;
            return Ok(true);
        }
        if !self.trained {
            return Ok(false);
        }
        match self.queue.pop_front() {
            Some(p) => {
                self.maker.push(&p)?;
                Ok(true)
            }
            None => Ok(false),
        }
    }

    fn send_pair(&mut self, i: u32) -> Result<(), Error> {
        let mid = self.cfg.mid(i).ok_or(spiv_core::Error::TickOverflow)?;
        let ask = self.ear.asked();
        let dt = u16::try_from(self.cfg.dt).unwrap_or(u16::MAX);
        let cost = self.maker.send(
            (i, mid, dt),
            &ask,
            self.cfg.cold_reach,
            &mut self.out,
            &mut CoreLink(&mut self.link),
        )?;
        let c = &mut self.counts;
        c.pairs += 1;
        c.warm += u32::from(cost.rung_frames > 0);
        c.cost.head += cost.head;
        c.cost.rung_frames += cost.rung_frames;
        c.cost.events += cost.events;
        c.cost.rates += cost.rates;
        self.next += 1;
        Ok(())
    }

    /// True once every scheduled pair was sent.
    pub fn done(&self) -> bool {
        self.cfg.pairs.is_some_and(|n| self.next >= n)
    }

    /// Pushes out what the link holds.
    pub fn flush(&mut self) -> Result<(), Error> {
        Ok(self.link.flush()?)
    }

    /// The counts so far.
    pub fn counts(&self) -> LadderCounts {
        LadderCounts {
            messages: u64::from(self.out.sent().messages),
            lost: self.maker.lost(),
            ..self.counts
        }
    }

    /// Flushes the link; the counts.
    pub fn finish(&mut self) -> Result<LadderCounts, Error> {
        self.link.flush()?;
        Ok(self.counts())
    }

    /// The link (to take a memory link back).
    pub fn into_link(self) -> L {
        self.link
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{SceneKind, SceneParams};
    use crate::simulation::{simulate_planes, Request};
    use spiv_core::warp::Flow;
    use spiv_core::wire::ask::{ask_parts, encode_ask, MAX_ASK_PAYLOAD};
    use spiv_core::wire::control::control_header;
    use spiv_core::wire::pair::{PairHead, NO_ASK};
    use spiv_core::wire::{encode_message, Decoder, Header, Kind, MAX_ENCODED};

    const W: u16 = 64;
    const H: u16 = 48;

    fn planes(ticks: u32) -> Vec<u8> {
        let p = SceneParams {
            width: W,
            height: H,
            ..SceneParams::new(SceneKind::Uniform)
        };
        let mut req = Request::new(p, 5);
        req.ticks = Some(ticks);
        simulate_planes(&req).expect("simulates").0
    }

    /// Every pair head in `bytes`.
    fn heads(bytes: &[u8]) -> Vec<PairHead> {
        let mut rx = vec![0u8; MAX_ENCODED];
        let mut dec = Decoder::new(&mut rx);
        let mut input = bytes;
        let mut out = Vec::new();
        while let Some(m) = dec.feed(&mut input) {
            let m = m.expect("a clean stream");
            if m.header.kind == Kind::PairHead {
                out.push(PairHead::parse(m.payload).expect("a head"));
            }
        }
        out
    }

    /// The messages of an ask for the pairs from `from_pair` on: rungs of
    /// 16 and 32 ticks along a uniform flow of 0.25 px per tick across.
    fn ask(from_pair: u32) -> Vec<u8> {
        let n = 4 * 3;
        let vx = vec![1024i16; n];
        let zero = vec![0i16; n];
        let flow = Flow {
            nx: 4,
            ny: 3,
            x0: 8 * 16,
            y0: 8 * 16,
            pitch: 16 * 16,
            vx: &vx,
            vy: &zero,
            ax: &zero,
            ay: &zero,
        };
        let mut rungs = spiv_core::rungs::Rungs::events(0);
        rungs.separations[..2].copy_from_slice(&[16, 32]);
        rungs.count = 2;
        let mut payload = vec![0u8; MAX_ASK_PAYLOAD];
        let mut wire = vec![0u8; MAX_ENCODED];
        let mut out = Vec::new();
        for (k, part) in ask_parts(&flow).enumerate() {
            let len = encode_ask(from_pair, &rungs, &flow, part, &mut payload).unwrap();
            let header = Header {
                kind: Kind::Ask,
                frame_id: from_pair,
                ..control_header(k as u32, W, H)
            };
            let m = encode_message(&header, &payload[..len], &mut wire).unwrap();
            out.extend_from_slice(&wire[..m]);
        }
        out
    }

    /// Runs the loop over `data`, hearing `downlink` (a pair number and
    /// bytes) just before that pair is made.
    fn run(
        cfg: LadderConfig,
        data: &[u8],
        downlink: &[(u32, Vec<u8>)],
    ) -> (Vec<u8>, LadderCounts, (u64, u64)) {
        let mut fw = LadderFirmware::new((W, H), cfg, Vec::new()).unwrap();
        let step = |fw: &mut LadderFirmware<Vec<u8>>| loop {
            if let Some(i) = fw.pair_due() {
                for (_, b) in downlink.iter().filter(|(at, _)| *at == i) {
                    // In pieces of 7 bytes: the ear keeps what it has.
                    for chunk in b.chunks(7) {
                        fw.hear(chunk);
                    }
                }
            }
            if fw.done() || !fw.step().unwrap() {
                break;
            }
        };
        for p in data.chunks_exact(usize::from(W) * usize::from(H) / 8) {
            fw.take(p).unwrap();
            step(&mut fw);
        }
        fw.end().unwrap();
        step(&mut fw);
        let counts = fw.finish().unwrap();
        let heard = fw.heard();
        (fw.into_link(), counts, heard)
    }

    /// Without an ask every scheduled pair goes up with its events within
    /// the cold reach, numbered in order, at its midpoint, with its `dt`.
    #[test]
    fn without_asks_every_pair_carries_its_events() {
        let data = planes(400);
        let cfg = LadderConfig::new(10);
        let (bytes, counts, heard) = run(cfg, &data, &[]);
        assert_eq!(heard, (0, 0));
        let heads = heads(&bytes);
        // Frame A at 27 + 40·i while A + dt < 400.
        assert_eq!(heads.len(), 10);
        assert_eq!((counts.pairs, counts.warm, counts.planes), (10, 0, 400));
        for (i, h) in heads.iter().enumerate() {
            assert_eq!((h.pair, h.mid, h.dt), (i as u32, 32 + 40 * i as u32, 10));
            assert_eq!((h.count, h.from_pair), (0, NO_ASK));
            let reach = u32::from(BOOTSTRAP_REACH);
            assert_eq!(h.ev_first, h.mid - reach, "pair {i}");
            let end = (h.mid + reach).min(400);
            assert_eq!(u32::from(h.ev_ticks), end - h.ev_first, "pair {i}");
        }
        assert!(counts.cost.events > 0 && counts.cost.rung_frames == 0);
    }

    /// An ask heard in pieces makes the pairs after it with rung frames
    /// along its flow (those the ring holds); an older ask heard later is
    /// refused and changes nothing.
    #[test]
    fn an_ask_heard_in_pieces_warms_the_next_pairs_and_an_older_one_is_refused() {
        let data = planes(500);
        let cfg = LadderConfig {
            pairs: Some(6),
            ..LadderConfig::new(10)
        };
        let downlink = [(2, ask(2)), (4, ask(1))];
        let (bytes, counts, heard) = run(cfg, &data, &downlink);
        assert_eq!(heard, (1, 1), "the newer ask heard, the older refused");
        let heads = heads(&bytes);
        assert_eq!(heads.len(), 6);
        for h in &heads[..2] {
            assert_eq!((h.count, h.from_pair), (0, NO_ASK));
        }
        for h in &heads[2..] {
            assert_eq!(
                (h.separations(), h.from_pair),
                (&[16u16, 32][..], 2),
                "{h:?}"
            );
            assert_eq!(h.ev_ticks, 0, "the ask's reach is 0");
        }
        assert_eq!(counts.warm, 4);
    }
}
