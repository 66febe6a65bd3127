//! The live loop's sidecar state over owned buffers: the static-light model
//! ([`crate::light`]) and event ring ([`crate::rungs`]) a stream of
//! planes goes through ([`PairMaker`]), the ask the host sent last as the
//! sidecar heard it ([`AskEar`]), and each pair made as that ask says —
//! in memory ([`CorePair`]) or sent up a wire ([`PairSender`]).
//!
//! `spiv flow` runs this in process (a sidecar without a wire) and the
//! simulated sidecar (`spiv_firmware_sim::ladder`) runs it between planes, so the host
//! measures the same frames either way.

use crate::error::LinkError;
use std::vec;
use std::vec::Vec;

use crate::buffers::{FlowBuf, LightBuf};
use crate::light::{Event, Light, LightClock};
use crate::plane::PlaneView;
use crate::rungs::{
    pair_plan, rung_frames, send_pair, EventRing, PairCost, PairPlan, PairScratch, RingCursor,
    Rungs,
};
use crate::warp::Flow;
use crate::wire::ask::{AskAssembly, AskProgress, AskView, Part, MAX_FLOW_NODES};
use crate::wire::codec::Lossy;
use crate::wire::pair::NO_ASK;
use crate::wire::sender::{tile_rows, Link, SendBuffers, Sender};
use crate::wire::{Decoder, DecoderState, Kind, WireError, MAX_ENCODED, MAX_PAYLOAD};
use crate::Error;

/// Pixel-ticks of the ring's depth per event it holds: a quarter of an
/// event per pixel and tick on average (the scenes of `spiv bench flows`
/// make 0.02–0.05); past that the ring drops its oldest ticks, and the
/// rungs that reach them are not made.
pub const RING_PIXEL_TICKS_PER_EVENT: usize = 4;

/// Planes the static-light model is trained on before the first plane of
/// a stream that starts with its recording ([`PairMaker::train`]).
pub const LIGHT_TRAIN: usize = 512;

/// What the pairs from `from_pair` on are made with: the rungs and reach
/// of the last ask heard, and the flow its rung frames follow.
#[derive(Debug, Clone, Copy)]
pub struct Asked<'f> {
    /// The first pair the ask applies to (0 before any ask).
    pub from_pair: u32,
    /// Separations (none without a flow) and the events' reach.
    pub rungs: Rungs,
    /// The flow the rung frames follow.
    pub flow: Flow<'f>,
}

/// The sidecar's state over a stream of planes, owned.
#[derive(Debug)]
pub struct PairMaker {
    width: u16,
    height: u16,
    light: LightBuf,
    clock: LightClock,
    entries: Vec<u32>,
    starts: Vec<u32>,
    cursor: RingCursor,
    frames: Vec<i16>,
}

impl PairMaker {
    /// A maker for planes of `width × height` stored pixels, the first
    /// plane tick `first`, its ring `depth` ticks deep
    /// ([`crate::rungs::ring_depth`]).
    pub fn new((width, height): (u16, u16), first: u32, depth: usize) -> Result<PairMaker, Error> {
        let px = usize::from(width) * usize::from(height);
        if px as u64 >= u64::from(crate::rungs::MAX_PIXELS) {
            return Err(Error::BadDimensions);
        }
        let mut light = LightBuf::new(px);
        let clock = Light::new(width, height, first, light.state())?.clock();
        let depth = depth.max(1);
        let mut entries = vec![0u32; (depth * px / RING_PIXEL_TICKS_PER_EVENT).max(1)];
        let mut starts = vec![0u32; depth + 1];
        let cursor = EventRing::new(&mut entries, &mut starts, first)?.cursor();
        Ok(PairMaker {
            width,
            height,
            light,
            clock,
            entries,
            starts,
            cursor,
            frames: Vec::new(),
        })
    }

    /// Stored width and height, px.
    pub fn size(&self) -> (u16, u16) {
        (self.width, self.height)
    }

