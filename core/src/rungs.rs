//! What a pair of the time ladder needs from the spikes, made where they
//! are: the innovation events ([`crate::light`]) of the last ticks, held
//! in a ring ([`EventRing`]), and from them either the events around the
//! pair (a pair with no flow to follow: [`Rungs::reach`]) or the rung
//! frames — for each separation `s`, frame A of the `s` ticks before the
//! pair's midpoint and frame B of the `s` ticks after it, each warped
//! along the host's flow to its own centre ([`rung_frames`],
//! [`crate::warp`]). The sidecar's loop and the host's offline run call
//! the same functions, so the host measures the same frames either way.
//!
//! [`send_pair`] sends a pair so made up the wire, as the live loop's pair
//! head and its parts ([`crate::wire::pair`]).
//!
//! Memory: the ring's two caller-supplied buffers and the frames'; no
//! allocation. Events the ring cannot hold are counted
//! ([`EventRing::lost`]), never silently dropped.

use crate::error::{Error, LinkError};
use crate::light::{Event, Light, MAX_TOLERANCE};
use crate::method::Method;
use crate::warp::{scatter, subtract_rates, Flow, Window, SCALE};
use crate::wire::codec::Lossy;
use crate::wire::pair::{PairHead, MAX_EVENT_TICKS};
use crate::wire::sender::{FrameInfo, Link, SendBuffers, Sender, Slot};
use crate::wire::{Encoding, WireError};

pub use crate::wire::pair::MAX_RUNGS;

/// The longest rung the live loop makes by default, ticks (the host's
/// ladder climbs 4, 8, 16, 32, 64 and 128 ticks).
pub const LONGEST_RUNG: u16 = 128;

/// Ticks on each side of the midpoint whose events a pair with no flow to
/// follow carries by default (the host's unestimated rungs sum them).
pub const BOOTSTRAP_REACH: u16 = 32;

/// Ticks after a pair's midpoint that a loop whose rungs reach up to
/// `longest` ticks and whose events reach `reach` ticks holds before it
/// makes the pair: the longest of them, then the events' tolerance.
///
/// ```
/// use spiv_core::rungs::{lead, LONGEST_RUNG, BOOTSTRAP_REACH};
/// assert_eq!(lead(LONGEST_RUNG, BOOTSTRAP_REACH), 128 + u32::from(spiv_core::light::MAX_TOLERANCE));
/// ```
pub const fn lead(longest: u16, reach: u16) -> u32 {
    let s = if longest > reach { longest } else { reach };
    s as u32 + MAX_TOLERANCE as u32
}

/// Ticks of events the ring of such a loop holds ([`EventRing`]'s
/// `depth`): the `longest` (or `reach`) ticks before a midpoint, [`lead`]
/// after it, and two more.
pub const fn ring_depth(longest: u16, reach: u16) -> u32 {
    let s = if longest > reach { longest } else { reach };
    s as u32 + lead(longest, reach) + 2
}

