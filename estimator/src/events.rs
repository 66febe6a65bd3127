//! The spikes around a pair as the estimator reads them: the core's
//! innovation events ([`spiv_core::light`]) of a stretch of ticks, with
//! the static rates of the pixels that predict by their rate, and the
//! frames the core's warp makes of them ([`Events::frame`]).
//!
//! Events index the **stored** rows (the sensor's order, bottom-up in a
//! Vidar file), as the core works; [`Events::frame`] warps in stored
//! coordinates along a [`WarpFlow`] in stored coordinates and returns the
//! frame upright and cropped, as PIV reads it. Memory: one `(u32, i8)`
//! per event (about 0.04 events per pixel and tick on the scenes of
//! `spiv bench flows`) and one `u16` per pixel.

use ndarray::Array2;
use spiv_core::light::Event;
use spiv_core::warp::{scatter, subtract_rates, Window, SCALE};

use crate::compensate::WarpFlow;

/// A stretch of events: ticks `first..first + ticks`.
#[derive(Debug, Clone, PartialEq)]
pub struct Events {
    /// Stored width of the planes, px (events index `row·stored_width +
    /// col`).
    pub stored_width: usize,
    /// Width of the frames, px (padding columns cropped).
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Stored rows are bottom-up.
    pub flip: bool,
    /// First tick held.
    pub first: u64,
    /// Ticks held.
    pub ticks: usize,
    /// Per tick, where its events start in `events` (`ticks + 1`).
    starts: Vec<usize>,
    /// Pixel (stored index) and sign of every event, tick by tick.
    events: Vec<(u32, i8)>,
    /// The static rate of every stored pixel that its events do not carry,
    /// 1/65536 spike per tick, as of the end of the stretch
    /// ([`Light::rate`]).
    rates: Vec<u16>,
}

impl Events {
    /// The events of ticks `first..first + per_tick.len()` (each tick's
    /// pixel and sign, stored order, in pixel order as the core's pair
    /// holds them: [`spiv_core::pairs::CoreEvents`]) with the static rates of the
    /// `stored_width × height` pixels, for frames `crop_width` px wide.
    pub fn from_ticks(
        (stored_width, height): (usize, usize),
        crop_width: usize,
        flip: bool,
        first: u64,
        per_tick: Vec<Vec<(u32, i8)>>,
        rates: Vec<u16>,
    ) -> Events {
        let n = per_tick.len();
        let mut starts = Vec::with_capacity(n + 1);
        let mut events = Vec::with_capacity(per_tick.iter().map(Vec::len).sum());
        for v in per_tick {
            starts.push(events.len());
            events.extend(v);
        }
        starts.push(events.len());
        Events {
            stored_width,
            width: crop_width.min(stored_width),
            height,
            flip,
            first,
            ticks: n,
            starts,
            events,
            rates,
        }
    }

    /// The recording ticks held, `first..first + ticks`.
    pub fn range(&self) -> std::ops::Range<u64> {
        self.first..self.first + self.ticks as u64
    }

    /// Events held.
    pub fn len(&self) -> usize {
        self.events.len()
    }

    /// Whether no event is held.
    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// The static rate of every stored pixel, 1/65536 spike per tick, as
    /// of the end of the stretch.
    pub fn rates(&self) -> &[u16] {
        &self.rates
    }

    /// The events of tick `t` (0 = the first held): stored pixel and sign.
    pub fn tick(&self, t: usize) -> &[(u32, i8)] {
        match (self.starts.get(t), self.starts.get(t + 1)) {
            (Some(&a), Some(&b)) => &self.events[a..b],
            _ => &[],
        }
    }

    /// The frame of the ticks `t0..t0 + n` (clipped to what is held),
    /// centred at `centre` (ticks; a spike of tick `t` is taken at
    /// `t + ½`), each event where `flow` carries it then
    /// ([`spiv_core::warp::scatter`]), less `n` ticks of the rate-predicted
    /// pixels' static rates; upright, cropped, in spikes.
    pub fn frame(&self, centre: f64, (t0, n): (u64, u64), flow: &WarpFlow) -> Array2<f32> {
        let (sw, h) = (self.stored_width, self.height);
        let span = self.range();
        let a = t0.max(span.start);
        let b = t0.saturating_add(n).min(span.end).max(a);
        let mut acc = vec![0i16; sw * h];
        let view = flow.view();
        let win = Window {
            start: a as u32,
            len: (b - a) as u32,
            centre2: (2.0 * centre).round() as i64,
        };
        for t in a..b {
            for &(index, sign) in self.tick((t - span.start) as usize) {
                let e = Event {
                    index,
                    tick: t as u32,
                    sign,
                };
                scatter(&mut acc, sw as u16, h as u16, &view, &win, e);
            }
        }
        subtract_rates(&mut acc, sw as u16, h as u16, &view, &win, |i| {
            self.rates.get(i).copied().unwrap_or(0)
        });
        upright(&acc, sw, h, self.width, self.flip)
    }
}

/// A frame of `i16` samples (1/[`SCALE`] spike, stored rows, `sw` wide)
/// as spikes, upright, `w` columns.
pub fn upright(acc: &[i16], sw: usize, h: usize, w: usize, flip: bool) -> Array2<f32> {
    let k = 1.0 / f32::from(SCALE);
    Array2::from_shape_fn((h, w), |(r, c)| {
        let sr = if flip { h - 1 - r } else { r };
        f32::from(acc[sr * sw + c]) * k
    })
}