    /// Trains the static-light model, reporting no event, on `len` ticks
    /// just before the stream's first: `planes` (the planes after the
    /// first, in recording order) played backwards, and back and forth
    /// again while `len` asks for more — the recording's start mirrored
    /// in time stands in for the light a sidecar that ran before the
    /// recording would have seen, and a mirror joins its planes without a
    /// jump. A pixel that a particle lights steadily through the planes is
    /// trained on its surroundings' background instead
    /// ([`crate::training`]): the sidecar would have seen the particle
    /// arrive.
    pub fn train(&mut self, planes: &[&[u8]], len: usize) -> Result<(), Error> {
        let n = planes.len();
        if n == 0 || len == 0 {
            return Ok(());
        }
        let owned = crate::training::background_planes(planes, self.width, self.height);
        let replaced: Vec<&[u8]>;
        let planes = match &owned {
            Some(o) => {
                replaced = o.iter().map(Vec::as_slice).collect();
                &replaced[..]
            }
            None => planes,
        };
        let start = LightClock {
            next: self.clock.next.wrapping_sub(len as u32),
            ..self.clock
        };
        let mut light = Light::resume(self.width, self.height, start, self.light.state())?;
        // Tick −k (k = 1 the last before the stream) plays plane k of a
        // triangle wave over the planes: 1, 2, …, n, n − 1, …, 1, 2, …
        let at = |k: usize| -> usize {
            if n == 1 {
                return 0;
            }
            let m = (k - 1) % (2 * (n - 1));
            if m < n {
                m
            } else {
                2 * (n - 1) - m
            }
        };
        for k in (1..=len).rev() {
            light.train(&PlaneView::new(planes[at(k)], self.width, self.height)?)?;
        }
        self.clock = light.clock();
        Ok(())
    }

    /// Takes the next plane.
    pub fn push(&mut self, plane: &[u8]) -> Result<(), Error> {
        let view = PlaneView::new(plane, self.width, self.height)?;
        let mut light = Light::resume(self.width, self.height, self.clock, self.light.state())?;
        let mut ring = EventRing::resume(&mut self.entries, &mut self.starts, self.cursor)?;
        ring.push(&mut light, &view)?;
        self.clock = light.clock();
        self.cursor = ring.cursor();
        Ok(())
    }

    /// The ticks the ring holds.
    pub fn ticks(&self) -> std::ops::Range<u32> {
        self.cursor.first..self.cursor.next
    }

    /// Events the ring could not hold, and ticks it dropped to make room.
    pub fn lost(&self) -> (u32, u32) {
        (self.cursor.lost, self.cursor.evicted)
    }

    /// The rungs and events the pair at `mid` carries as `ask` asks
    /// ([`pair_plan`]; `cold_reach` the events' reach when no rung frame
    /// is made).
    pub fn plan(&self, mid: u32, ask: &Asked<'_>, cold_reach: u16) -> (Rungs, Option<(u32, u32)>) {
        pair_plan(
            self.ticks(),
            mid,
            &ask.rungs,
            ask.flow.is_still(),
            cold_reach,
        )
    }

    /// What the pair whose midpoint is tick `mid` carries, as `ask` asks,
    /// in the core's terms ([`CorePair`]): its rung frames warped along
    /// the ask's flow (the separations the ticks held reach) and its
    /// events within the ask's reach — or within `cold_reach` when no rung
    /// frame is made.
    pub fn make(&mut self, mid: u32, ask: &Asked<'_>, cold_reach: u16) -> Result<CorePair, Error> {
        let px = usize::from(self.width) * usize::from(self.height);
        let (rungs, events) = self.plan(mid, ask, cold_reach);
        let light = Light::resume(self.width, self.height, self.clock, self.light.state())?;
        let ring = EventRing::resume(&mut self.entries, &mut self.starts, self.cursor)?;
        let mut pair = CorePair {
            size: (self.width, self.height),
            mid,
            from_pair: NO_ASK,
            rungs: Vec::new(),
            events: None,
        };
        if rungs.count > 0 {
            self.frames.resize(2 * usize::from(rungs.count) * px, 0);
            rung_frames(&ring, &light, &ask.flow, mid, &rungs, &mut self.frames)?;
            let frame = |k: usize| self.frames[k * px..(k + 1) * px].to_vec();
            pair.rungs = rungs
                .separations()
                .iter()
                .enumerate()
                .map(|(i, &s)| (s, [frame(2 * i), frame(2 * i + 1)]))
                .collect();
            pair.from_pair = ask.from_pair;
        }
        pair.events = events.map(|span| CoreEvents::from_ring(&ring, &light, span));
        Ok(pair)
    }

