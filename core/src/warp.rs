//! Frames of warped events: each innovation event ([`crate::light`]) is
//! added where a steady flow carries it at the frame's centre time, so a
//! particle that moves with the flow piles its spikes up where it is at
//! that time instead of smearing them along its path. Scatter, not
//! gather: the cost is per event, and an event needs only the flow at its
//! own pixel — no spike history is read back.
//!
//! The flow is a grid of nodes ([`Flow`]: the host's PIV grid), each with
//! a velocity `v` (Q12, 1/4096 px per tick) and the acceleration along
//! the path `a = (v·∇)v` (Q16, 1/65536 px per tick²), both bilinear
//! between nodes (linear one node step beyond the outer ones, constant
//! past that). An event at pixel `p` and tick `t` (taken at `t + ½`) goes
//! to `p + d·v(p) + ½·d²·a(p)`, `d = c − t − ½` ticks before the frame's
//! centre `c` — the path through the steady flow to second order, which
//! follows a vortex round its turn — rounded to the nearest pixel (halves
//! up). Events carried out of the image are lost. Without a flow
//! ([`Flow::still`]) every event stays on its pixel: the plain frame.
//!
//! A frame's samples are `i16` in 1/[`SCALE`] spike (saturating): an event
//! adds `±SCALE`; [`subtract_rates`] takes off the static rate of the
//! pixels that predict by their rate.
//!
//! Rounding, the one definition both this module and the host's `f64`
//! reference use: with the bilinear weights in 1/16 px exact, the
//! displacement `D = (d2·V·64 + d2²·A) / (2^19·W)` (`d2 = 2d`, `V`, `A`
//! the weighted sums of the nodes' Q12 and Q16 values, `W` the sum of the
//! weights) is rounded as `⌊(D·2^19·W + 2^18·W) / (2^19·W)⌋`.

use crate::error::{Error, ParamError};
use crate::light::Event;

/// Samples per spike of a warped frame.
pub const SCALE: i16 = 64;

/// Largest node pitch, 1/16 px (256 px).
pub const MAX_PITCH: u16 = 4096;

/// Largest `|d2|` the displacement takes, half ticks (events farther than
/// 512 ticks from a frame's centre are not its).
pub const MAX_D2: i32 = 1024;

/// A steady flow on a grid of nodes: node `(r, c)` at `(x0 + c·pitch,
/// y0 + r·pitch)`, coordinates in 1/16 px of the stored row order with
/// pixel centres on whole pixels (x right, y down the stored rows).
#[derive(Debug, Clone, Copy)]
pub struct Flow<'a> {
    /// Nodes across (≥ 1).
    pub nx: u16,
    /// Nodes down (≥ 1).
    pub ny: u16,
    /// x of column 0, 1/16 px.
    pub x0: i32,
    /// y of row 0, 1/16 px.
    pub y0: i32,
    /// Node spacing, 1/16 px (16..=[`MAX_PITCH`]).
    pub pitch: u16,
    /// x velocity per node, Q12 px/tick, `ny × nx` row-major.
    pub vx: &'a [i16],
    /// y velocity, as `vx`.
    pub vy: &'a [i16],
    /// x acceleration along the path, Q16 px/tick², as `vx`.
    pub ax: &'a [i16],
    /// y acceleration, as `vx`.
    pub ay: &'a [i16],
}

impl Flow<'static> {
    /// No motion: every event stays on its pixel.
    ///
    /// ```
    /// let f = spiv_core::warp::Flow::still();
    /// assert!(f.is_still() && f.check().is_ok());
    /// ```
    pub const fn still() -> Flow<'static> {
        Flow {
            nx: 0,
            ny: 0,
            x0: 0,
            y0: 0,
            pitch: 16,
            vx: &[],
            vy: &[],
            ax: &[],
            ay: &[],
        }
    }
}

