//! The static light of every pixel, predicted from its own spikes, and the
//! *innovation events*: the spikes the prediction did not expect, and the
//! predicted spikes that did not come.
//!
//! An integrate-and-fire pixel under steady light fires almost
//! periodically: static light (background, glare, the sensor's fixed
//! pattern) gives each pixel a period, and only light that moves — a
//! particle — fires it off its beat. [`Light`] keeps, per pixel, the tick
//! of its last spike, a running estimate of its period and how often that
//! estimate was right, and its mean rate; from those it predicts the next
//! spike one period after the last. Streaming and causal: each plane is
//! taken once, in order, and every decision uses only what came before
//! (and at most [`MAX_TOLERANCE`] ticks after the prediction it settles).
//!
//! Per pixel and tick, with `P` the period estimate in whole ticks, the
//! pixel *periodic* once [`CONFIDENT`] intervals in a row agreed with it,
//! and the tolerances `early = P/16`, `late = 1 + P/16` ([`tolerance`]:
//! the sensor's jitter, a tick of phase and the photon noise of one
//! spike's charge):
//!
//! - a spike of a periodic pixel `P − early ..= P + late` ticks after its
//!   last spike was predicted — unless the train has run ahead of its
//!   period chain: at periods below [`LEAD_PERIOD`] each such spike adds
//!   its interval's deviation from the
//!   Q4 period to the pixel's *lead* (leaking an eighth per spike), and
//!   once the lead is more than [`LEAD`] (a tick and a half) and `early`
//!   ahead, the spike is an extra one (event `+1`) and the lead gives a
//!   period back. At short periods (glare: a period of 2.3 ticks fires
//!   intervals of 2 and 3) a particle's light shortens no interval by a
//!   whole tick, and shows only in the sum;
//! - any other spike: event `+1` at its tick;
//! - a periodic pixel silent `P + late` ticks after its last spike: event
//!   `−1` at tick `last + P` (the prediction that did not come), settled
//!   `late` ticks later, and one agreement less.
//!
//! An interval within a tick (or a fifth of the period, when that is more)
//! of the period agrees with it and moves it by a sixteenth of the
//! difference, rounded with a dither so that the period is the mean
//! interval ([`dithered_step`]). Intervals shorter than that (light added
//! for a while: a particle, however slowly it crosses) leave the period as it was until
//! they have lasted [`RELEARN_TICKS`]; a longer one costs two agreements,
//! and the period is learnt again when none are left. A pixel that is not periodic (too dark to have shown its period
//! yet, or too irregular) predicts no spike times: its static light is its
//! mean rate ([`Light::rate`], spikes per tick averaged over
//! [`RATE_TICKS`]), which the frames it adds to take off along the same
//! paths its spikes take ([`crate::warp::subtract_rates`]). Events are
//! sparse: light that fires on its beat makes none.
//!
//! Units: ticks (one plane), pixels of the stored row order; periods in
//! 1/16 tick (Q4); rates in 1/65536 spike per tick (Q16).
//!
//! Memory: [`LIGHT_BYTES_PER_PIXEL`] bytes per pixel in six
//! caller-supplied slices ([`LightState`]); nothing else.

use crate::error::Error;
use crate::plane::PlaneView;

/// Late ticks within which a spike still counts as the predicted one, at
/// the shortest periods ([`tolerance`]).
pub const TOLERANCE: u16 = 1;

/// Agreeing intervals after which a pixel's period predicts its spikes.
pub const CONFIDENT: u8 = 2;

/// Most agreements a pixel counts (a pixel that drifts off its period
/// loses it after a few misses however long it was steady).
pub const MAX_CONFIDENCE: u8 = 7;

/// Longest period a pixel can hold, ticks: slower pixels are predicted by
/// their rate.
pub const MAX_PERIOD: u16 = 4095;

/// Lead, Q4 ticks, by which a periodic pixel's spikes may run ahead of
/// its period chain, summed over its spikes ([`LEAD_LEAK`]), before one of
/// them counts as extra: a tick and a half. At short periods (glare) every
/// interval is a whole number of ticks around a fractional period, so a
/// particle's light shows only in the sum.
pub const LEAD: i32 = 24;

