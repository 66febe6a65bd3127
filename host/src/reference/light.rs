//! The `f64` reference of the core's static-light model, its innovation
//! events and its warped frames ([`spiv_core::light`],
//! [`spiv_core::warp`], [`spiv_core::rungs`]), written for clarity: one
//! pixel at a time over an unpacked spike volume, the period and the
//! agreements in whole numbers as the core keeps them, the mean rate and
//! every displacement in `f64`.
//!
//! **Tolerance** (held by `host/tests/light_parity.rs`): the events
//! identical; each pixel's mean rate within 2⁻¹² spike per tick of the
//! reference's (the core divides in integers each tick); each warped
//! event on the reference's pixel but where the reference's unrounded
//! displacement lies within 10⁻⁹ px of a half (the core rounds the exact
//! rational once); each frame sample within 1/64 spike per rate block of
//! the reference's unrounded value.

use super::SpikeVolume;
use spiv_core::light::{
    early_tolerance, tolerance, CONFIDENT, LEAD, LEAD_LEAK, LEAD_PERIOD, MAX_CONFIDENCE,
    MAX_PERIOD, RATE_TICKS, RELEARN_TICKS, SETTLED_SHIFT,
};

/// One pixel's model, in the reference's terms.
#[derive(Debug, Clone, Copy, Default)]
struct Pixel {
    spiked: bool,
    last: i64,
    /// Period, 1/16 tick.
    period: i32,
    count: u8,
    /// Ticks of short intervals since the last agreeing one.
    short: u32,
    /// Lead on the period chain, 1/16 tick.
    lead: i32,
    /// Mean rate, spikes per tick.
    rate: f64,
}

/// An event: pixel index, tick, sign (+1 unpredicted spike, −1 missed
/// prediction).
pub type Event = (u32, u32, i8);

/// What [`events`] gives: the events, each pixel's mean rate (spikes per
/// tick) and whether it ended periodic.
pub type Events = (Vec<Event>, Vec<f64>, Vec<bool>);

/// Every event of `vol` in tick order (ticks of the volume, the first
/// `first`), and each pixel's mean rate and periodicity after the last
/// tick.
pub fn events(vol: &SpikeVolume) -> Events {
    let px = vol.width * vol.rows;
    let mut pixels = vec![Pixel::default(); px];
    let mut out = Vec::new();
    for t in 0..vol.ticks {
        let tick = i64::from(vol.first) + t as i64;
        let k = ((t + 1) as f64).min(f64::from(RATE_TICKS));
        for (i, p) in pixels.iter_mut().enumerate() {
            let s = vol.data[t * px + i] == 1;
            p.rate += (f64::from(u8::from(s)) - p.rate) / k;
            if !s && !p.spiked {
                continue;
            }
            let since = tick - p.last;
            let per = ((p.period >> 4) as i64).max(1);
            let late = i64::from(tolerance(per as u16));
            let early = i64::from(early_tolerance(per as u16));
            let periodic = p.spiked && p.count >= CONFIDENT;
            if s {
                let in_window = periodic && since + early >= per && since <= per + late;
                let extra = if in_window && per >= i64::from(LEAD_PERIOD) {
                    p.lead = 0;
                    false
                } else if in_window {
                    // The lead on the period chain gains the deviation,
                    // leaks an eighth (floored), and gives a period back
                    // past a tick and a half (and the early tolerance)
                    // ahead.
                    let mut lead = p.lead + (since * 16) as i32 - p.period;
                    lead -= (f64::from(lead) / f64::from(1u32 << LEAD_LEAK)).floor() as i32;
                    let extra = lead < -(LEAD + 16 * early as i32);
                    if extra {
                        lead += p.period;
                    }
                    p.lead = lead.clamp(-128, 127);
                    extra
                } else {
                    p.lead = 0;
                    true
                };
                if extra {
                    out.push((i as u32, tick as u32, 1));
                }
                if p.spiked {
                    learn(p, since, tick as u16);
                }
                p.last = tick;
                p.spiked = true;
            } else if periodic && since == per + late {
                out.push((i as u32, (tick - late) as u32, -1));
                p.count -= 1;
            }
        }
    }
    // The core hands −1 events over when it settles them; in tick order
    // they come back by their own ticks, as the core's ring gives them.
    out.sort_by_key(|&(i, t, _)| (t, i));
    let rates = pixels.iter().map(|p| p.rate).collect();
    let periodic = pixels
        .iter()
        .map(|p| p.spiked && p.count >= CONFIDENT)
        .collect();
    (out, rates, periodic)
}