/// What the pair at midpoint `mid` carries when the ring holds the ticks
/// `held` and the last ask heard says `asked` (`still`: it gave no flow):
/// the asked separations `s` whose frames the held ticks reach (`s`
/// before `mid`, `s` and the events' tolerance after it) — none without a
/// flow — and the ticks of events within the ask's reach, or within
/// `cold_reach` when no rung frame is made (`None`: no events).
///
/// ```
/// use spiv_core::rungs::{pair_plan, Rungs};
/// let mut asked = Rungs::events(0);
/// asked.separations[..2].copy_from_slice(&[16, 128]);
/// asked.count = 2;
/// // 128 ticks do not fit before tick 100: the 16-tick rung alone, no events.
/// let (r, ev) = pair_plan(0..400, 100, &asked, false, 32);
/// assert_eq!((r.separations(), ev), (&[16u16][..], None));
/// // No flow: the events within the cold reach.
/// let (r, ev) = pair_plan(0..400, 100, &asked, true, 32);
/// assert_eq!((r.count, ev), (0, Some((68, 132))));
/// ```
pub fn pair_plan(
    held: core::ops::Range<u32>,
    mid: u32,
    asked: &Rungs,
    still: bool,
    cold_reach: u16,
) -> (Rungs, Option<(u32, u32)>) {
    let fits = |s: u32| {
        mid >= held.start.saturating_add(s)
            && u64::from(mid) + u64::from(s) + u64::from(MAX_TOLERANCE) <= u64::from(held.end)
    };
    let mut rungs = Rungs::events(asked.reach);
    if !still {
        for &s in asked.separations() {
            if fits(u32::from(s)) {
                rungs.separations[usize::from(rungs.count)] = s;
                rungs.count += 1;
            }
        }
    }
    let r = if rungs.count == 0 {
        u32::from(cold_reach.max(1))
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

/// Bits of a ring entry below the pixel: the ticks between the event and
/// the tick it was stored under (a prediction settled late), and the sign.
const LOW_BITS: u32 = 6;
/// Bit of a ring entry: the event is `−1`.
const NEG: u32 = 0b01;

/// Most pixels a ring entry can name.
pub const MAX_PIXELS: u32 = 1 << (32 - LOW_BITS);

/// The events of the last `depth` ticks, in two caller-supplied buffers:
/// `entries` (one `u32` per event: pixel `<< 6`, the ticks it was settled
/// late (5 bits) and a sign bit) used as a circular buffer, and `starts` (`depth + 1` entries: the
/// running count of events stored before each tick, modulo 2^32).
#[derive(Debug)]
pub struct EventRing<'a> {
    entries: &'a mut [u32],
    starts: &'a mut [u32],
    at: RingCursor,
}

/// Where an [`EventRing`] stands besides its buffers: a ring taken apart
/// ([`EventRing::cursor`]) and put together again over the same buffers
/// ([`EventRing::resume`]) goes on as if never stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RingCursor {
    /// Ticks held, oldest first: `first..next`.
    pub first: u32,
    /// The next tick.
    pub next: u32,
    /// Events stored so far (the write position is `stored % capacity`).
    pub stored: u32,
    /// Events that did not fit.
    pub lost: u32,
    /// Ticks dropped to make room.
    pub evicted: u32,
}

impl<'a> EventRing<'a> {
    /// An empty ring over `entries` and `starts` (depth `starts.len() − 1`
    /// ticks, at least 1), whose first tick will be `first`.
    pub fn new(entries: &'a mut [u32], starts: &'a mut [u32], first: u32) -> Result<Self, Error> {
        if starts.len() < 2 || entries.is_empty() {
            return Err(Error::BufferTooSmall {
                needed: 2,
                got: starts.len().min(entries.len()),
            });
        }
        starts.fill(0);
        Ok(EventRing {
            entries,
            starts,
            at: RingCursor {
                first,
                next: first,
                stored: 0,
                lost: 0,
                evicted: 0,
            },
        })
    }

    /// The ring as it stood at `at` over `entries` and `starts` (as
    /// [`EventRing::cursor`] and the buffers left it).
    pub fn resume(
        entries: &'a mut [u32],
        starts: &'a mut [u32],
        at: RingCursor,
    ) -> Result<Self, Error> {
        if starts.len() < 2 || entries.is_empty() {
            return Err(Error::BufferTooSmall {
                needed: 2,
                got: starts.len().min(entries.len()),
            });
        }
        Ok(EventRing {
            entries,
            starts,
            at,
        })
    }

    /// Where the ring stands (to [`EventRing::resume`] it).
    pub fn cursor(&self) -> RingCursor {
        self.at
    }

    /// Ticks the ring holds at most.
    pub fn depth(&self) -> u32 {
        (self.starts.len() - 1) as u32
    }

    /// The ticks held, `first..next`.
    pub fn ticks(&self) -> core::ops::Range<u32> {
        self.at.first..self.at.next
    }

    /// Events that did not fit (a tick with more events than the ring
    /// holds keeps the first ones).
    pub fn lost(&self) -> u32 {
        self.at.lost
    }

    /// Ticks dropped from the old end before they left the depth, to make
    /// room for new events.
    pub fn evicted(&self) -> u32 {
        self.at.evicted
    }

    fn slot(&self, tick: u32) -> usize {
        (tick % self.starts.len() as u32) as usize
    }

