//! A pair of the live loop on the wire, both ways: sent as the sidecar
//! sends it ([`spiv_core::rungs::send_pair`]: its head,
//! [`spiv_core::wire::pair::PairHead`], and its parts as lossless
//! `Context` tiles through one stream's [`PairSender`], kept in memory by
//! [`Uplink`]), and read back bit-exact from the messages as the core's
//! pair ([`PairReader`] → [`CorePair`]: the frame assembler's CRC-checked
//! frames, put together by the head). What each part costs is counted as
//! it leaves (headers, CRCs and COBS framing included):
//!
//! - each rung frame as 16-bit levels above its smallest sample, whose
//!   value the head carries;
//! - each tick of events as a stored-order plane of levels 0 (none),
//!   1 (−1) and 2 (+1);
//! - with the events, the static rate of every stored pixel (16-bit).

use spiv_core::error::LinkError;
use spiv_core::pairs::{Asked, CoreEvents, CorePair, PairMaker, PairSender};
use spiv_core::rungs::PairCost;
use spiv_core::warp::SCALE;
use spiv_core::wire::pair::PairHead;
use spiv_core::wire::sender::Link;
use spiv_core::wire::{Kind, Message};

use crate::receive::assemble::{Assembler, FrameLimit, ReceivedFrame};
use crate::Error;

/// Bytes of one pair on the wire, by what they carry: the core's
/// [`PairCost`], for the host's reports (serialisable).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct PairBytes {
    /// The head.
    pub head: u64,
    /// The rung frames.
    pub rung_frames: u64,
    /// The events, tick by tick.
    pub events: u64,
    /// The static rates sent with the events.
    pub rates: u64,
}

impl From<PairCost> for PairBytes {
    fn from(c: PairCost) -> Self {
        PairBytes {
            head: c.head,
            rung_frames: c.rung_frames,
            events: c.events,
            rates: c.rates,
        }
    }
}

impl PairBytes {
    /// Every byte of the pair.
    ///
    /// ```
    /// use spiv_host::estimator::uplink::PairBytes;
    /// let b = PairBytes { head: 120, rung_frames: 9000, events: 0, rates: 0 };
    /// assert_eq!(b.total(), 9120);
    /// ```
    pub fn total(&self) -> u64 {
        self.head + self.rung_frames + self.events + self.rates
    }
}

/// A link that keeps every message.
#[derive(Debug, Default)]
struct Keep {
    messages: Vec<Vec<u8>>,
}

impl Link for Keep {
    type Error = std::convert::Infallible;
    fn send(&mut self, message: &[u8]) -> Result<(), Self::Error> {
        self.messages.push(message.to_vec());
        Ok(())
    }
}

fn core(e: LinkError<std::convert::Infallible>) -> spiv_core::Error {
    match e {
        LinkError::Core(c) => c,
        LinkError::Link(never) => match never {},
    }
}

/// One stream of live-loop pairs out of a `width × height` sensor, kept
/// in memory: the sidecar's sender ([`PairSender`]).
#[derive(Debug)]
pub struct Uplink {
    out: PairSender,
}

impl Uplink {
    /// A stream for a sensor of `width × height` stored pixels.
    pub fn new(size: (u16, u16)) -> Result<Uplink, Error> {
        Ok(Uplink {
            out: PairSender::new(size)?,
        })
    }

    /// Sends the pair `maker` makes at `mid` as `ask` asks (numbered
    /// `pair`, reported over `dt` ticks; [`PairMaker::send`]): its
    /// messages, in order, and what they cost.
    pub fn send(
        &mut self,
        maker: &mut PairMaker,
        (pair, mid, dt): (u32, u32, u16),
        ask: &Asked<'_>,
        cold_reach: u16,
    ) -> Result<(Vec<Vec<u8>>, PairBytes), Error> {
        let mut link = Keep::default();
        let cost = maker
            .send((pair, mid, dt), ask, cold_reach, &mut self.out, &mut link)
            .map_err(core)?;
        Ok((link.messages, cost.into()))
    }
}

