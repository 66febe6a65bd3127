//! What the core makes of a stream of spike planes, in process: the
//! sidecar's static-light model ([`spiv_core::light`]) and event ring
//! ([`spiv_core::rungs`]) over owned buffers, and from them each pair's
//! [`PairInput`] as the estimator asked for it ([`Heard`]: its ask as the
//! wire delivered it) — the same frames a sidecar sends.

use spiv_core::buffers::LightBuf;
use spiv_core::light::{Light, LightClock, MAX_TOLERANCE};
use spiv_core::plane::PlaneView;
use spiv_core::rungs::{rung_frames, EventRing, PairPlan, RingCursor, Rungs};
use spiv_core::Error;

use super::control::{Ask, Heard};
use super::events::{upright, Events};
use super::ladder::PairInput;
use super::uplink::{PairBytes, Uplink, UplinkError};
use crate::piv::Field;
use crate::reconstruct::Planes;
use spiv_core::light::Event;
use spiv_core::wire::pair::NO_ASK;

/// Pixel-ticks of the ring's depth per event it holds: a quarter of an
/// event per pixel and tick on average (the scenes of `spiv bench flows`
/// make 0.02–0.05); past that the ring drops its oldest ticks, and the
/// rungs that reach them are not made.
pub const RING_PIXEL_TICKS_PER_EVENT: usize = 4;

/// Planes the static-light model is trained on before the first plane of
/// a stream that starts with its recording ([`PairMaker::train`]).
pub const LIGHT_TRAIN: usize = 512;

/// The sidecar's state over a stream of planes, owned.
#[derive(Debug)]
pub struct PairMaker {
    width: u16,
    height: u16,
    crop: usize,
    flip: bool,
    light: LightBuf,
    clock: LightClock,
    entries: Vec<u32>,
    starts: Vec<u32>,
    cursor: RingCursor,
    frames: Vec<i16>,
}