    /// Stores the events `light` settles with the next plane: pushes
    /// `plane` through `light` (tick [`Light::next_tick`], which must be
    /// the ring's next tick). Kept out of line: `firmware-sim/cost.sh`
    /// counts its instructions by its symbol.
    #[inline(never)]
    pub fn push(
        &mut self,
        light: &mut Light<'_>,
        plane: &crate::plane::PlaneView<'_>,
    ) -> Result<(), Error> {
        let t = light.next_tick();
        if t != self.at.next {
            return Err(Error::TickUnavailable);
        }
        // Open tick t: drop the oldest tick if the depth is full.
        if self.at.next.wrapping_sub(self.at.first) >= self.depth() {
            self.at.first = self.at.first.wrapping_add(1);
        }
        let s = self.slot(t);
        self.starts[s] = self.at.stored;
        let cap = self.entries.len() as u32;
        let mut overflow = 0u32;
        light.push(plane, |e| {
            // Room: drop the oldest ticks until the event fits; a tick
            // that alone fills the ring keeps its first events.
            loop {
                let oldest = self.starts[self.slot(self.at.first)];
                if self.at.stored.wrapping_sub(oldest) < cap {
                    break;
                }
                if self.at.first == t {
                    overflow = overflow.saturating_add(1);
                    return;
                }
                self.at.first = self.at.first.wrapping_add(1);
                self.at.evicted = self.at.evicted.wrapping_add(1);
            }
            let late = t.wrapping_sub(e.tick).min(31);
            let neg = if e.sign < 0 { NEG } else { 0 };
            let k = (self.at.stored % cap) as usize;
            self.entries[k] = e.index << LOW_BITS | late << 1 | neg;
            self.at.stored = self.at.stored.wrapping_add(1);
        })?;
        self.at.lost = self.at.lost.saturating_add(overflow);
        self.at.next = t.wrapping_add(1);
        Ok(())
    }

    /// Calls `f` with every event of ticks `a..b` the ring holds (events
    /// settled up to [`MAX_TOLERANCE`] ticks later included).
    pub fn each(&self, a: u32, b: u32, mut f: impl FnMut(Event)) {
        let cap = self.entries.len() as u32;
        let lo = a.max(self.at.first);
        let hi = b.saturating_add(u32::from(MAX_TOLERANCE)).min(self.at.next);
        let mut t = lo;
        while t < hi {
            let s0 = self.starts[self.slot(t)];
            let s1 = if t + 1 == self.at.next {
                self.at.stored
            } else {
                self.starts[self.slot(t + 1)]
            };
            let mut k = s0;
            while k != s1 {
                let x = self.entries[(k % cap) as usize];
                let tick = t.wrapping_sub((x >> 1) & 31);
                if tick >= a && tick < b {
                    f(Event {
                        index: x >> LOW_BITS,
                        tick,
                        sign: if x & NEG != 0 { -1 } else { 1 },
                    });
                }
                k = k.wrapping_add(1);
            }
            t += 1;
        }
    }
}

/// What the host asks of a pair (the control's rung part).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Rungs {
    /// Separations of the rung frames, ticks (each 2..=255; `count` of
    /// them in use).
    pub separations: [u16; MAX_RUNGS],
    /// Separations in use.
    pub count: u8,
    /// Ticks on each side of the midpoint whose events the pair carries
    /// (0: none).
    pub reach: u16,
}

impl Rungs {
    /// No rung frames, the events within `reach` ticks of the midpoint.
    ///
    /// ```
    /// use spiv_core::rungs::Rungs;
    /// let r = Rungs::events(24);
    /// assert!(r.separations().is_empty());
    /// assert_eq!(r.ahead(), 24 + u32::from(spiv_core::light::MAX_TOLERANCE));
    /// ```
    pub const fn events(reach: u16) -> Rungs {
        Rungs {
            separations: [0; MAX_RUNGS],
            count: 0,
            reach,
        }
    }

    /// The separations in use.
    pub fn separations(&self) -> &[u16] {
        &self.separations[..usize::from(self.count).min(MAX_RUNGS)]
    }