/// Live-loop pairs back from the messages of one stream: each pair once
/// its head and every part arrived bit-exact (the frame assembler's CRC);
/// a pair with a part missing is dropped when the next head comes, and
/// counted.
#[derive(Debug)]
pub struct PairReader {
    frames: Assembler,
    head: Option<(PairHead, u16, u16)>,
    parts: Vec<Option<ReceivedFrame>>,
    /// Pairs delivered.
    pub pairs: u64,
    /// Pairs dropped with a part missing.
    pub incomplete: u64,
}

impl PairReader {
    /// A reader that takes frames up to `limit`.
    pub fn new(limit: FrameLimit) -> PairReader {
        PairReader {
            frames: Assembler::new(limit),
            head: None,
            parts: Vec::new(),
            pairs: 0,
            incomplete: 0,
        }
    }

    /// What its frame assembler counted.
    pub fn stats(&self) -> crate::receive::assemble::AssemblyStats {
        self.frames.stats()
    }

    /// The stream ended: a pair still waiting for parts is incomplete, and
    /// frames still partial are lost.
    pub fn finish(&mut self) {
        if self.head.take().is_some() {
            self.incomplete += 1;
        }
        self.frames.finish();
    }

    /// Takes one message; returns a pair (its head and the core's pair)
    /// when the message completes one.
    pub fn push(&mut self, m: &Message<'_>) -> Option<(PairHead, CorePair)> {
        if m.header.kind == Kind::PairHead {
            let h = PairHead::parse(m.payload).ok()?;
            if self.head.is_some() {
                self.incomplete += 1;
            }
            self.head = Some((h, m.header.width, m.header.height));
            self.parts = vec![None; usize::from(h.parts())];
            return self.complete();
        }
        let f = self.frames.push(m)?;
        let (h, _, _) = self.head.as_ref()?;
        if f.end.pair == h.pair {
            if let Some(slot) = self.parts.get_mut(usize::from(f.end.member)) {
                *slot = Some(f);
            }
        }
        self.complete()
    }

