//! The sidecar's ear: control messages from the host
//! ([`crate::wire::control`]) heard on the downlink, checked, held until
//! their pair, then applied — the predicted motion of motion-compensated
//! frames, the window caps of adaptive frames and a lower `n_max`.
//!
//! Bytes arrive in any chunking ([`Downlink::hear`]: the USB OUT endpoint's
//! packets, a TCP socket's reads, a control file); the stream decoder
//! resynchronises after damage like the host's. A chunk that is not a valid
//! control for this sensor — bad COBS or CRC, another kind, another frame
//! size, a malformed payload, an `n_max` above the sidecar's, more rows or
//! caps than its buffers, or a `from_pair` older than one already heard — is
//! counted ([`DownlinkStats::refused`]) and never applied. A valid one waits
//! in the `next_*` buffers (a newer one replaces it) and is applied at the
//! start of the first pair `≥ from_pair` ([`Downlink::start_pair`]), so a
//! pair's two frames always share one control. A sidecar that never hears a
//! control runs the paper's algorithm.
//!
//! Memory: the caller's [`DownlinkBuffers`] — a receive buffer
//! ([`crate::wire::control::MAX_CONTROL_ENCODED`] bytes for every legal
//! control) and two sets of velocities (4 bytes per stored row and tile
//! column each; the finest grid has a column per 64-px word) and caps. The state itself is a few dozen bytes.

use crate::motion::Motion;
use crate::wire::control::ControlView;
use crate::wire::{Decoder, DecoderState, Kind, Message};

/// What the downlink heard.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DownlinkStats {
    /// Valid controls heard (applied, or replaced by a newer one first).
    pub heard: u32,
    /// Controls that took effect.
    pub applied: u32,
    /// Chunks refused (never applied).
    pub refused: u32,
}

/// The downlink's memory, borrowed for one call. Empty slices
/// ([`DownlinkBuffers::none`]): a sidecar that does not listen.
#[derive(Debug)]
pub struct DownlinkBuffers<'a> {
    /// Receive buffer of the stream decoder.
    pub rx: &'a mut [u8],
    /// The applied x velocity of each stored row and tile column
    /// (`rows × cols`), 1/4096 px per tick.
    pub vx: &'a mut [i16],
    /// The applied y velocity of each stored row and tile column (stored
    /// rows, down).
    pub vy: &'a mut [i16],
    /// The applied caps, one per band of [`crate::sidecar::CAP_BAND`]
    /// upright rows.
    pub caps: &'a mut [u16],
    /// The waiting control's x velocities.
    pub next_vx: &'a mut [i16],
    /// The waiting control's y velocities.
    pub next_vy: &'a mut [i16],
    /// The waiting control's caps.
    pub next_caps: &'a mut [u16],
}

impl DownlinkBuffers<'_> {
    /// No downlink.
    pub fn none() -> Self {
        DownlinkBuffers {
            rx: &mut [],
            vx: &mut [],
            vy: &mut [],
            caps: &mut [],
            next_vx: &mut [],
            next_vy: &mut [],
            next_caps: &mut [],
        }
    }
}

/// One control as the sidecar keeps it (its rows and caps in the buffers).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Steer {
    from_pair: u32,
    n_max: u16,
    motion: bool,
    cols: u16,
    tile: u16,
    caps: u16,
}

/// The downlink's state between calls.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Downlink {
    decoder: DecoderState,
    next: Option<Steer>,
    active: Option<Steer>,
    stats: DownlinkStats,
}

/// What a control must fit: the sensor and the sidecar's window limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fit {
    /// Sensor width, px.
    pub width: u16,
    /// Sensor height, px (stored rows).
    pub height: u16,
    /// The sidecar's `n_max`, ticks (a control may only lower it).
    pub n_max: u16,
}

impl Downlink {
    /// The counts so far.
    pub fn stats(&self) -> DownlinkStats {
        self.stats
    }