    /// Ticks after the midpoint the pair needs before it can be made
    /// (its longest rung or its reach, then the events' tolerance).
    pub fn ahead(&self) -> u32 {
        let s = self.separations().iter().copied().max().unwrap_or(0);
        u32::from(s.max(self.reach)) + u32::from(MAX_TOLERANCE)
    }

    /// Ticks before the midpoint the pair reads.
    pub fn behind(&self) -> u32 {
        let s = self.separations().iter().copied().max().unwrap_or(0);
        u32::from(s.max(self.reach))
    }

    /// Checks the separations (2..=255, at most [`MAX_RUNGS`]).
    pub fn check(&self) -> Result<(), Error> {
        if usize::from(self.count) > MAX_RUNGS
            || self.separations().iter().any(|&s| !(2..=255).contains(&s))
        {
            return Err(Error::BadParam(crate::error::ParamError::Window));
        }
        Ok(())
    }
}

/// The floor of a rung's frames, whole spikes: `round(√(s/16))` for a
/// separation of `s` ticks, at least 1 (1 up to 35 ticks, 2 for 36–99,
/// 3 for 100–195, 4 for 196–323). A frame sample below it is sent as 0
/// ([`rung_frames`]): the shot noise of the particle-free background,
/// whose spread grows as √s, and most of a rung frame's bytes on the wire
/// (what it costs and saves: docs/results.md, `spiv bench live`).
///
/// ```
/// use spiv_core::rungs::rung_floor;
/// assert_eq!([16, 32, 64, 128].map(rung_floor), [1, 1, 2, 3]);
/// ```
pub const fn rung_floor(s: u16) -> i16 {
    // round(√(s/16)) = #{k ≥ 1 : (k − ½)² ≤ s/16} = #{k : 4(2k − 1)² ≤ s}.
    let mut k = 1u32;
    while 4 * (2 * k - 1) * (2 * k - 1) <= s as u32 {
        k += 1;
    }
    if k > 2 {
        (k - 1) as i16
    } else {
        1
    }
}

/// Makes the rung frames of the pair whose midpoint is tick `mid` (a tick
/// boundary: A ends and B begins there) from the events in `ring`, warped
/// along `flow`: for the `i`-th separation `s`, frame `2i` (A: ticks
/// `mid − s..mid`, centred at `mid − s/2`) and `2i + 1` (B: `mid..mid + s`,
/// at `mid + s/2`), each `width × height` samples of `frames`: the
/// events less the static rate of `light`'s rate-predicted pixels over `s`
/// ticks ([`subtract_rates`]), in 1/[`crate::warp::SCALE`] spike, then
/// rounded to whole spikes (half up), and 0 below the rung's floor
/// ([`rung_floor`]; negative samples too). Kept out of line for
/// `firmware-sim/cost.sh`.
#[inline(never)]
pub fn rung_frames(
    ring: &EventRing<'_>,
    light: &Light<'_>,
    flow: &Flow<'_>,
    mid: u32,
    rungs: &Rungs,
    frames: &mut [i16],
) -> Result<(), Error> {
    rungs.check()?;
    flow.check()?;
    let (w, h) = (light.width(), light.height());
    let px = usize::from(w) * usize::from(h);
    let seps = rungs.separations();
    let needed = 2 * seps.len() * px;
    if frames.len() < needed {
        return Err(Error::BufferTooSmall {
            needed,
            got: frames.len(),
        });
    }
    let frames = &mut frames[..needed];
    frames.fill(0);
    let longest = u32::from(seps.iter().copied().max().unwrap_or(0));
    if longest == 0 {
        return Ok(());
    }
    let first = mid.checked_sub(longest).ok_or(Error::TickUnavailable)?;
    let end = mid.checked_add(longest).ok_or(Error::TickOverflow)?;
    if first < ring.ticks().start || end.saturating_add(u32::from(MAX_TOLERANCE)) > ring.ticks().end
    {
        return Err(Error::TickUnavailable);
    }
    let windows = windows_of(mid, seps);
    ring.each(first, end, |e| {
        for (k, win) in windows.iter().enumerate().take(2 * seps.len()) {
            if win.holds(e.tick) {
                scatter(&mut frames[k * px..(k + 1) * px], w, h, flow, win, e);
            }
        }
    });
    for (k, win) in windows.iter().enumerate().take(2 * seps.len()) {
        let frame = &mut frames[k * px..(k + 1) * px];
        subtract_rates(frame, w, h, flow, win, |i| light.rate(i));
        floored(frame, rung_floor(seps[k / 2]));
    }
    Ok(())
}