impl PairMaker {
    /// A maker for planes of `width × height` (stored order, bottom-up
    /// when `flip`; frames cropped to `crop` columns), the first plane
    /// tick `first`, its ring `depth` ticks deep.
    pub fn new(
        (width, height): (u16, u16),
        crop: usize,
        flip: bool,
        first: u32,
        depth: usize,
    ) -> Result<PairMaker, Error> {
        let px = usize::from(width) * usize::from(height);
        if px as u64 >= u64::from(spiv_core::rungs::MAX_PIXELS) {
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
            crop: crop.min(usize::from(width)),
            flip,
            light,
            clock,
            entries,
            starts,
            cursor,
            frames: Vec::new(),
        })
    }

    /// Trains the static-light model, reporting no event, on `len` ticks
    /// just before the stream's first: `planes` (the planes after the
    /// first, in recording order) played backwards, and back and forth
    /// again while `len` asks for more — the recording's start mirrored
    /// in time stands in for the light a sidecar that ran before the
    /// recording would have seen, and a mirror joins its planes without a
    /// jump.
    pub fn train(&mut self, planes: &[&[u8]], len: usize) -> Result<(), Error> {
        let n = planes.len();
        if n == 0 || len == 0 {
            return Ok(());
        }
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

    /// What the pair whose midpoint is tick `mid` carries, as `ask` asks,
    /// in the core's terms ([`CorePair`]): its rung frames warped along
    /// the ask's flow (the separations the ticks held reach: `s` before
    /// `mid` and `s` plus the events' settling after it), and its events
    /// within the ask's reach — or within `reach` when no rung frame is
    /// made.
    pub fn make(&mut self, mid: u32, ask: &Heard, reach: u32) -> Result<CorePair, Error> {
        let px = usize::from(self.width) * usize::from(self.height);
        let (rungs, events) = self.plan(mid, ask, reach);
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
            rung_frames(
                &ring,
                &light,
                &ask.flow.view(),
                mid,
                &rungs,
                &mut self.frames,
            )?;
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

    /// The rungs the pair at `mid` carries (those of `ask` that the ticks
    /// held reach) and its ticks of events (within the ask's reach, or
    /// within `reach` when it has no rung frames; `None`: none).
    fn plan(&self, mid: u32, ask: &Heard, reach: u32) -> (Rungs, Option<(u32, u32)>) {
        let held = self.ticks();
        let fits = |s: u32| {
            mid >= held.start.saturating_add(s)
                && u64::from(mid) + u64::from(s) + u64::from(MAX_TOLERANCE) <= u64::from(held.end)
        };
        let rungs = ask.core_rungs(fits);
        let r = if rungs.count == 0 {
            reach.max(1)
        } else {
            u32::from(rungs.reach)
        };
        let events = (r > 0).then(|| {
            let a = mid.saturating_sub(r).max(held.start);
            let b = mid.saturating_add(r).min(held.end).max(a);
            (a, b)
        });
        (rungs, events)
    }

    /// Sends the pair [`PairMaker::make`] makes as pair number `pair` up
    /// `uplink`'s stream ([`spiv_core::rungs::send_pair`]): its messages,
    /// in order, and what they cost.
    pub fn send(
        &mut self,
        pair: u32,
        mid: u32,
        ask: &Heard,
        reach: u32,
        uplink: &mut Uplink,
    ) -> Result<(Vec<Vec<u8>>, PairBytes), UplinkError> {
        let px = usize::from(self.width) * usize::from(self.height);
        let (rungs, events) = self.plan(mid, ask, reach);
        let light = Light::resume(self.width, self.height, self.clock, self.light.state())?;
        let ring = EventRing::resume(&mut self.entries, &mut self.starts, self.cursor)?;
        let plan = PairPlan {
            pair,
            mid,
            from_pair: if rungs.count > 0 {
                ask.from_pair
            } else {
                NO_ASK
            },
            rungs,
            flow: ask.flow.view(),
            events,
        };
        self.frames.resize(2 * usize::from(rungs.count) * px, 0);
        uplink.send(&ring, &light, &plan, &mut self.frames)
    }

    /// [`PairMaker::make`] as the estimator reads it ([`CorePair::input`]),
    /// its start the field the ask was sent from.
    pub fn input(&mut self, mid: u32, ask: &Heard, reach: u32) -> Result<PairInput, Error> {
        let (crop, flip) = (self.crop, self.flip);
        Ok(self
            .make(mid, ask, reach)?
            .input(crop, flip, ask.start.as_ref()))
    }
}

/// A pair as the core makes it, in its own terms (stored rows, fixed
/// point): what a sidecar sends up the wire ([`super::uplink`]).
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
    /// in 1/64 spike: [`spiv_core::rungs::rung_frames`]; stored rows).
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

impl CorePair {
    /// What the estimator reads of the pair: its rung frames upright,
    /// cropped to `crop` columns, in spikes; its events ([`Events`]); and
    /// `start`, the field its rung frames followed, when it has rung
    /// frames (rows stored bottom-up when `flip`).
    pub fn input(&self, crop: usize, flip: bool, start: Option<&Field>) -> PairInput {
        let (w, h) = (usize::from(self.size.0), usize::from(self.size.1));
        let crop = crop.min(w);
        let mut input = PairInput::default();
        if let (Some(field), false) = (start, self.rungs.is_empty()) {
            input.rungs = self
                .rungs
                .iter()
                .map(|(s, [a, b])| {
                    let f = |x: &Vec<i16>| upright(x, w, h, crop, flip);
                    (u32::from(*s), [f(a), f(b)])
                })
                .collect();
            input.start = Some(field.clone());
        }
        if let Some(ev) = &self.events {
            input.events = Some(Events::from_ticks(
                (w, h),
                crop,
                flip,
                u64::from(ev.first),
                ev.ticks.clone(),
                ev.rates.clone(),
            ));
        }
        input
    }
}

/// The input of the one pair at `mid` of `planes` (a whole stretch held in
/// memory) as the core makes it when asked `ask` (through the wire at
/// once, [`Heard::of`]): the model trained on the stretch's planes played
/// backwards, then every plane taken in order.
pub fn input_of(planes: &Planes, mid: u64, ask: &Ask, reach: u32) -> Result<PairInput, Error> {
    let heard = Heard::of(ask, (planes.width, planes.height), planes.flip)
        .map_err(|_| Error::BadParam(spiv_core::error::ParamError::Motion))?;
    let (w, h) = (planes.width, planes.height);
    let pb = (usize::from(w) * usize::from(h) / 8).max(1);
    let n = planes.data.len() / pb;
    let first = u32::try_from(planes.first).map_err(|_| Error::TickOverflow)?;
    let mut m = PairMaker::new(
        (w, h),
        usize::from(planes.crop_width),
        planes.flip,
        first,
        n + 1,
    )?;
    let all: Vec<&[u8]> = planes.data.chunks_exact(pb).collect();
    m.train(&all[1.min(all.len())..], LIGHT_TRAIN)?;
    for p in &all {
        m.push(p)?;
    }
    let mid = u32::try_from(mid).map_err(|_| Error::TickOverflow)?;
    m.input(mid, &heard, reach)
}
