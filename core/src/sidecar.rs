//! The sidecar loop: spike planes in, one by one, into the history ring; at
//! the scheduled ticks (docs/spec.md §8: pairs `(k, k + dt)`, one pair every
//! `every` ticks) a frame through the core — adaptive, TFP or TFI — sent by
//! the [`Sender`] (tiles coded by [`crate::wire::codec`], framed by
//! [`crate::wire`]) into the caller's [`Link`]; now and then a status.
//!
//! This is the one loop of spiv: the simulated firmware
//! (`spiv-firmware-sim`) and the Cortex-M4 firmware both call it, so they put
//! the same bytes on the wire. It holds no buffers: every call borrows the
//! caller's [`Memory`] (static arrays on a device; the owned
//! `buffers::SidecarBuf` behind the `std` feature on a host), so the loop
//! state itself is a few dozen bytes.
//!
//! A [`Probe`] sees each stage begin and end and every frame as it was sent:
//! the M4 firmware brackets its cost markers with it, the simulator keeps
//! copies of frames; `()` is the probe that does nothing (and costs nothing).

use crate::downlink::{Downlink, DownlinkBuffers, DownlinkStats, Fit};
use crate::error::{ConfigError, Error, LinkError};
use crate::frame::{reconstruct_adaptive, reconstruct_compensated, reconstruct_rows};
use crate::gray::Gray;
use crate::history::History;
use crate::method::Method;
use crate::motion::{refine, Motion, Refine};
use crate::params::Params;
use crate::plane::PlaneView;
use crate::state::{Workspace, WorkspaceSizes};
use crate::window::{tfi, tfp};
use crate::wire::codec::{tile_scratch, Lossy};
use crate::wire::sender::{tile_rows, FrameInfo, Link, Schedule, SendBuffers, Sender, Sent, Slot};
use crate::wire::Encoding;

/// Rows per band of the optional window caps (upright rows, top first).
pub const CAP_BAND: u16 = 32;

/// What the sidecar does.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Core parameters (`n_max` is the adaptive and TFI window limit, ticks).
    pub params: Params,
    /// How frames are made.
    pub method: Method,
    /// The TFP window, ticks (`1..=255`; TFP only).
    pub tfp_window: u16,
    /// When frames are made.
    pub schedule: Schedule,
    /// Tile coding wanted (lossless fallbacks apply, see
    /// [`crate::wire::codec::encode_tile`]).
    pub encoding: Encoding,
    /// Lossy settings.
    pub lossy: Lossy,
    /// Send a status message every this many pairs (0: only at the end).
    pub status_every: u32,
    /// [`Method::Mc`]: refine the predicted motion from the spikes before
    /// each frame (contrast maximisation, `crate::motion::refine`).
    pub refine: Option<Refine>,
    /// [`Method::Mc`]: how frames are made while no motion was heard —
    /// [`Method::Tfp`] (the default: short windows do not streak, so the
    /// host's PIV of them gives the first prediction) or
    /// [`Method::Adaptive`] (the paper's; at `n_max` = 128 fast particles
    /// streak and PIV of those frames measures nothing to predict from).
    pub bootstrap: Method,
}

impl Config {
    /// The defaults for a pair `dt` ticks apart whose first frame is at
    /// `first`: adaptive, lossless Rice, one pair every `4·dt` ticks, until
    /// the input ends, a status every 16 pairs.
    pub fn new(first: u32, dt: u32) -> Config {
        Config {
            params: Params::default(),
            method: Method::Adaptive,
            tfp_window: 8,
            schedule: Schedule {
                first,
                dt,
                every: dt.saturating_mul(4),
                pairs: None,
            },
            encoding: Encoding::Rice,
            lossy: Lossy::default(),
            status_every: 16,
            refine: None,
            bootstrap: Method::Tfp,
        }
    }