/// Rounds every sample of `frame` (1/[`SCALE`] spike) to whole spikes,
/// half up, and makes those below `floor` spikes 0.
fn floored(frame: &mut [i16], floor: i16) {
    let (one, half) = (i32::from(SCALE), i32::from(SCALE / 2));
    let least = i32::from(floor) * one;
    let most = i32::from(i16::MAX) & !(one - 1);
    for v in frame {
        let n = ((i32::from(*v) + half) & !(one - 1)).min(most);
        *v = if n >= least { n as i16 } else { 0 };
    }
}

/// The windows of the rung frames around `mid`: A then B per separation.
fn windows_of(mid: u32, seps: &[u16]) -> [Window; 2 * MAX_RUNGS] {
    let mut out = [Window::new(0, 0); 2 * MAX_RUNGS];
    for (i, &s) in seps.iter().enumerate().take(MAX_RUNGS) {
        let s = u32::from(s);
        out[2 * i] = Window::new(mid.saturating_sub(s), s);
        out[2 * i + 1] = Window::new(mid, s);
    }
    out
}

/// A live-loop pair to send ([`send_pair`]): which pair, its midpoint,
/// the ask its rung frames follow, and what it carries.
#[derive(Debug, Clone, Copy)]
pub struct PairPlan<'f> {
    /// Pair counter.
    pub pair: u32,
    /// Midpoint, ticks.
    pub mid: u32,
    /// `from_pair` of the ask followed ([`crate::wire::pair::NO_ASK`]
    /// without rung frames).
    pub from_pair: u32,
    /// The rung frames' separations (their `reach` is not read).
    pub rungs: Rungs,
    /// The flow they are warped along.
    pub flow: Flow<'f>,
    /// Ticks `a..b` of events to send (`None`: none), at most
    /// [`MAX_EVENT_TICKS`].
    pub events: Option<(u32, u32)>,
    /// Ticks between the frames of the pair the host reports (the head's
    /// `dt`; 0: not given).
    pub dt: u16,
}

/// The caller's buffers for [`send_pair`], each for a sensor of `px`
/// pixels.
#[derive(Debug)]
pub struct PairScratch<'a> {
    /// The rung frames: 2 × separations × `px` samples.
    pub frames: &'a mut [i16],
    /// One frame of 16-bit levels: `px`.
    pub levels: &'a mut [u16],
    /// One plane of event levels: `px`.
    pub plane: &'a mut [u8],
}

/// Bytes a pair took on the wire, by what they carry (headers, CRCs and
/// COBS framing included).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PairCost {
    /// The head.
    pub head: u64,
    /// The rung frames.
    pub rung_frames: u64,
    /// The events, tick by tick.
    pub events: u64,
    /// The static rates sent with the events.
    pub rates: u64,
}