/// Periods, whole ticks, below which a pixel keeps a lead: at longer ones
/// a particle's light brings a spike a tick or more early, which the
/// window itself sees, and a lead would carry the phase a particle left
/// behind for many ticks after it passed (an extra event on the pixel
/// long after, where the flow no longer is).
pub const LEAD_PERIOD: u16 = 8;

/// The lead keeps 1 − 1/2^`LEAD_LEAK` of itself per spike (the sensor's
/// phase noise does not add up).
pub const LEAD_LEAK: u32 = 3;

/// Largest late [`tolerance`], ticks: the longest an event waits to be
/// settled.
pub const MAX_TOLERANCE: u16 = 16;

/// Ticks of intervals shorter than the period, with no agreeing one
/// between, after which the period is learnt again (static light that
/// brightened); shorter runs of them are light added for a while — a
/// particle, however slowly it crosses the pixel — and leave the period
/// as it was.
pub const RELEARN_TICKS: u16 = 512;

/// Ticks the mean rate averages over (an exponential average, 1/256 of
/// each new tick; over the first ticks the plain mean).
pub const RATE_TICKS: u32 = 256;
const _: () = assert!(RATE_TICKS.is_power_of_two());

/// A settled period of at least 16 ticks moves by 1/2^`SETTLED_SHIFT` of
/// each agreeing interval's difference from it; a shorter one by a
/// smaller share ([`settled_shift`]).
pub const SETTLED_SHIFT: u32 = 4;

/// The shift by which a settled period of `per` (Q4) learns: [`SETTLED_SHIFT`]
/// and one more for each halving of the period below 16 ticks (8 at a
/// period of 1 tick), so that it learns over about 256 ticks at any
/// period. Per spike, a glare pixel's period would otherwise learn a
/// slow particle that lingers a hundred ticks as its own light.
///
/// ```
/// use spiv_core::light::settled_shift;
/// assert_eq!(settled_shift(16), 8); // a period of 1 tick
/// assert_eq!(settled_shift(40), 7); // 2.5 ticks
/// assert_eq!(settled_shift(16 * 20), 4); // 20 ticks
/// ```
#[inline]
pub fn settled_shift(per: u16) -> u32 {
    let whole = (per >> 4).max(1);
    let log2 = 15 - whole.leading_zeros();
    SETTLED_SHIFT + 4u32.saturating_sub(log2)
}

/// One spike per tick in the rate's state (Q24).
const RATE_ONE: i64 = 1 << 24;

/// Bytes of state per pixel.
pub const LIGHT_BYTES_PER_PIXEL: usize = 12;

/// Flag bit of a pixel that has spiked at least once.
const SPIKED: u8 = 0x80;
/// Bits of the agreement count.
const COUNT: u8 = 0x0f;

/// One innovation event: pixel `index` (stored row-major, `row·width +
/// col`) at `tick`, `sign` `+1` (an unexpected spike) or `−1` (a
/// predicted spike that did not come).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Event {
    /// Pixel, stored row-major.
    pub index: u32,
    /// Tick of the spike (or of the prediction).
    pub tick: u32,
    /// `+1` or `−1`.
    pub sign: i8,
}

/// The per-pixel state, borrowed: each slice one entry per pixel.
#[derive(Debug)]
pub struct LightState<'a> {
    /// Tick of the last spike, modulo 2^16.
    pub last: &'a mut [u16],
    /// Period estimate, Q4 ticks (0: none).
    pub period: &'a mut [u16],
    /// Mean rate, Q24 spikes per tick (the extra bits keep the running
    /// average's rounding off its mean).
    pub rate: &'a mut [u32],
    /// Ticks of short intervals since the last agreeing one.
    pub short: &'a mut [u16],
    /// The train's lead on its period chain, Q4 ticks ([`LEAD`]).
    pub lead: &'a mut [i8],
    /// Bit 7: has spiked; bits 0–3: agreements with the period.
    pub flags: &'a mut [u8],
}