    /// The window a frame needs, ticks: `n_max` for adaptive and TFI, the
    /// TFP window for TFP, the larger of both for motion-compensated frames
    /// bootstrapped by TFP.
    pub fn window(&self) -> u16 {
        match self.method {
            Method::Tfp => self.tfp_window,
            Method::Mc if self.bootstrap == Method::Tfp => self.params.n_max.max(self.tfp_window),
            Method::Adaptive | Method::Tfi | Method::Mc | Method::Ladder => self.params.n_max,
        }
    }

    /// Spike planes the history must hold (at least 2).
    pub fn depth(&self) -> u16 {
        self.window().max(self.params.n_max).max(2)
    }

    /// Ticks a stream needs for `pairs` pairs of this schedule (the last
    /// frame's window included).
    pub fn ticks_for(&self, pairs: u32) -> u32 {
        let window = self.window();
        let ahead = u32::from(window - window / 2);
        let s = &self.schedule;
        s.first
            .saturating_add(pairs.saturating_sub(1).saturating_mul(s.every))
            .saturating_add(s.dt)
            .saturating_add(ahead)
    }
}

/// The buffers a sidecar running a [`Config`] needs, in elements: the one
/// place that decides which [`Memory`] buffers a configuration uses (the
/// owned `buffers::SidecarBuf` and the C ABI's caller-supplied block are
/// both sized by it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemorySizes {
    /// The workspace: one region per 16 px for [`Method::Mc`], else per 64.
    pub workspace: WorkspaceSizes,
    /// History depth, planes ([`Config::depth`]).
    pub depth: u16,
    /// `u64` words of the history.
    pub history_words: usize,
    /// Samples of the frame (`width × height`).
    pub frame: usize,
    /// Frames of 16-bit samples (`full_scale` above 255).
    pub wide: bool,
    /// Motion-compensated counts (`workspace` pixels for [`Method::Mc`]).
    pub motion_counts: usize,
    /// TFP counts (`width × height` when TFP frames are made, the MC
    /// bootstrap included).
    pub tfp_counts: usize,
    /// Sparse codec scratch (`u16`; [`Encoding::Sparse`] only).
    pub codec_scratch: usize,
    /// Entries of the downlink's velocity buffers (each of four): one per
    /// stored row and 64-px word, the finest motion grid a control may
    /// carry ([`crate::motion::Motion`]).
    pub motion_entries: usize,
    /// Bands of the downlink's caps (each of two).
    pub cap_bands: usize,
    /// Refined velocities (each of two; with [`Config::refine`]).
    pub refined: usize,
}

impl Config {
    /// The buffers this configuration needs on a `width × height` sensor,
    /// or `None` when a size overflows.
    pub fn memory_sizes(&self, width: u16, height: u16) -> Option<MemorySizes> {
        let px = usize::from(width).checked_mul(usize::from(height))?;
        let mc = self.method == Method::Mc;
        let rows = crate::state::strip_rows(width, height, self.params.margin);
        let workspace = if mc {
            WorkspaceSizes::for_motion(width, rows)
        } else {
            WorkspaceSizes::for_strip(width, rows)
        };
        let depth = self.depth();
        let wide = self.params.full_scale > 255;
        let tfp = self.method == Method::Tfp || (mc && self.bootstrap == Method::Tfp);
        let rows = tile_rows(width, height, wide, self.lossy.block);
        let codec_scratch = tile_scratch(self.encoding, width, rows, self.lossy.block);
        let grid = usize::from(height).checked_mul(crate::plane::words_per_row(width))?;
        let refined = match self.refine {
            Some(_) => grid,
            None => 0,
        };
        Some(MemorySizes {
            workspace,
            depth,
            history_words: History::words_needed(width, height, depth)?,
            frame: px,
            wide,
            motion_counts: if mc { workspace.pixels() } else { 0 },
            tfp_counts: if tfp { px } else { 0 },
            codec_scratch,
            motion_entries: grid,
            cap_bands: usize::from(height.div_ceil(CAP_BAND)),
            refined,
        })
    }
}