/// Sends the pair `plan` describes through `sender` into `link`: its head
/// ([`PairHead`]), then its parts as lossless `Context` frames — the rung
/// frames made from `ring` and `light` ([`rung_frames`]: whole spikes) as
/// levels of one spike above each frame's smallest sample, one plane per
/// tick of events (0 none, 1 a `−1`, 2 a `+1`) and, with events, the
/// static rate of every pixel ([`Light::rate`]). Each part's frame end names the pair and the part
/// (`member`), and carries the rung's separation as `dt`.
pub fn send_pair<L: Link>(
    sender: &mut Sender,
    buf: &mut SendBuffers<'_>,
    link: &mut L,
    (ring, light): (&EventRing<'_>, &Light<'_>),
    plan: &PairPlan<'_>,
    scratch: PairScratch<'_>,
) -> Result<PairCost, LinkError<L::Error>> {
    let px = usize::from(light.width()) * usize::from(light.height());
    let n = 2 * plan.rungs.separations().len();
    if scratch.frames.len() < n * px || scratch.levels.len() < px || scratch.plane.len() < px {
        return Err(LinkError::from(WireError::TooLarge));
    }
    let (a, b) = plan.events.unwrap_or((0, 0));
    if plan.events.is_some() && (a < ring.ticks().start || b > ring.ticks().end) {
        return Err(LinkError::from(WireError::Payload));
    }
    if n > 0 {
        rung_frames(
            ring,
            light,
            &plan.flow,
            plan.mid,
            &plan.rungs,
            scratch.frames,
        )
        .map_err(|_| LinkError::from(WireError::Payload))?;
    }
    let frames = &scratch.frames[..n * px];
    let head = pair_head(plan, frames, px)?;
    let mut cost = PairCost::default();
    let before = sender.sent.bytes;
    sender.send_pair_head(buf, &head, link)?;
    cost.head = sender.sent.bytes - before;
    let mut member = 0u8;
    let mut part = |sender: &Sender, dt: u32| {
        let info = FrameInfo {
            slot: Slot {
                tick: plan.mid,
                pair: plan.pair,
                member,
            },
            method: Method::Ladder,
            full_scale: u16::MAX,
            dt,
        };
        member = member.wrapping_add(1);
        (info, sender.sent.bytes)
    };
    let levels = &mut scratch.levels[..px];
    for (k, f) in frames.chunks_exact(px).enumerate() {
        let low = i32::from(head.offsets[k]);
        for (l, &v) in levels.iter_mut().zip(f) {
            *l = ((i32::from(v) - low) / i32::from(SCALE)) as u16;
        }
        let (info, before) = part(sender, u32::from(head.separations[k / 2]));
        sender.send_frame(buf, levels, &info, Encoding::Context, &Lossy::DEFAULT, link)?;
        cost.rung_frames += sender.sent.bytes - before;
    }
    if plan.events.is_none() {
        return Ok(cost);
    }
    let plane = &mut scratch.plane[..px];
    for t in a..b {
        plane.fill(0);
        ring.each(t, t + 1, |e: Event| {
            if let Some(x) = plane.get_mut(e.index as usize) {
                *x = if e.sign > 0 { 2 } else { 1 };
            }
        });
        let (info, before) = part(sender, 0);
        sender.send_frame(buf, plane, &info, Encoding::Context, &Lossy::DEFAULT, link)?;
        cost.events += sender.sent.bytes - before;
    }
    for (i, l) in levels.iter_mut().enumerate() {
        *l = light.rate(i);
    }
    let (info, before) = part(sender, 0);
    sender.send_frame(buf, levels, &info, Encoding::Context, &Lossy::DEFAULT, link)?;
    cost.rates += sender.sent.bytes - before;
    Ok(cost)
}