/// The static-light model of a `width × height` sensor.
///
/// A pixel that fires every 5 ticks goes quiet once it has shown its
/// period; an early spike (a particle) is an event:
///
/// ```
/// use spiv_core::light::{Light, LightState};
/// use spiv_core::plane::PlaneView;
///
/// # fn main() -> Result<(), spiv_core::Error> {
/// let (mut last, mut period, mut rate) = ([0u16; 8], [0u16; 8], [0u32; 8]);
/// let (mut short, mut lead, mut flags) = ([0u16; 8], [0i8; 8], [0u8; 8]);
/// let state = LightState {
///     last: &mut last,
///     period: &mut period,
///     rate: &mut rate,
///     short: &mut short,
///     lead: &mut lead,
///     flags: &mut flags,
/// };
/// let mut light = Light::new(8, 1, 0, state)?;
/// let mut events = Vec::new();
/// for t in 0..70u32 {
///     // Pixel 3 fires every 5 ticks; light added at tick 52 fires it
///     // early, and its beat goes on from there (57, 62, …).
///     let spike = if t < 52 { t % 5 == 0 } else { (t - 52) % 5 == 0 };
///     let byte = [u8::from(spike) << 3];
///     light.push(&PlaneView::new(&byte, 8, 1)?, |e| events.push((e.tick, e.sign)))?;
/// }
/// assert!(light.periodic(3));
/// let late: Vec<_> = events.into_iter().filter(|e| e.0 > 20).collect();
/// assert_eq!(late, vec![(52, 1)]);
/// # Ok(())
/// # }
/// ```
#[derive(Debug)]
pub struct Light<'a> {
    width: u16,
    height: u16,
    clock: LightClock,
    state: LightState<'a>,
}

/// Where a [`Light`] stands besides its per-pixel state: a model taken
/// apart ([`Light::clock`]) and put together again over the same state
/// ([`Light::resume`]) goes on as if never stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LightClock {
    /// The tick the next plane gets.
    pub next: u32,
    /// Ticks taken so far (the rate's average is the plain mean until
    /// [`RATE_TICKS`]).
    pub seen: u32,
}

/// Ticks by which a spike of a pixel of period `p` ticks may come late
/// and still be the predicted one: [`TOLERANCE`] (a tick of phase) and
/// `p/16` (the photon noise of a spike's charge, about 3 % of the period
/// at 1000 electrons per spike, twice over), at most [`MAX_TOLERANCE`].
///
/// ```
/// use spiv_core::light::tolerance;
/// assert_eq!(tolerance(2), 1);
/// assert_eq!(tolerance(40), 3);
/// assert_eq!(tolerance(4000), 16);
/// ```
#[inline]
pub fn tolerance(p: u16) -> u16 {
    TOLERANCE.saturating_add(p / 16).min(MAX_TOLERANCE)
}

/// Ticks by which a spike may come early and still be the predicted one:
/// `p/16` (none at the short periods of glare, where a particle's light
/// brings a spike a tick early).
#[inline]
pub fn early_tolerance(p: u16) -> u16 {
    (p / 16).min(MAX_TOLERANCE)
}

impl<'a> Light<'a> {
    /// A model with nothing seen yet, over `state` (each slice at least
    /// `width × height` entries; they are cleared). The first plane pushed
    /// is tick `first`.
    pub fn new(width: u16, height: u16, first: u32, state: LightState<'a>) -> Result<Self, Error> {
        let clock = LightClock {
            next: first,
            seen: 0,
        };
        let mut light = Light::resume(width, height, clock, state)?;
        let px = usize::from(width) * usize::from(height);
        let s = &mut light.state;
        s.last[..px].fill(0);
        s.period[..px].fill(0);
        s.rate[..px].fill(0);
        s.short[..px].fill(0);
        s.lead[..px].fill(0);
        s.flags[..px].fill(0);
        Ok(light)
    }

    /// The model as it stood at `clock` over `state` (as [`Light::clock`]
    /// and the state left it; the state is not cleared).
    pub fn resume(
        width: u16,
        height: u16,
        clock: LightClock,
        state: LightState<'a>,
    ) -> Result<Self, Error> {
        let px = crate::plane::plane_bytes(width, height).ok_or(Error::BadDimensions)? * 8;
        let got = state
            .last
            .len()
            .min(state.period.len())
            .min(state.rate.len())
            .min(state.short.len())
            .min(state.lead.len())
            .min(state.flags.len());
        if got < px {
            return Err(Error::BufferTooSmall { needed: px, got });
        }
        Ok(Light {
            width,
            height,
            clock,
            state,
        })
    }