/// The memory the loop works in, borrowed for one call.
#[derive(Debug)]
pub struct Memory<'a, G: Gray> {
    /// The spike history over the whole camera, [`Config::depth`] planes
    /// deep, as it stood after the previous call ([`Sidecar::next_tick`]).
    pub history: History<'a>,
    /// Per-pixel state of the adaptive frame (unused by TFP and TFI).
    pub workspace: Workspace<'a>,
    /// One frame, `width × height` samples.
    pub frame: &'a mut [G],
    /// TFP's window counts, `width × height` (empty unless TFP).
    pub counts: &'a mut [u8],
    /// The sender's payload, COBS and codec buffers.
    pub send: SendBuffers<'a>,
    /// What the host told the sidecar ([`crate::downlink`]): the predicted
    /// velocity of each stored row for [`Method::Mc`] frames (the workspace
    /// then needs its motion counts), the window caps per band of
    /// [`CAP_BAND`] upright rows for adaptive ones ([`capped_frame`]).
    /// [`DownlinkBuffers::none`]: the sidecar does not listen and runs the
    /// paper's algorithm.
    pub downlink: DownlinkBuffers<'a>,
    /// With [`Config::refine`]: where the refined velocities go (one per
    /// band row and tile column each).
    pub refine: RefineBuffers<'a>,
}

/// The refinement's buffers (empty when [`Config::refine`] is `None`).
#[derive(Debug)]
pub struct RefineBuffers<'a> {
    /// Refined x velocities, laid out as the motion's (band rows × tile
    /// columns; [`MemorySizes::refined`] holds the finest grid).
    pub vx: &'a mut [i16],
    /// Refined y velocities, as `vx`.
    pub vy: &'a mut [i16],
}

impl RefineBuffers<'_> {
    /// No refinement.
    pub fn none() -> Self {
        RefineBuffers {
            vx: &mut [],
            vy: &mut [],
        }
    }
}

/// A stage of the loop, for a [`Probe`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Stage {
    /// One plane into the history.
    Ingest,
    /// One frame through the core.
    Frame,
    /// One frame coded, framed and handed to the link.
    Send,
}

/// Sees the loop work. Every method does nothing by default.
pub trait Probe<G> {
    /// A stage begins.
    #[inline(always)]
    fn enter(&mut self, _stage: Stage) {}
    /// A stage ends.
    #[inline(always)]
    fn leave(&mut self, _stage: Stage) {}
    /// Frame `frame_id` of `slot` was sent; `frame` holds exactly what a
    /// receiver decodes (stored row order).
    #[inline(always)]
    fn sent(&mut self, _frame_id: u32, _slot: Slot, _frame: &[G]) {}
}

/// The probe that sees nothing.
impl<G> Probe<G> for () {}

/// The loop's state: where the schedule stands and what was sent. No
/// buffers.
#[derive(Debug, Clone)]
pub struct Sidecar {
    cfg: Config,
    sender: Sender,
    next: u64,
    next_tick: u32,
    downlink: Downlink,
    width: u16,
    height: u16,
}