/// The head of the pair `plan` describes, its rung frames `frames` (`px`
/// samples each): each frame's offset its smallest sample.
fn pair_head<E>(plan: &PairPlan<'_>, frames: &[i16], px: usize) -> Result<PairHead, LinkError<E>> {
    let (a, b) = plan.events.unwrap_or((0, 0));
    let ev_ticks = u16::try_from(b.saturating_sub(a))
        .ok()
        .filter(|&t| t <= MAX_EVENT_TICKS)
        .ok_or(LinkError::from(WireError::Payload))?;
    let seps = plan.rungs.separations();
    let mut head = PairHead {
        pair: plan.pair,
        mid: plan.mid,
        from_pair: plan.from_pair,
        count: plan.rungs.count,
        ev_first: a,
        ev_ticks,
        dt: plan.dt,
        ..PairHead::default()
    };
    head.separations[..seps.len()].copy_from_slice(seps);
    for (k, f) in frames.chunks_exact(px.max(1)).enumerate() {
        head.offsets[k] = f.iter().copied().min().unwrap_or(0);
    }
    Ok(head)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::buffers::LightBuf;
    use crate::plane::PlaneView;

    /// A bright dot moving 1 px per 4 ticks right along row 2 of a 32×4
    /// sensor over a dark background.
    fn dot(t: u32) -> Vec<u8> {
        let mut p = vec![0u8; 32 * 4 / 8];
        let x = 4 + (t / 4) as usize;
        let i = 2 * 32 + x;
        p[i / 8] |= 1 << (i % 8);
        p
    }

    #[test]
    fn events_come_back_by_tick_and_rung_frames_pile_a_moving_dot_up() {
        let mut b = LightBuf::new(128);
        let mut light = Light::new(32, 4, 0, b.state()).unwrap();
        let (mut entries, mut starts) = (vec![0u32; 4096], vec![0u32; 65]);
        let mut ring = EventRing::new(&mut entries, &mut starts, 0).unwrap();
        for t in 0..50 {
            ring.push(&mut light, &PlaneView::new(&dot(t), 32, 4).unwrap())
                .unwrap();
        }
        assert_eq!(ring.ticks(), 0..50);
        let mut n = 0;
        ring.each(10, 20, |e| {
            assert!((10..20).contains(&e.tick));
            n += 1;
        });
        assert!(n >= 8, "{n}");
        // The flow: 0.25 px/tick right everywhere (one node).
        let (vx, vy, ax, ay) = ([1024i16], [0i16], [0i16], [0i16]);
        let flow = Flow {
            nx: 1,
            ny: 1,
            x0: 0,
            y0: 0,
            pitch: 16,
            vx: &vx,
            vy: &vy,
            ax: &ax,
            ay: &ay,
        };
        let mut rungs = Rungs::events(0);
        rungs.separations[0] = 8;
        rungs.count = 1;
        let mut frames = vec![0i16; 2 * 128];
        rung_frames(&ring, &light, &flow, 24, &rungs, &mut frames).unwrap();
        // A: ticks 16..24, centre 20 → the dot at x = 4 + 5 = 9; B: 24..32,
        // centre 28 → x = 11. Their positive samples sit there.
        let peak = |f: &[i16]| {
            f.iter()
                .enumerate()
                .max_by_key(|(_, &v)| v)
                .map(|(k, _)| k)
                .unwrap()
        };
        assert_eq!(peak(&frames[..128]), 2 * 32 + 9);
        assert_eq!(peak(&frames[128..]), 2 * 32 + 11);
        // Not enough planes for a 32-tick rung after 24.
        rungs.separations[0] = 32;
        assert_eq!(
            rung_frames(&ring, &light, &flow, 24, &rungs, &mut frames),
            Err(Error::TickUnavailable)
        );
    }

    /// Whole spikes, half up; below the floor (and negative) 0; the
    /// largest samples do not wrap.
    #[test]
    fn samples_round_to_whole_spikes_above_the_floor() {
        let s = |x: f64| (x * f64::from(SCALE)) as i16;
        let mut f = [
            s(0.49),
            s(0.5),
            s(1.49),
            s(1.5),
            s(2.5),
            s(-3.0),
            i16::MAX,
            i16::MIN,
        ];
        let g = f;
        floored(&mut f, 1);
        assert_eq!(f, [0, 64, 64, 128, 192, 0, 32704, 0]);
        let mut f = g;
        floored(&mut f, 3);
        assert_eq!(f, [0, 0, 0, 0, 192, 0, 32704, 0]);
        assert_eq!(
            [2, 3, 4, 35, 36, 99, 100, 195, 196, 255].map(rung_floor),
            [1, 1, 1, 1, 2, 2, 3, 3, 4, 4]
        );
    }

    #[test]
    fn a_full_ring_drops_old_ticks_and_counts_what_it_cannot_hold() {
        let mut b = LightBuf::new(128);
        let mut light = Light::new(32, 4, 0, b.state()).unwrap();
        // Every pixel fires every other tick: up to 128 events a tick.
        let (mut entries, mut starts) = (vec![0u32; 100], vec![0u32; 9]);
        let mut ring = EventRing::new(&mut entries, &mut starts, 0).unwrap();
        for t in 0..20u32 {
            let p = vec![if t % 2 == 0 { 0xff } else { 0 }; 16];
            ring.push(&mut light, &PlaneView::new(&p, 32, 4).unwrap())
                .unwrap();
        }
        assert!(ring.lost() > 0);
        let mut n = 0;
        ring.each(0, 20, |_| n += 1);
        assert!(n <= 100);
    }
}