    /// Sends the pair [`PairMaker::make`] makes, numbered `pair` and
    /// reported over `dt` ticks, through `out`'s stream into `link`
    /// ([`crate::rungs::send_pair`]): what it cost.
    pub fn send<L: Link>(
        &mut self,
        (pair, mid, dt): (u32, u32, u16),
        ask: &Asked<'_>,
        cold_reach: u16,
        out: &mut PairSender,
        link: &mut L,
    ) -> Result<PairCost, LinkError<L::Error>> {
        let px = usize::from(self.width) * usize::from(self.height);
        let (rungs, events) = self.plan(mid, ask, cold_reach);
        let light = Light::resume(self.width, self.height, self.clock, self.light.state())
            .map_err(|_| LinkError::from(WireError::Payload))?;
        let ring = EventRing::resume(&mut self.entries, &mut self.starts, self.cursor)
            .map_err(|_| LinkError::from(WireError::Payload))?;
        let plan = PairPlan {
            pair,
            mid,
            from_pair: if rungs.count > 0 {
                ask.from_pair
            } else {
                NO_ASK
            },
            rungs,
            flow: ask.flow,
            events,
            dt,
        };
        self.frames.resize(2 * usize::from(rungs.count) * px, 0);
        let mut buf = SendBuffers {
            payload: &mut out.payload,
            wire: &mut out.wire,
            // `Context` tiles need no scratch.
            scratch: &mut [],
        };
        let scratch = PairScratch {
            frames: &mut self.frames,
            levels: &mut out.levels,
            plane: &mut out.plane,
        };
        send_pair(
            &mut out.sender,
            &mut buf,
            link,
            (&ring, &light),
            &plan,
            scratch,
        )
    }
}

/// One stream of live-loop pairs out of a `width × height` sensor: one
/// sender (its message and frame counters run on) and its buffers.
#[derive(Debug)]
pub struct PairSender {
    sender: Sender,
    payload: Vec<u8>,
    wire: Vec<u8>,
    levels: Vec<u16>,
    plane: Vec<u8>,
}

impl PairSender {
    /// A stream for a sensor of `width × height` stored pixels.
    pub fn new((width, height): (u16, u16)) -> Result<PairSender, Error> {
        let rows = tile_rows(width, height, true, Lossy::DEFAULT.block);
        let px = usize::from(width) * usize::from(height);
        Ok(PairSender {
            sender: Sender::new(width, height, rows)?,
            payload: vec![0u8; MAX_PAYLOAD],
            wire: vec![0u8; MAX_ENCODED],
            levels: vec![0; px],
            plane: vec![0; px],
        })
    }

    /// What the stream sent so far.
    pub fn sent(&self) -> crate::wire::sender::Sent {
        self.sender.sent
    }
}

/// A pair as the core makes it, in its own terms (stored rows, fixed
/// point): what a sidecar sends up the wire.
#[derive(Debug, Clone, PartialEq)]
pub struct CorePair {
    /// Stored width and height of the sensor, px.
    pub size: (u16, u16),
    /// Midpoint, ticks.
    pub mid: u32,
    /// `from_pair` of the ask its rung frames followed ([`NO_ASK`]
    /// without rung frames).
    pub from_pair: u32,
    /// Each rung: its separation (ticks) and frames A and B (whole spikes,
    /// in 1/64 spike: [`crate::rungs::rung_frames`]; stored rows).
    pub rungs: Vec<(u16, [Vec<i16>; 2])>,
    /// Its events, if it carries them.
    pub events: Option<CoreEvents>,
}

/// A pair's events in the core's terms.
#[derive(Debug, Clone, PartialEq)]
pub struct CoreEvents {
    /// First tick.
    pub first: u32,
    /// Each tick's events: stored pixel and sign, in pixel order.
    pub ticks: Vec<Vec<(u32, i8)>>,
    /// The static rate of every stored pixel, 1/65536 spike per tick.
    pub rates: Vec<u16>,
}