    /// The pending pair, if every part is in.
    fn complete(&mut self) -> Option<(PairHead, CorePair)> {
        if self.parts.iter().any(Option::is_none) {
            return None;
        }
        let (h, w, hh) = self.head.take()?;
        let parts: Vec<ReceivedFrame> = std::mem::take(&mut self.parts)
            .into_iter()
            .flatten()
            .collect();
        let px = usize::from(w) * usize::from(hh);
        if parts.iter().any(|f| f.data.len() != px) {
            self.incomplete += 1;
            return None;
        }
        let count = usize::from(h.count);
        let rungs = (0..count)
            .map(|k| {
                let frame = |j: usize| -> Vec<i16> {
                    let off = i32::from(h.offsets[2 * k + j]);
                    parts[2 * k + j]
                        .data
                        .iter()
                        .map(|&l| {
                            (i32::from(l) * i32::from(SCALE) + off)
                                .clamp(i32::from(i16::MIN), i32::from(i16::MAX))
                                as i16
                        })
                        .collect()
                };
                (h.separations[k], [frame(0), frame(1)])
            })
            .collect();
        let events = (h.ev_ticks > 0).then(|| {
            let planes = &parts[2 * count..2 * count + usize::from(h.ev_ticks)];
            CoreEvents {
                first: h.ev_first,
                ticks: planes
                    .iter()
                    .map(|f| {
                        f.data
                            .iter()
                            .enumerate()
                            .filter(|(_, &l)| l != 0)
                            .map(|(i, &l)| (i as u32, if l == 2 { 1 } else { -1 }))
                            .collect()
                    })
                    .collect(),
                rates: parts[2 * count + usize::from(h.ev_ticks)].data.clone(),
            }
        });
        self.pairs += 1;
        Some((
            h,
            CorePair {
                size: (w, hh),
                mid: h.mid,
                from_pair: h.from_pair,
                rungs,
                events,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimator::control::{Ask, Heard};
    use crate::piv::{Field, Grid, State};
    use spiv_core::wire::{Decoder, MAX_ENCODED};
    use spiv_firmware_sim::scene::{SceneKind, SceneParams};
    use spiv_firmware_sim::simulation::{simulate_planes, Request};

    const W: u16 = 64;
    const H: u16 = 48;

    /// A maker that took 300 planes of a uniform flow with glare.
    fn maker() -> PairMaker {
        let p = SceneParams {
            width: W,
            height: H,
            glare_sigma: 10.0,
            ..SceneParams::new(SceneKind::Uniform)
        };
        let mut req = Request::new(p, 4);
        req.ticks = Some(300);
        let (data, _) = simulate_planes(&req).expect("simulates");
        let mut m = PairMaker::new((W, H), 0, 301).unwrap();
        for plane in data.chunks_exact(usize::from(W) * usize::from(H) / 8) {
            m.push(plane).unwrap();
        }
        m
    }

    /// An ask with rung frames along a uniform flow, as the core hears it.
    fn warm() -> Heard {
        let grid = Grid::new(usize::from(W), usize::from(H), 16, 8).unwrap();
        let mut f = Field::unmeasured(grid);
        f.u.fill(0.3);
        f.v.fill(-0.1);
        f.state.fill(State::Valid);
        let ask = Ask {
            flow: Some(spiv_estimator::units::PerTick(f)),
            rungs: vec![16, 32, 64],
            reach: 20,
        };
        Heard::of(&ask, (W, H), false).unwrap()
    }

    /// Every pair `reader` reads from `messages`.
    fn read(reader: &mut PairReader, messages: &[Vec<u8>]) -> Vec<(u32, CorePair)> {
        let mut rx = vec![0u8; MAX_ENCODED];
        let mut dec = Decoder::new(&mut rx);
        let mut out = Vec::new();
        for m in messages {
            let mut input = m.as_slice();
            while let Some(r) = dec.feed(&mut input) {
                if let Ok(msg) = r {
                    out.extend(reader.push(&msg).map(|(h, p)| (h.pair, p)));
                }
            }
        }
        out
    }

    /// What the core sends up the wire is read back as exactly the pair
    /// the host makes in process, pair after pair of one stream; the
    /// bytes counted are the bytes sent.
    #[test]
    fn the_wire_gives_back_the_pair_made_in_process() {
        let mut m = maker();
        let mut up = Uplink::new((W, H)).unwrap();
        let mut reader = PairReader::new(FrameLimit::default());
        let cold = Heard::cold(&crate::estimator::ladder::LadderSettings::default());
        for (k, (mid, ask)) in [(150, warm()), (160, cold), (200, warm())]
            .into_iter()
            .enumerate()
        {
            let want = m.make(mid, &ask.asked(), 24).unwrap();
            let (messages, bytes) = up
                .send(&mut m, (k as u32, mid, 10), &ask.asked(), 24)
                .unwrap();
            let sent: u64 = messages.iter().map(|b| b.len() as u64).sum();
            assert_eq!(bytes.total(), sent);
            assert!(bytes.head > 0);
            assert_eq!(bytes.rung_frames > 0, !want.rungs.is_empty());
            assert_eq!(bytes.events > 0, want.events.is_some());
            assert_eq!(read(&mut reader, &messages), vec![(k as u32, want)]);
        }
        assert_eq!((reader.pairs, reader.incomplete), (3, 0));
    }

    /// A damaged part loses its pair, never the next one, and the loss is
    /// counted.
    #[test]
    fn a_damaged_part_loses_its_pair_only() {
        let mut m = maker();
        let mut up = Uplink::new((W, H)).unwrap();
        let mut reader = PairReader::new(FrameLimit::default());
        let ask = warm();
        let (mut first, _) = up.send(&mut m, (0, 150, 10), &ask.asked(), 24).unwrap();
        let k = first.len() / 2;
        let n = first[k].len();
        first[k][n / 2] ^= 0x10;
        assert!(read(&mut reader, &first).is_empty());
        let (second, _) = up.send(&mut m, (1, 200, 10), &ask.asked(), 24).unwrap();
        let want = m.make(200, &ask.asked(), 24).unwrap();
        assert_eq!(read(&mut reader, &second), vec![(1, want)]);
        assert_eq!(reader.incomplete, 1);
    }
}