impl Sidecar {
    /// The loop for a `width × height` sensor; checks the configuration.
    pub fn new(width: u16, height: u16, cfg: Config) -> Result<Sidecar, Error> {
        for m in [cfg.method, cfg.bootstrap] {
            if m == Method::Ladder {
                return Err(Error::Config(ConfigError::Method(m)));
            }
        }
        let window = cfg.window();
        // TFI needs two ticks to see an interval.
        let least = if cfg.method == Method::Tfi { 2 } else { 1 };
        if !(least..=255).contains(&window) {
            return Err(Error::Config(ConfigError::Window(window)));
        }
        if cfg.method == Method::Mc
            && cfg.bootstrap == Method::Tfp
            && !(1..=255).contains(&cfg.tfp_window)
        {
            return Err(Error::Config(ConfigError::Window(cfg.tfp_window)));
        }
        let s = &cfg.schedule;
        if s.dt == 0 || s.every < s.dt {
            return Err(Error::Config(ConfigError::Schedule {
                every: s.every,
                dt: s.dt,
            }));
        }
        cfg.params.validate(cfg.depth())?;
        let rows = tile_rows(width, height, cfg.params.full_scale > 255, cfg.lossy.block);
        if rows == 0 {
            return Err(Error::Config(ConfigError::RowTooWide(width)));
        }
        Ok(Sidecar {
            cfg,
            sender: Sender::new(width, height, rows)?,
            next: 0,
            next_tick: 0,
            downlink: Downlink::default(),
            width,
            height,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Rows per tile message.
    pub fn tile_rows(&self) -> u16 {
        self.sender.tile_rows()
    }

    /// What was sent so far.
    pub fn sent(&self) -> Sent {
        self.sender.sent
    }

    /// The tick the next plane gets (a caller that rebuilds its
    /// [`History`] for each call resumes it here).
    pub fn next_tick(&self) -> u32 {
        self.next_tick
    }

    /// The pair whose first frame the next plane completes, if it does
    /// (a driver that paces itself on the host's answers waits here).
    pub fn pair_due(&self) -> Option<u32> {
        let slot = self.cfg.schedule.slot(self.next)?;
        (slot.member == 0 && Schedule::ready(slot.tick, self.cfg.window(), self.next_tick))
            .then_some(slot.pair)
    }

    /// True once every scheduled pair was sent.
    pub fn done(&self) -> bool {
        self.cfg.schedule.slot(self.next).is_none()
    }

    /// Takes bytes from the downlink (the host's control messages, any
    /// chunking; [`crate::downlink`]). A valid control applies from the
    /// start of its pair; anything else is counted and dropped.
    pub fn hear(&mut self, buf: &mut DownlinkBuffers<'_>, bytes: &[u8]) {
        let fit = Fit {
            width: self.width,
            height: self.height,
            n_max: self.cfg.params.n_max,
        };
        self.downlink.hear(buf, fit, bytes);
    }

    /// What the downlink heard so far.
    pub fn downlink(&self) -> DownlinkStats {
        self.downlink.stats()
    }

    /// The status counts of the downlink into the sender's.
    fn sync_downlink(&mut self) {
        let d = self.downlink.stats();
        self.sender.sent.controls_applied = d.applied;
        self.sender.sent.controls_refused = d.refused;
    }

    /// Ingests the next plane (stored row order, `width·height/8` bytes) and
    /// sends every frame whose window it completes.
    pub fn push_plane<G: Gray, L: Link, P: Probe<G>>(
        &mut self,
        mem: &mut Memory<'_, G>,
        plane: &[u8],
        link: &mut L,
        probe: &mut P,
    ) -> Result<(), LinkError<L::Error>> {
        probe.enter(Stage::Ingest);
        let newest = Self::ingest(&mut mem.history, plane)?;
        probe.leave(Stage::Ingest);
        self.next_tick = mem.history.next_tick();
        self.sender.sent.planes = self.sender.sent.planes.wrapping_add(1);
        let window = self.cfg.window();
        while let Some(slot) = self.cfg.schedule.slot(self.next) {
            if !Schedule::ready(slot.tick, window, newest) {
                break;
            }
            self.next += 1;
            if slot.member == 0 {
                self.downlink.start_pair(&mut mem.downlink, slot.pair);
            }
            probe.enter(Stage::Frame);
            let method = self.make_frame(mem, slot.tick)?;
            probe.leave(Stage::Frame);
            let frame_id = self.sender.sent.frames;
            probe.enter(Stage::Send);
            self.send_frame(mem, slot, method, link)?;
            probe.leave(Stage::Send);
            probe.sent(frame_id, slot, mem.frame);
            let every = self.cfg.status_every;
            if slot.member == 1 && every > 0 && (slot.pair + 1) % every == 0 {
                self.sync_downlink();
                self.sender.send_status(&mut mem.send, link)?;
            }
        }
        Ok(())
    }

    /// Sends the final status; returns the counts.
    pub fn finish<L: Link>(
        &mut self,
        send: &mut SendBuffers<'_>,
        link: &mut L,
    ) -> Result<Sent, LinkError<L::Error>> {
        self.sync_downlink();
        self.sender.send_status(send, link)?;
        Ok(self.sender.sent)
    }

    // The three stages stay out of line (one call per plane or frame, a
    // few instructions) so instruction counters — callgrind on the host,
    // QEMU's trace on the Cortex-M4 — can attribute cost to each stage.

    #[inline(never)]
    fn ingest(history: &mut History<'_>, plane: &[u8]) -> Result<u32, Error> {
        history.push(&PlaneView::new(plane, history.width(), history.height())?)
    }

    /// Makes the frame at `k` with what the downlink applied; returns the
    /// method it used ([`make_frame`]).
    #[inline(never)]
    fn make_frame<G: Gray>(&self, mem: &mut Memory<'_, G>, k: u32) -> Result<Method, Error> {
        let dl = &mem.downlink;
        let guide = Guide {
            n_max: self.downlink.n_max(),
            caps: self.downlink.caps(dl),
            motion: self.downlink.motion(dl),
        };
        make_frame(
            &self.cfg,
            k,
            &guide,
            &mem.history,
            FrameBuffers {
                workspace: &mut mem.workspace,
                counts: mem.counts,
                refine: &mut mem.refine,
                frame: mem.frame,
            },
        )
    }

    #[inline(never)]
    fn send_frame<G: Gray, L: Link>(
        &mut self,
        mem: &mut Memory<'_, G>,
        slot: Slot,
        method: Method,
        link: &mut L,
    ) -> Result<(), LinkError<L::Error>> {
        let info = FrameInfo {
            slot,
            method,
            full_scale: self.cfg.params.full_scale,
            dt: self.cfg.schedule.dt,
        };
        self.sender.send_frame(
            &mut mem.send,
            mem.frame,
            &info,
            self.cfg.encoding,
            &self.cfg.lossy,
            link,
        )
    }
}

/// What a frame is made with besides the spikes: the host's word
/// ([`crate::downlink`] applies it in the loop; a firmware that schedules
/// its own frames passes it here).
#[derive(Debug, Clone, Copy, Default)]
pub struct Guide<'m> {
    /// A window limit below [`Params::n_max`] (ticks).
    pub n_max: Option<u16>,
    /// Window caps per band of [`CAP_BAND`] upright rows, ticks (empty:
    /// none; adaptive frames only).
    pub caps: &'m [u16],
    /// Predicted velocity of each stored row and tile column
    /// ([`Method::Mc`] frames; `None`: the frame is made by
    /// [`Config::bootstrap`]).
    pub motion: Option<Motion<'m>>,
}

/// The buffers one frame is made in (borrowed from a [`Memory`]).
#[derive(Debug)]
pub struct FrameBuffers<'m, 'a, G> {
    /// Per-pixel state of the adaptive frame (with motion counts for
    /// [`Method::Mc`]).
    pub workspace: &'m mut Workspace<'a>,
    /// TFP's window counts (`width × height`; empty unless TFP is used).
    pub counts: &'m mut [u8],
    /// With [`Config::refine`]: the refined velocities.
    pub refine: &'m mut RefineBuffers<'a>,
    /// The frame, `width × height` samples, stored row order.
    pub frame: &'m mut [G],
}

/// Makes the frame centred at tick `k` of `hist` by `cfg`'s method, guided by
/// `guide`; returns the method it used: an [`Method::Mc`] frame without a
/// motion is made by [`Config::bootstrap`] (adaptive with the caps, if
/// any). The one frame maker of the loop, public for firmware that
/// schedules frames itself (the C ABI's `spiv_make_frame`).
pub fn make_frame<G: Gray>(
    cfg: &Config,
    k: u32,
    guide: &Guide<'_>,
    hist: &History<'_>,
    mem: FrameBuffers<'_, '_, G>,
) -> Result<Method, Error> {
    let mut p = cfg.params;
    if let Some(n) = guide.n_max {
        p.n_max = n.min(p.n_max);
        p.n0 = p.n0.min(p.n_max);
    }
    let p = &p;
    let caps = guide.caps;
    let method = match (cfg.method, guide.motion) {
        (Method::Mc, None) => match cfg.bootstrap {
            Method::Mc => Method::Adaptive,
            b => b,
        },
        (m, _) => m,
    };
    match (method, guide.motion) {
        (Method::Ladder, _) => Err(Error::BadParam(crate::error::ParamError::Method)),
        (Method::Tfp, _) => {
            tfp(hist, k, cfg.tfp_window, p.full_scale, mem.counts, mem.frame)?;
            Ok(Method::Tfp)
        }
        (Method::Tfi, _) => {
            tfi(hist, k, p.n_max, p.full_scale, mem.frame)?;
            Ok(Method::Tfi)
        }
        (Method::Mc, Some(motion)) => {
            if !motion.covers(hist.rows()) {
                return Err(Error::BufferTooSmall {
                    needed: Motion::entries(hist.rows(), motion.cols),
                    got: motion.vx.len().min(motion.vy.len()),
                });
            }
            let m = match &cfg.refine {
                None => motion,
                Some(rc) => {
                    let r = mem.refine;
                    refine(hist, k, &motion, rc, r.vx, r.vy)?;
                    Motion {
                        vx: r.vx,
                        vy: r.vy,
                        ..motion
                    }
                }
            };
            reconstruct_compensated(hist, k, p, mem.workspace, (0, hist.rows()), &m, mem.frame)?;
            Ok(Method::Mc)
        }
        (Method::Adaptive | Method::Mc, _) => {
            if caps.is_empty() {
                reconstruct_adaptive(hist, k, p, mem.workspace, mem.frame)?;
            } else {
                capped_frame(hist, k, p, caps, mem.workspace, mem.frame)?;
            }
            Ok(Method::Adaptive)
        }
    }
}

/// The adaptive frame at `k` with a window limit per band of [`CAP_BAND`]
/// upright rows (`caps[0]` the top band; missing entries: `p.n_max`; each
/// clamped to `1..=p.n_max`): each band is reconstructed once, with its own
/// limit and a margin of `p.margin` rows ([`reconstruct_rows`]). The one
/// implementation of the dwell cap, for the sidecar and the host. Returns
/// the labelling's counts summed over the bands (saturating), so that
/// what full tables lost is reported.
pub fn capped_frame<G: Gray>(
    hist: &History<'_>,
    k: u32,
    p: &Params,
    caps: &[u16],
    ws: &mut Workspace<'_>,
    out: &mut [G],
) -> Result<crate::label::LabelStats, Error> {
    p.validate(hist.depth())?;
    let mut labels = crate::label::LabelStats::default();
    let h = hist.rows();
    for b in 0..h.div_ceil(CAP_BAND) {
        let cap = caps.get(usize::from(b)).copied().unwrap_or(p.n_max);
        let n_max = cap.min(p.n_max).max(1);
        // A cap below n0 starts the segmentation at the cap itself.
        let q = Params {
            n_max,
            n0: p.n0.min(n_max),
            ..*p
        };
        // Upright band b is stored rows h − 32(b+1) .. h − 32b (bottom-up).
        let e1 = h - b * CAP_BAND;
        let e0 = e1.saturating_sub(CAP_BAND);
        let l = reconstruct_rows(hist, k, &q, ws, (e0, e1), out)?.labels;
        labels.regions = labels.regions.saturating_add(l.regions);
        labels.noise_regions = labels.noise_regions.saturating_add(l.noise_regions);
        labels.overflow_regions = labels.overflow_regions.saturating_add(l.overflow_regions);
        labels.dropped_pixels = labels.dropped_pixels.saturating_add(l.dropped_pixels);
    }
    Ok(labels)
}