    /// Where the model stands (to [`Light::resume`] it).
    pub fn clock(&self) -> LightClock {
        self.clock
    }

    /// Width, px.
    pub fn width(&self) -> u16 {
        self.width
    }

    /// Height, px.
    pub fn height(&self) -> u16 {
        self.height
    }

    /// The tick the next plane gets.
    pub fn next_tick(&self) -> u32 {
        self.clock.next
    }

    /// Takes the next plane (tick [`Light::next_tick`]) and hands every
    /// event it settles to `sink`: `+1` events of this tick and `−1`
    /// events of earlier ticks (at most [`MAX_TOLERANCE`] earlier), in
    /// pixel order.
    pub fn push(&mut self, plane: &PlaneView<'_>, sink: impl FnMut(Event)) -> Result<(), Error> {
        let t = self.clock.next;
        let next = t.checked_add(1).ok_or(Error::TickOverflow)?;
        self.push_at(plane, t, sink)?;
        self.clock.next = next;
        Ok(())
    }

    /// Takes `plane` as the next tick without reporting any event, the
    /// tick counter wrapping: a model trained on planes before its first
    /// reported tick ([`Light::new`] with `first` less the planes to train
    /// on, wrapping).
    pub fn train(&mut self, plane: &PlaneView<'_>) -> Result<(), Error> {
        let t = self.clock.next;
        self.push_at(plane, t, |_| {})?;
        self.clock.next = t.wrapping_add(1);
        Ok(())
    }

    fn push_at(
        &mut self,
        plane: &PlaneView<'_>,
        t: u32,
        mut sink: impl FnMut(Event),
    ) -> Result<(), Error> {
        if plane.width() != self.width || plane.height() != self.height {
            return Err(Error::PlaneMismatch);
        }
        let t16 = t as u16;
        let px = usize::from(self.width) * usize::from(self.height);
        self.clock.seen = self.clock.seen.saturating_add(1);
        // The rate's average: the plain mean over the first ticks.
        let k = i64::from(self.clock.seen.min(RATE_TICKS));
        // The average's step `d / k` rounded half away from zero; once
        // `k` is RATE_TICKS (a power of two) a shift of `|d|` instead of
        // a division, the same number.
        let shift = (k == i64::from(RATE_TICKS)).then_some(RATE_TICKS.trailing_zeros());
        let step = |d: i64| -> i64 {
            match shift {
                Some(sh) => {
                    let a = ((d.unsigned_abs() + (1 << (sh - 1))) >> sh) as i64;
                    if d < 0 {
                        -a
                    } else {
                        a
                    }
                }
                None => (d + d.signum() * k / 2) / k,
            }
        };
        let st = &mut self.state;
        let bytes = plane.bytes();
        // Bytes whose eight pixels are all on the sensor.
        let whole = (px / 8).min(bytes.len());
        for (b, &byte) in bytes.iter().enumerate() {
            let base = b * 8;
            if byte == 0 && b < whole {
                // Eight silent pixels (most bytes of most planes): every
                // rate steps towards 0, and a periodic pixel whose spike
                // is overdue settles its −1.
                for r in &mut st.rate[base..base + 8] {
                    let ri = i64::from(*r);
                    *r = (ri + step(-ri)) as u32;
                }
                for i in base..base + 8 {
                    overdue(st, i, t, &mut sink);
                }
                continue;
            }
            for bit in 0..8 {
                let i = base + bit;
                if i >= px {
                    break;
                }
                let spike = (byte >> bit) & 1 != 0;
                let r = i64::from(st.rate[i]);
                let d = if spike { RATE_ONE } else { 0 } - r;
                // Rounded to nearest, so the average has no drift.
                st.rate[i] = (r + step(d)) as u32;
                if !spike {
                    overdue(st, i, t, &mut sink);
                    continue;
                }
                let flags = st.flags[i];
                let since = t16.wrapping_sub(st.last[i]);
                let p = (st.period[i] >> 4).max(1);
                let late = tolerance(p);
                let periodic = flags & SPIKED != 0 && flags & COUNT >= CONFIDENT;
                let early = early_tolerance(p);
                let in_window =
                    periodic && since.saturating_add(early) >= p && since <= p.saturating_add(late);
                let (extra, lead) = match (in_window, p < LEAD_PERIOD) {
                    (true, true) => ahead(st.lead[i], since, st.period[i], early),
                    (true, false) => (false, 0),
                    (false, _) => (true, 0),
                };
                st.lead[i] = lead;
                if extra {
                    sink(Event {
                        index: i as u32,
                        tick: t,
                        sign: 1,
                    });
                }
                if flags & SPIKED != 0 {
                    learn(st, i, since, t16);
                }
                st.last[i] = t16;
                st.flags[i] |= SPIKED;
            }
        }
        Ok(())
    }