impl CoreEvents {
    /// The events of ticks `a..b` that `ring` holds, each tick's in pixel
    /// order, with the static rates of `light` as of now.
    pub fn from_ring(ring: &EventRing<'_>, light: &Light<'_>, (a, b): (u32, u32)) -> CoreEvents {
        let px = usize::from(light.width()) * usize::from(light.height());
        let mut ticks: Vec<Vec<(u32, i8)>> = vec![Vec::new(); b.saturating_sub(a) as usize];
        ring.each(a, b, |e: Event| {
            if let Some(v) = ticks.get_mut((e.tick - a) as usize) {
                v.push((e.index, e.sign));
            }
        });
        for v in &mut ticks {
            v.sort_unstable();
        }
        CoreEvents {
            first: a,
            ticks,
            rates: (0..px).map(|i| light.rate(i)).collect(),
        }
    }
}

/// The downlink's asks as a sidecar hears them: the stream decoder (COBS,
/// CRC), the payload's checks and the parts put together in order
/// ([`AskAssembly`]). An ask whose parts did not all arrive intact is not
/// heard, and neither is one older than the last heard; the sidecar makes
/// its pairs with the last ask it heard.
#[derive(Debug)]
pub struct AskEar {
    size: (u16, u16),
    rx: Vec<u8>,
    rx_state: Option<DecoderState>,
    store: [Vec<i16>; 4],
    assembly: AskProgress,
    from_pair: u32,
    rungs: Rungs,
    flow: FlowBuf,
    /// Asks heard whole.
    pub heard: u64,
    /// Parts and asks refused (corrupt, not continuing the ask being put
    /// together, older than the last heard, for another sensor size).
    pub refused: u64,
}

impl AskEar {
    /// Nothing heard yet, for a `width × height` sensor: the pairs carry
    /// their events within `cold_reach` ticks of their midpoint.
    pub fn new(size: (u16, u16), cold_reach: u16) -> AskEar {
        AskEar {
            size,
            rx: vec![0; MAX_ENCODED],
            rx_state: None,
            store: std::array::from_fn(|_| vec![0; MAX_FLOW_NODES]),
            assembly: AskProgress::default(),
            from_pair: 0,
            rungs: Rungs::events(cold_reach),
            flow: FlowBuf::still(),
            heard: 0,
            refused: 0,
        }
    }

    /// The ask the pairs are made with now.
    pub fn asked(&self) -> Asked<'_> {
        Asked {
            from_pair: self.from_pair,
            rungs: self.rungs,
            flow: self.flow.view(),
        }
    }

    /// Hears `bytes` (any chunking of the downlink's stream); returns the
    /// `from_pair` of the newest ask they completed, if any.
    pub fn hear(&mut self, bytes: &[u8]) -> Option<u32> {
        let mut dec = match self.rx_state {
            Some(st) => Decoder::resume(&mut self.rx, st),
            None => Decoder::new(&mut self.rx),
        };
        let [vx, vy, ax, ay] = &mut self.store;
        let mut asm = AskAssembly::resume(vx, vy, ax, ay, self.assembly);
        let mut newest = None;
        let mut input = bytes;
        while let Some(r) = dec.feed(&mut input) {
            let view = match r {
                Ok(msg)
                    if msg.header.kind == Kind::Ask
                        && (msg.header.width, msg.header.height) == self.size =>
                {
                    AskView::parse(msg.payload)
                }
                _ => Err(WireError::Payload.into()),
            };
            match view.map(|v| asm.take(&v)) {
                Ok(Part::Whole) => match asm.head() {
                    Some(h) if h.from_pair >= self.from_pair => {
                        self.from_pair = h.from_pair;
                        self.rungs = h.rungs;
                        self.flow = FlowBuf::of(&asm.flow());
                        self.heard += 1;
                        newest = Some(h.from_pair);
                    }
                    _ => self.refused += 1,
                },
                Ok(Part::Taken) => {}
                Ok(Part::Refused) | Err(_) => self.refused += 1,
            }
        }
        self.rx_state = Some(dec.state());
        self.assembly = asm.progress();
        newest
    }
}