impl Flow<'_> {
    /// Whether this is [`Flow::still`].
    pub fn is_still(&self) -> bool {
        self.nx == 0 || self.ny == 0
    }

    /// Checks the layout: a still flow, or `nx, ny ≥ 1`, a pitch in
    /// `16..=MAX_PITCH` and every slice `nx·ny` long.
    pub fn check(&self) -> Result<(), Error> {
        if self.is_still() {
            return Ok(());
        }
        let n = usize::from(self.nx) * usize::from(self.ny);
        let ok = (16..=MAX_PITCH).contains(&self.pitch)
            && [self.vx.len(), self.vy.len(), self.ax.len(), self.ay.len()]
                .iter()
                .all(|&l| l == n)
            && self.x0.unsigned_abs() < 1 << 24
            && self.y0.unsigned_abs() < 1 << 24;
        if ok {
            Ok(())
        } else {
            Err(Error::BadParam(ParamError::Motion))
        }
    }

    /// The two nodes and the weight (1/16 px, of `pitch`) of the upper
    /// one along one axis for coordinate `p` (whole px): linear between
    /// nodes and one node step beyond the outer ones, constant past that.
    #[inline]
    fn axis(p: i32, first: i32, pitch: i32, n: u16) -> (usize, usize, i32) {
        if n < 2 {
            return (0, 0, 0);
        }
        let x = (p * 16 - first).clamp(-pitch, i32::from(n) * pitch);
        let i = x.div_euclid(pitch).clamp(0, i32::from(n) - 2);
        (i as usize, i as usize + 1, x - i * pitch)
    }

    /// The displacement of an event at pixel `(x, y)` carried `d2` half
    /// ticks forward in time (negative: backward), whole px.
    #[inline]
    pub fn displacement(&self, x: u16, y: u16, d2: i32) -> (i32, i32) {
        if self.is_still() || d2 == 0 {
            return (0, 0);
        }
        let d2 = i64::from(d2.clamp(-MAX_D2, MAX_D2));
        let pitch = i32::from(self.pitch);
        let (c0, c1, fx) = Self::axis(i32::from(x), self.x0, pitch, self.nx);
        let (r0, r1, fy) = Self::axis(i32::from(y), self.y0, pitch, self.ny);
        let nx = usize::from(self.nx);
        // Weights: (pitch − f, f) along each axis, or (pitch, 0) for a
        // single node; their product sums to pitch² (or pitch, pitch²).
        let (wx0, wx1) = if self.nx < 2 {
            (pitch, 0)
        } else {
            (pitch - fx, fx)
        };
        let (wy0, wy1) = if self.ny < 2 {
            (pitch, 0)
        } else {
            (pitch - fy, fy)
        };
        let taps = [
            (r0 * nx + c0, wy0 * wx0),
            (r0 * nx + c1, wy0 * wx1),
            (r1 * nx + c0, wy1 * wx0),
            (r1 * nx + c1, wy1 * wx1),
        ];
        let w = i64::from(pitch) * i64::from(pitch);
        let sum = |f: &[i16]| -> i64 {
            taps.iter()
                .map(|&(k, wt)| i64::from(f.get(k).copied().unwrap_or(0)) * i64::from(wt))
                .sum()
        };
        let den = w << 19;
        let half = w << 18;
        let d = |v: &[i16], a: &[i16]| -> i32 {
            let num = d2 * sum(v) * 64 + d2 * d2 * sum(a);
            (num + half).div_euclid(den).clamp(-32768, 32767) as i32
        };
        (d(self.vx, self.ax), d(self.vy, self.ay))
    }
}

/// One frame's ticks and centre: the events of ticks `start..start + len`
/// go where the flow carries them at the centre, `centre2` half ticks
/// (`2·start + len`: the window's middle).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Window {
    /// First tick.
    pub start: u32,
    /// Ticks.
    pub len: u32,
    /// Centre, half ticks.
    pub centre2: i64,
}

impl Window {
    /// The window of `len` ticks from `start`, centred on its middle.
    pub const fn new(start: u32, len: u32) -> Window {
        Window {
            start,
            len,
            centre2: 2 * start as i64 + len as i64,
        }
    }