    /// Whether pixel `i` predicts its spikes by its period (else by its
    /// rate); `false` outside the sensor.
    pub fn periodic(&self, i: usize) -> bool {
        self.state
            .flags
            .get(i)
            .is_some_and(|&f| f & SPIKED != 0 && f & COUNT >= CONFIDENT)
    }

    /// The static rate of pixel `i` that its events do not carry, Q16
    /// spikes per tick, as of the last plane pushed: its mean rate, or 0
    /// for a periodic pixel (its predictions are events).
    pub fn rate(&self, i: usize) -> u16 {
        if self.periodic(i) {
            return 0;
        }
        let r = self.state.rate.get(i).copied().unwrap_or(0);
        ((r + 128) >> 8).min(u32::from(u16::MAX)) as u16
    }
}

/// Pixel `i` did not fire at tick `t`: a periodic pixel whose predicted
/// spike is now [`tolerance`] ticks overdue settles a `−1` event at the
/// predicted tick and loses one agreement.
#[inline(always)]
fn overdue(st: &mut LightState<'_>, i: usize, t: u32, sink: &mut impl FnMut(Event)) {
    let flags = st.flags[i];
    if flags & SPIKED == 0 || flags & COUNT < CONFIDENT {
        return;
    }
    let p = (st.period[i] >> 4).max(1);
    let late = tolerance(p);
    if (t as u16).wrapping_sub(st.last[i]) == p.saturating_add(late) {
        sink(Event {
            index: i as u32,
            tick: t.wrapping_sub(u32::from(late)),
            sign: -1,
        });
        st.flags[i] = (flags & !COUNT) | ((flags & COUNT) - 1);
    }
}

/// Whether a spike `since` ticks after the last, within its periodic
/// pixel's window (period `per`, Q4; early tolerance `early` ticks), is an
/// extra one, and the train's new lead (Q4 ticks, [`LEAD`]): the lead
/// gains the spike's deviation from the period and leaks 1/2^[`LEAD_LEAK`]
/// of itself; past [`LEAD`] and the early tolerance ahead, the spike is
/// extra (`+1`) and the lead gives back one period.
#[inline]
fn ahead(lead: i8, since: u16, per: u16, early: u16) -> (bool, i8) {
    let mut acc = i32::from(lead) + i32::from(since) * 16 - i32::from(per);
    acc -= acc >> LEAD_LEAK;
    let extra = acc < -(LEAD + 16 * i32::from(early));
    if extra {
        acc += i32::from(per);
    }
    (
        extra,
        acc.clamp(i32::from(i8::MIN), i32::from(i8::MAX)) as i8,
    )
}

/// A step of `d` (Q4) scaled by 2^−`shift` and rounded by the dither of
/// tick `t`: `⌊(d + u) / 2^shift⌋` with `u` the top `shift` bits of the
/// tick's multiplicative hash, so that over many ticks the step is `d /
/// 2^shift` on average. (A plain shift floors: it pulled every period down
/// by up to a tick, and a glare pixel of period 2.1 ticks came to expect
/// 1, so each of its 3-tick intervals was an event of static light.)
///
/// ```
/// use spiv_core::light::dithered_step;
/// // A step of 3/16 is 0 or 1 tick by tick, 3/16 on average.
/// let sum: i32 = (0..4096u16).map(|t| dithered_step(3, 4, t)).sum();
/// assert!((sum - 768).abs() < 40, "{sum}");
/// assert_eq!(dithered_step(-16, 4, 7), -1);
/// ```
#[inline]
pub fn dithered_step(d: i32, shift: u32, t: u16) -> i32 {
    let u = (u32::from(t).wrapping_mul(0x9E37_79B9) >> (32 - shift)) as i32;
    (d + u) >> shift
}