fn learn(p: &mut Pixel, since: i64, t: u16) {
    if since > i64::from(MAX_PERIOD) {
        (p.period, p.count, p.short) = (0, 0, 0);
        return;
    }
    if p.count == 0 || p.period == 0 {
        (p.period, p.count, p.short) = ((since * 16) as i32, 1, 0);
        return;
    }
    let iv = (since * 16) as i32;
    let d = iv - p.period;
    let bound = p.period / 5;
    let agrees = if d < 0 {
        -d <= bound.max(16)
    } else {
        d <= bound.max(16)
    };
    if agrees {
        let shift = if p.count >= CONFIDENT {
            // One more halving of the step per halving of the period below
            // 16 ticks.
            let whole = f64::from((p.period >> 4).max(1));
            SETTLED_SHIFT + (4.0 - whole.log2().floor()).max(0.0) as u32
        } else {
            1
        };
        // The core's dither: the top `shift` bits of the tick's
        // multiplicative hash (mod 2^32), added before flooring.
        let hash = (u64::from(t) * 0x9E37_79B9) % (1 << 32);
        let u = (hash >> (32 - shift)) as f64;
        p.period += ((f64::from(d) + u) / f64::from(1u32 << shift)).floor() as i32;
        p.count = (p.count + 1).min(MAX_CONFIDENCE);
        p.short = 0;
    } else if d < 0 && p.short + (since as u32) < u32::from(RELEARN_TICKS) {
        p.short += since as u32;
    } else if d > 0 && p.count > 2 {
        p.count -= 2;
    } else {
        (p.period, p.count, p.short) = (iv, 1, 0);
    }
}

/// A flow on a grid of nodes in `f64` (the core's
/// [`spiv_core::warp::Flow`], values in px per tick and px per tick²).
#[derive(Debug, Clone)]
pub struct NodeFlow {
    /// Nodes across.
    pub nx: usize,
    /// Nodes down.
    pub ny: usize,
    /// Node (0, 0), px.
    pub origin: (f64, f64),
    /// Node spacing, px.
    pub pitch: f64,
    /// `(vx, vy, ax, ay)` per node, row-major.
    pub nodes: Vec<(f64, f64, f64, f64)>,
}

impl NodeFlow {
    /// The core's flow in `f64`.
    pub fn of(f: &spiv_core::warp::Flow<'_>) -> NodeFlow {
        let n = usize::from(f.nx) * usize::from(f.ny);
        NodeFlow {
            nx: usize::from(f.nx),
            ny: usize::from(f.ny),
            origin: (f64::from(f.x0) / 16.0, f64::from(f.y0) / 16.0),
            pitch: f64::from(f.pitch) / 16.0,
            nodes: (0..n)
                .map(|k| {
                    (
                        f64::from(f.vx[k]) / 4096.0,
                        f64::from(f.vy[k]) / 4096.0,
                        f64::from(f.ax[k]) / 65536.0,
                        f64::from(f.ay[k]) / 65536.0,
                    )
                })
                .collect(),
        }
    }