    /// Whether `tick` is one of the window's.
    #[inline]
    pub fn holds(&self, tick: u32) -> bool {
        tick >= self.start && tick - self.start < self.len
    }
}

/// Adds `event` to `frame` (`width × height` samples, stored row-major)
/// where `flow` carries it at `window`'s centre, if its tick is the
/// window's and it lands in the image.
#[inline]
pub fn scatter(
    frame: &mut [i16],
    width: u16,
    height: u16,
    flow: &Flow<'_>,
    window: &Window,
    event: Event,
) {
    if !window.holds(event.tick) {
        return;
    }
    let w = u32::from(width);
    if w == 0 {
        return;
    }
    let (y, x) = ((event.index / w) as u16, (event.index % w) as u16);
    let d2 = window.centre2 - (2 * i64::from(event.tick) + 1);
    let d2 = d2.clamp(-i64::from(MAX_D2), i64::from(MAX_D2)) as i32;
    let (dx, dy) = flow.displacement(x, y, d2);
    let (tx, ty) = (i32::from(x) + dx, i32::from(y) + dy);
    if tx < 0 || ty < 0 || tx >= i32::from(width) || ty >= i32::from(height) {
        return;
    }
    let k = ty as usize * usize::from(width) + tx as usize;
    if let Some(s) = frame.get_mut(k) {
        *s = s.saturating_add(SCALE * i16::from(event.sign));
    }
}

/// Ticks of one block of [`subtract_rates`]: a pixel's static rate over a
/// block is taken off where the flow carries the block's middle tick.
pub const RATE_BLOCK: u32 = 8;

/// Takes off `frame` the static light that the events of the
/// rate-predicted pixels do not carry: each such pixel's rate
/// (`rate(i)`, Q16 spikes per tick; 0 for the others) over each block of
/// [`RATE_BLOCK`] ticks of `window`, in 1/[`SCALE`] spike, where `flow`
/// carries the pixel at the block's middle — the same path its spikes
/// take ([`scatter`]), so static light warped along the flow cancels.
pub fn subtract_rates(
    frame: &mut [i16],
    width: u16,
    height: u16,
    flow: &Flow<'_>,
    window: &Window,
    rate: impl Fn(usize) -> u16,
) {
    let w = usize::from(width);
    let px = w * usize::from(height);
    let blocks = window.len.div_ceil(RATE_BLOCK);
    for i in 0..px.min(frame.len()) {
        let r = rate(i);
        if r == 0 {
            continue;
        }
        let (x, y) = ((i % w) as u16, (i / w) as u16);
        for b in 0..blocks {
            let a = b * RATE_BLOCK;
            let n = RATE_BLOCK.min(window.len - a);
            // The block's middle, half ticks: start + a + n/2.
            let mid2 = 2 * (i64::from(window.start) + i64::from(a)) + i64::from(n);
            let d2 = (window.centre2 - mid2).clamp(-i64::from(MAX_D2), i64::from(MAX_D2)) as i32;
            let (dx, dy) = flow.displacement(x, y, d2);
            let (tx, ty) = (i32::from(x) + dx, i32::from(y) + dy);
            if tx < 0 || ty < 0 || tx >= i32::from(width) || ty >= i32::from(height) {
                continue;
            }
            let k = ty as usize * w + tx as usize;
            if let Some(s) = frame.get_mut(k) {
                *s = s.saturating_sub(rate_samples(r, n));
            }
        }
    }
}