    /// Takes downlink bytes (any chunking); every control they complete is
    /// checked against `fit` and either waits for its pair or is refused.
    pub fn hear(&mut self, buf: &mut DownlinkBuffers<'_>, fit: Fit, bytes: &[u8]) {
        let DownlinkBuffers {
            rx,
            next_vx,
            next_vy,
            next_caps,
            ..
        } = buf;
        let mut dec = Decoder::resume(rx, self.decoder);
        let mut input = bytes;
        while let Some(r) = dec.feed(&mut input) {
            let ok = match r {
                Ok(m) => self.accept(&m, fit, next_vx, next_vy, next_caps),
                Err(_) => false,
            };
            if ok {
                self.stats.heard = self.stats.heard.wrapping_add(1);
            } else {
                self.stats.refused = self.stats.refused.wrapping_add(1);
            }
        }
        self.decoder = dec.state();
    }

    fn accept(
        &mut self,
        m: &Message<'_>,
        fit: Fit,
        vx: &mut [i16],
        vy: &mut [i16],
        caps: &mut [u16],
    ) -> bool {
        let h = &m.header;
        if h.kind != Kind::Control || h.width != fit.width || h.height != fit.height {
            return false;
        }
        let Ok(c) = ControlView::parse(m.payload) else {
            return false;
        };
        let entries = Motion::entries(fit.height, c.head.cols);
        let newest = self.next.or(self.active).map(|s| s.from_pair);
        if c.head.n_max > fit.n_max
            || (c.nodes() > 0 && (vx.len() < entries || vy.len() < entries))
            || c.caps() > caps.len()
            || newest.is_some_and(|p| c.head.from_pair < p)
        {
            return false;
        }
        if let (Some(x), Some(y)) = (vx.get_mut(..entries), vy.get_mut(..entries)) {
            c.rows_into(x, y);
        }
        for (i, d) in caps.iter_mut().take(c.caps()).enumerate() {
            *d = c.cap(i);
        }
        self.next = Some(Steer {
            from_pair: c.head.from_pair,
            n_max: c.head.n_max,
            motion: c.nodes() > 0,
            cols: c.head.cols,
            tile: c.head.tile,
            caps: c.caps() as u16,
        });
        true
    }

    /// Pair `pair` begins: the waiting control takes effect if it is for
    /// this pair or an earlier one.
    pub fn start_pair(&mut self, buf: &mut DownlinkBuffers<'_>, pair: u32) {
        let Some(n) = self.next else { return };
        if n.from_pair > pair {
            return;
        }
        if n.motion {
            let e = buf.next_vx.len().min(buf.vx.len());
            buf.vx[..e].copy_from_slice(&buf.next_vx[..e]);
            let e = buf.next_vy.len().min(buf.vy.len());
            buf.vy[..e].copy_from_slice(&buf.next_vy[..e]);
        }
        let caps = usize::from(n.caps)
            .min(buf.caps.len())
            .min(buf.next_caps.len());
        buf.caps[..caps].copy_from_slice(&buf.next_caps[..caps]);
        self.active = Some(n);
        self.next = None;
        self.stats.applied = self.stats.applied.wrapping_add(1);
    }

    /// The applied motion, if the applied control has one.
    pub fn motion<'b>(&self, buf: &'b DownlinkBuffers<'_>) -> Option<Motion<'b>> {
        match self.active {
            Some(s) if s.motion => Motion::grid(&*buf.vx, &*buf.vy, s.cols, s.tile).ok(),
            _ => None,
        }
    }

    /// The applied caps (empty: none).
    pub fn caps<'b>(&self, buf: &'b DownlinkBuffers<'_>) -> &'b [u16] {
        let n = self.active.map_or(0, |s| usize::from(s.caps));
        buf.caps.get(..n).unwrap_or(&[])
    }

    /// The applied window limit, if the control set one.
    pub fn n_max(&self) -> Option<u16> {
        self.active.map(|s| s.n_max).filter(|&n| n > 0)
    }
}