    /// The unrounded displacement of a point at pixel `(x, y)` carried `d`
    /// ticks: `d·v + ½·d²·a`, `v` and `a` bilinear between nodes (linear one
    /// node step beyond the outer ones, constant past that).
    pub fn displacement(&self, x: f64, y: f64, d: f64) -> (f64, f64) {
        if self.nx == 0 || self.ny == 0 {
            return (0.0, 0.0);
        }
        let axis = |p: f64, first: f64, n: usize| -> (usize, usize, f64) {
            if n < 2 {
                return (0, 0, 0.0);
            }
            let q = ((p - first) / self.pitch).clamp(-1.0, n as f64);
            let i = q.floor().clamp(0.0, (n - 2) as f64);
            (i as usize, i as usize + 1, q - i)
        };
        let (c0, c1, fx) = axis(x, self.origin.0, self.nx);
        let (r0, r1, fy) = axis(y, self.origin.1, self.ny);
        let at = |r: usize, c: usize| self.nodes[r * self.nx + c];
        let mix = |f: &dyn Fn((f64, f64, f64, f64)) -> f64| {
            let top = f(at(r0, c0)) * (1.0 - fx) + f(at(r0, c1)) * fx;
            let bot = f(at(r1, c0)) * (1.0 - fx) + f(at(r1, c1)) * fx;
            top * (1.0 - fy) + bot * fy
        };
        let (vx, vy) = (mix(&|n| n.0), mix(&|n| n.1));
        let (ax, ay) = (mix(&|n| n.2), mix(&|n| n.3));
        (d * vx + 0.5 * d * d * ax, d * vy + 0.5 * d * d * ay)
    }
}

/// The floor of a rung of `s` ticks, spikes: `√(s/16)` rounded, at least 1
/// (the core's [`spiv_core::rungs::rung_floor`]).
pub fn floor_of(s: u32) -> f64 {
    (f64::from(s) / 16.0).sqrt().round().max(1.0)
}

/// `frame` (spikes) as the core sends a rung of `s` ticks: each sample
/// rounded to whole spikes (half up), 0 below [`floor_of`]`(s)`.
pub fn floored(frame: &[f64], s: u32) -> Vec<f64> {
    let least = floor_of(s);
    frame
        .iter()
        .map(|&v| {
            let n = (v + 0.5).floor();
            if n >= least {
                n
            } else {
                0.0
            }
        })
        .collect()
}

/// The frame of `events` (index, tick, sign) of ticks `start..start + len`
/// warped to the centre `centre` (ticks; an event of tick `t` taken at
/// `t + ½`) along `flow`, less `rate(i)` (spikes per tick) over each block
/// of [`spiv_core::warp::RATE_BLOCK`] ticks carried from its middle;
/// `width × height`, in spikes, unrounded but for each event's pixel.
pub fn frame(
    events: &[(u32, u32, i8)],
    (width, height): (usize, usize),
    flow: &NodeFlow,
    (start, len, centre): (u32, u32, f64),
    rate: impl Fn(usize) -> f64,
) -> Vec<f64> {
    let mut out = vec![0.0; width * height];
    let mut put = |x: f64, y: f64, v: f64| {
        let (tx, ty) = (x.floor(), y.floor());
        if tx >= 0.0 && ty >= 0.0 && tx < width as f64 && ty < height as f64 {
            out[ty as usize * width + tx as usize] += v;
        }
    };
    for &(index, tick, sign) in events {
        if tick < start || tick - start >= len {
            continue;
        }
        let (x, y) = (
            (index as usize % width) as f64,
            (index as usize / width) as f64,
        );
        let d = centre - (f64::from(tick) + 0.5);
        let (dx, dy) = flow.displacement(x, y, d);
        put(x + dx + 0.5, y + dy + 0.5, f64::from(sign));
    }
    let block = spiv_core::warp::RATE_BLOCK;
    for i in 0..width * height {
        let r = rate(i);
        if r == 0.0 {
            continue;
        }
        let (x, y) = ((i % width) as f64, (i / width) as f64);
        let mut a = 0;
        while a < len {
            let n = block.min(len - a);
            let mid = f64::from(start + a) + f64::from(n) / 2.0;
            let (dx, dy) = flow.displacement(x, y, centre - mid);
            put(x + dx + 0.5, y + dy + 0.5, -r * f64::from(n));
            a += block;
        }
    }
    out
}