/// `len` ticks of a rate of `q16` (1/65536 spike per tick) in 1/[`SCALE`]
/// spike, rounded half up, at most `i16::MAX`.
#[inline]
pub fn rate_samples(q16: u16, len: u32) -> i16 {
    let x = (u64::from(q16) * u64::from(len) * SCALE as u64 + (1 << 15)) >> 16;
    x.min(i16::MAX as u64) as i16
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flow_of<'a>(v: &'a [[i16; 4]; 4], n: (u16, u16)) -> Flow<'a> {
        Flow {
            nx: n.0,
            ny: n.1,
            x0: 8 * 16,
            y0: 8 * 16,
            pitch: 16 * 16,
            vx: &v[0][..usize::from(n.0 * n.1)],
            vy: &v[1][..usize::from(n.0 * n.1)],
            ax: &v[2][..usize::from(n.0 * n.1)],
            ay: &v[3][..usize::from(n.0 * n.1)],
        }
    }

    #[test]
    fn a_uniform_flow_moves_every_event_alike() {
        // 0.25 px/tick right, 0.5 up: 20 ticks before the centre → 5, −10.
        let v = [[1024; 4], [-2048; 4], [0; 4], [0; 4]];
        let f = flow_of(&v, (2, 2));
        f.check().unwrap();
        for (x, y) in [(0u16, 0u16), (20, 7), (100, 100)] {
            assert_eq!(f.displacement(x, y, 40), (5, -10));
            assert_eq!(f.displacement(x, y, -40), (-5, 10));
        }
        assert_eq!(Flow::still().displacement(3, 3, 99), (0, 0));
    }

    #[test]
    fn bilinear_between_nodes_and_the_second_order_term() {
        // Nodes at x = 8 and 24: vx 0 and 4096 (1 px/tick); at x = 16
        // halfway, 0.5 px/tick: 10 ticks → 5 px.
        let v = [[0, 4096, 0, 4096], [0; 4], [0; 4], [0; 4]];
        let f = flow_of(&v, (2, 2));
        assert_eq!(f.displacement(16, 8, 20), (5, 0));
        // One step beyond the right node (x = 40): extrapolated to 2
        // px/tick; past that (x = 60), constant.
        assert_eq!(f.displacement(40, 8, 20), (20, 0));
        assert_eq!(f.displacement(60, 8, 20), (20, 0));
        // a = 1/64 px/tick² (1024 in Q16), 16 ticks: ½·256/64 = 2 px.
        let acc = [[0; 4], [0; 4], [0; 4], [1024; 4]];
        let f = flow_of(&acc, (2, 2));
        assert_eq!(f.displacement(9, 9, 32), (0, 2));
        assert_eq!(f.displacement(9, 9, -32), (0, 2));
    }

    #[test]
    fn events_land_where_the_flow_carries_them() {
        let v = [[4096; 4], [0; 4], [0; 4], [0; 4]];
        let f = flow_of(&v, (2, 2));
        let w = Window::new(10, 8); // centre 14
        let mut frame = vec![0i16; 32 * 4];
        // Pixel (row 1, col 5) at tick 10 (10.5: 3.5 ticks early) → col 9
        // (5 + 3.5 rounds half up).
        let e = Event {
            index: 32 + 5,
            tick: 10,
            sign: 1,
        };
        scatter(&mut frame, 32, 4, &f, &w, e);
        assert_eq!(frame[32 + 9], SCALE);
        // Outside the window: nothing; carried out of the image: nothing.
        scatter(&mut frame, 32, 4, &f, &w, Event { tick: 18, ..e });
        scatter(
            &mut frame,
            32,
            4,
            &f,
            &w,
            Event {
                index: 32 + 30,
                ..e
            },
        );
        assert_eq!(
            frame.iter().map(|&s| i32::from(s)).sum::<i32>(),
            i32::from(SCALE)
        );
    }

    #[test]
    fn layouts_are_checked() {
        let v = [[0; 4], [0; 4], [0; 4], [0; 4]];
        let mut f = flow_of(&v, (2, 2));
        f.pitch = 8;
        assert!(f.check().is_err());
        let mut f = flow_of(&v, (2, 2));
        f.vx = &v[0][..3];
        assert!(f.check().is_err());
        assert!(Flow::still().check().is_ok());
    }

    #[test]
    fn rates_round_half_up() {
        // 1/8 spike per tick for 20 ticks: 2.5 spikes = 160 samples.
        assert_eq!(rate_samples(8192, 20), 160);
        assert_eq!(rate_samples(u16::MAX, 1 << 20), i16::MAX);
    }
}