/// Updates pixel `i`'s period and agreements with a new interval of
/// `since` ticks, ending at tick `t` (mod 2^16).
fn learn(st: &mut LightState<'_>, i: usize, since: u16, t: u16) {
    let flags = st.flags[i];
    let count = flags & COUNT;
    let per = st.period[i];
    let short = st.short[i];
    let (per, count, short) = if since > MAX_PERIOD {
        (0, 0, 0)
    } else if count == 0 || per == 0 {
        (since * 16, 1, 0)
    } else {
        let iv = since * 16;
        let d = i32::from(iv) - i32::from(per);
        // An interval agrees within a fifth of the period, and at least a
        // tick either way (a period that is not a whole number of ticks
        // fires the whole ticks on both sides of it).
        let agrees = d.abs() <= (i32::from(per) / 5).max(16);
        if agrees {
            // Learnt fast at first, then slowly: a particle that lingers
            // on the pixel does not become its static light.
            let shift = if count >= CONFIDENT {
                settled_shift(per)
            } else {
                1
            };
            let per = (i32::from(per) + dithered_step(d, shift, t)) as u16;
            (per, (count + 1).min(MAX_CONFIDENCE), 0)
        } else if d < 0 && short.saturating_add(since) < RELEARN_TICKS {
            (per, count, short + since)
        } else if d > 0 && count > 2 {
            (per, count - 2, short)
        } else {
            (iv, 1, 0)
        }
    };
    st.period[i] = per;
    st.short[i] = short;
    st.flags[i] = (flags & !COUNT) | count;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::buffers::LightBuf;

    /// One pixel's events over its spike train (an 8×1 sensor, pixel 3).
    fn events(train: &[u8]) -> (Vec<(u32, i8)>, bool, u16) {
        let mut buf = LightBuf::new(8);
        let mut light = Light::new(8, 1, 0, buf.state()).unwrap();
        let mut out = Vec::new();
        for &s in train {
            let byte = [s << 3];
            let plane = PlaneView::new(&byte, 8, 1).unwrap();
            light
                .push(&plane, |e| {
                    assert_eq!(e.index, 3);
                    out.push((e.tick, e.sign));
                })
                .unwrap();
        }
        let (p, r) = (light.periodic(3), light.rate(3));
        (out, p, r)
    }

    #[test]
    fn a_steady_pixel_goes_quiet_and_a_particle_stands_out() {
        // Period 5: spikes until the period is learnt, then nothing.
        let train: Vec<u8> = (0..60).map(|t| u8::from(t % 5 == 0)).collect();
        let (ev, periodic, rate) = events(&train);
        assert!(periodic);
        assert_eq!(rate, 0);
        assert!(ev.iter().all(|&(t, _)| t <= 10), "{ev:?}");
        // An early spike at 32 (the beat is 30, 35, …): +1 there and the
        // beat moves with it (37, 42, …).
        let train: Vec<u8> = (0..60)
            .map(|t| {
                u8::from(if t < 32 {
                    t % 5 == 0
                } else {
                    (t - 32) % 5 == 0
                })
            })
            .collect();
        let (ev, _, _) = events(&train);
        let late: Vec<_> = ev.iter().filter(|e| e.0 > 10).collect();
        assert_eq!(late, vec![&(32, 1)]);
    }

    #[test]
    fn jitter_within_the_tolerance_is_no_event_and_a_silence_is() {
        // Intervals of 5 and 6 (a period of 5.5): every spike within
        // P..=P + 2 of the last.
        let mut t = 0;
        let mut train = vec![0u8; 80];
        let mut k = 0;
        while t < 80 {
            train[t] = 1;
            t += if k % 2 == 0 { 5 } else { 6 };
            k += 1;
        }
        let (ev, periodic, _) = events(&train);
        assert!(periodic);
        assert!(ev.iter().all(|&(t, _)| t <= 12), "{ev:?}");
        // The pixel goes dark after tick 40: one −1 at the prediction.
        let mut dark = train.clone();
        dark[41..].fill(0);
        let (ev, _, _) = events(&dark);
        let last_spike = dark.iter().rposition(|&s| s == 1).unwrap() as u32;
        let after: Vec<_> = ev.iter().filter(|e| e.0 > last_spike).collect();
        assert_eq!(after.len(), 1, "{ev:?}");
        assert_eq!(after[0].1, -1);
    }

    /// An integrate-and-fire pixel's train: `light(t)` thresholds per
    /// tick, each tick's charge off by up to ±3 % (a fixed pseudo-random
    /// sequence: the sensor's photon noise).
    fn fire(ticks: usize, light: impl Fn(usize) -> f64) -> Vec<u8> {
        let mut charge = 0.37;
        let mut noise: u32 = 12345;
        (0..ticks)
            .map(|t| {
                noise = noise.wrapping_mul(1_103_515_245).wrapping_add(12345);
                let jitter = f64::from(noise >> 16) / 65536.0 * 0.06 - 0.03;
                charge += light(t) * (1.0 + jitter);
                let s = charge >= 1.0;
                if s {
                    charge -= 1.0;
                }
                u8::from(s)
            })
            .collect()
    }

    #[test]
    fn glare_of_a_fractional_period_is_quiet_and_added_light_is_not() {
        // Periods of 2.3, 2.5 and 2.8 ticks: intervals of 2 and 3 ticks.
        for light in [1.0 / 2.3, 0.4, 1.0 / 2.8] {
            let train = fire(3000, |_| light);
            let (ev, periodic, _) = events(&train);
            assert!(periodic, "{light}");
            let late = ev.iter().filter(|e| e.0 >= 200).count();
            assert!(late <= 6, "{light}: {late} events of static light");
        }
        // A particle adds 30 % for 40 ticks: about 5 extra spikes, which
        // show as events though every interval is still 2 or 3 ticks.
        let base = 1.0 / 2.3;
        let lit = |t: usize| {
            if (2000..2040).contains(&t) {
                1.3 * base
            } else {
                base
            }
        };
        let train = fire(3000, lit);
        let extra = train[2000..2040]
            .iter()
            .map(|&s| usize::from(s))
            .sum::<usize>() as f64
            - 40.0 * base;
        let (ev, _, _) = events(&train);
        let seen = ev
            .iter()
            .filter(|e| (2000..2060).contains(&e.0) && e.1 > 0)
            .count() as f64;
        assert!(extra > 4.0, "{extra}");
        assert!(
            seen >= 0.5 * extra && seen <= extra + 2.0,
            "{seen} events for {extra} extra spikes"
        );
    }

    #[test]
    fn a_dark_pixel_is_predicted_by_its_rate() {
        let mut train = vec![0u8; 200];
        for t in [10, 60, 150] {
            train[t] = 1;
        }
        let (ev, periodic, rate) = events(&train);
        assert!(!periodic);
        assert_eq!(ev, vec![(10, 1), (60, 1), (150, 1)]);
        // Its mean rate over the 200 ticks: 3/200 spikes per tick (the
        // running mean in integer steps, within 5 %).
        let want = 3.0 / 200.0 * 65536.0;
        assert!(
            (f64::from(rate) - want).abs() < 0.05 * want,
            "{rate} against {want}"
        );
    }

    #[test]
    fn planes_of_another_size_are_refused() {
        let mut buf = LightBuf::new(16);
        let mut light = Light::new(8, 2, 0, buf.state()).unwrap();
        let byte = [0u8];
        let plane = PlaneView::new(&byte, 8, 1).unwrap();
        assert_eq!(light.push(&plane, |_| {}), Err(Error::PlaneMismatch));
        let mut small = LightBuf::new(4);
        assert!(matches!(
            Light::new(8, 2, 0, small.state()),
            Err(Error::BufferTooSmall { needed: 16, got: 4 })
        ));
    }
}
