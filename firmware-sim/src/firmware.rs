//! The sidecar firmware loop, simulated: spike planes in, one by one, into
//! the core's history ring; at the scheduled ticks an integrated frame
//! through the core (adaptive or TFP), sent by the core's
//! [`spiv_core::sender`] — bands of rows coded ([`spiv_core::compress`]) and
//! framed ([`spiv_core::wire`]) — into a [`Link`]; the schedule is the
//! core's [`Schedule`], so firmware on a device sends the same bytes. SPEC section 8: pairs `(k, k + dt)`, one pair every `every`
//! ticks (default `4·dt`).
//!
//! Everything per message is bounded: one band of at most 16 KiB payload, one
//! message buffer. The frame buffer is one frame of u16 (a device with a
//! strip workspace would send each strip as it is done).

use spiv_core::compress::{sparse_scratch, Lossy};
use spiv_core::sender::{tile_rows, FrameInfo, Schedule, SendBuffers, SendError, Sender, Slot};
use spiv_core::window::tfp;
use spiv_core::wire::{Encoding, MAX_ENCODED, MAX_PAYLOAD};
use spiv_core::{reconstruct_adaptive, reconstruct_rows, Params, PlaneView};

use crate::buffers::{HistoryBuf, WorkspaceBuf};

/// Rows per band of the optional window caps (upright rows, top first).
pub const CAP_BAND: u16 = 32;

/// How frames are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// The paper's adaptive integration, window limit `Params::n_max`.
    Adaptive,
    /// Spike count over a window of this many ticks.
    Tfp(u16),
}

impl Method {
    fn code(self) -> u8 {
        match self {
            Method::Adaptive => 0,
            Method::Tfp(_) => 1,
        }
    }

    fn window(self, p: &Params) -> u16 {
        match self {
            Method::Adaptive => p.n_max,
            Method::Tfp(n) => n,
        }
    }
}

/// What the firmware does.
#[derive(Debug, Clone)]
pub struct Config {
    /// Core parameters (`n_max` is the adaptive window limit, ticks).
    pub params: Params,
    /// Frame method.
    pub method: Method,
    /// Tick of the first pair's first frame.
    pub first: u32,
    /// Ticks between the frames of a pair (Δt).
    pub dt: u32,
    /// Ticks between pairs (M ≥ Δt).
    pub every: u32,
    /// Stop after this many pairs (`None`: until the input ends).
    pub pairs: Option<u32>,
    /// Tile coding wanted (lossless fallbacks apply, see `encode_tile`).
    pub encoding: Encoding,
    /// Lossy settings.
    pub lossy: Lossy,
    /// Optional adaptive window limit per band of [`CAP_BAND`] upright rows
    /// (top first, the camera's stored rows being bottom-up); empty: `n_max`
    /// everywhere. The host computes them and would send them down the
    /// control endpoint.
    pub caps: Vec<u16>,
    /// Send a status message every this many pairs (0: only at the end).
    pub status_every: u32,
}

impl Config {
    /// The defaults for a pair `dt` ticks apart whose first frame is at
    /// `first`: adaptive, lossless Rice, one pair every `4·dt` ticks.
    pub fn new(first: u32, dt: u32) -> Config {
        Config {
            params: Params::default(),
            method: Method::Adaptive,
            first,
            dt,
            every: 4 * dt,
            pairs: None,
            encoding: Encoding::Rice,
            lossy: Lossy::default(),
            caps: Vec::new(),
            status_every: 16,
        }
    }
}

/// Why the firmware stopped.
#[derive(Debug, thiserror::Error)]
pub enum FirmwareError {
    /// The core refused.
    #[error("core: {0}")]
    Core(#[from] spiv_core::Error),
    /// Framing.
    #[error("wire: {0}")]
    Wire(#[from] spiv_core::wire::WireError),
    /// The link.
    #[error("link: {0}")]
    Link(#[from] std::io::Error),
    /// A configuration the firmware cannot run.
    #[error("configuration: {0}")]
    Config(String),
}

/// Where messages go: one call per whole message (delimiter included).
pub trait Link {
    /// Sends one framed message.
    fn send(&mut self, message: &[u8]) -> std::io::Result<()>;
    /// Pushes out anything held.
    fn flush(&mut self) -> std::io::Result<()>;
}

/// A link over any writer.
#[derive(Debug)]
pub struct Plain<W: std::io::Write>(pub W);

impl<W: std::io::Write> Link for Plain<W> {
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.0.write_all(message)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

/// The core's sender writes through this.
struct CoreLink<'a, L: Link>(&'a mut L);

impl<L: Link> spiv_core::sender::Link for CoreLink<'_, L> {
    type Error = std::io::Error;
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.0.send(message)
    }
}

impl From<SendError<std::io::Error>> for FirmwareError {
    fn from(e: SendError<std::io::Error>) -> Self {
        match e {
            SendError::Wire(w) => FirmwareError::Wire(w),
            SendError::Link(l) => FirmwareError::Link(l),
        }
    }
}

/// Messages kept in memory (for in-process runs and tests).
impl Link for Vec<u8> {
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.extend_from_slice(message);
        Ok(())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A frame the firmware made, as it made it (for in-process comparison).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SentFrame {
    /// Frame counter.
    pub frame_id: u32,
    /// Centre tick.
    pub tick: u32,
    /// Pair counter and member (0: k, 1: k + dt).
    pub pair: u32,
    /// 0 or 1.
    pub member: u8,
    /// Samples in stored row order as the receiver will decode them.
    pub data: Vec<u16>,
}

/// The firmware's counters (also sent as a status message): the core
/// sender's.
pub type Counters = spiv_core::sender::Sent;

/// The loop.
#[derive(Debug)]
pub struct Firmware<L: Link> {
    cfg: Config,
    width: u16,
    height: u16,
    hist: HistoryBuf,
    ws: WorkspaceBuf,
    frame: Vec<u16>,
    counts: Vec<u8>,
    payload: Vec<u8>,
    wire: Vec<u8>,
    scratch: Vec<u16>,
    sender: Sender,
    schedule: Schedule,
    next: u64,
    next_tick: u32,
    link: L,
    /// Keep copies of what was sent (tests, in-process comparison).
    pub keep: Option<Vec<SentFrame>>,
}

impl<L: Link> Firmware<L> {
    /// A firmware for a `width × height` sensor sending to `link`.
    pub fn new(width: u16, height: u16, cfg: Config, link: L) -> Result<Self, FirmwareError> {
        let window = cfg.method.window(&cfg.params);
        if !(1..=255).contains(&window) {
            return Err(FirmwareError::Config(format!(
                "window {window} out of range (1..=255)"
            )));
        }
        if cfg.dt == 0 || cfg.every < cfg.dt {
            return Err(FirmwareError::Config(format!(
                "pair every {} ticks must be at least dt = {} > 0",
                cfg.every, cfg.dt
            )));
        }
        cfg.params.validate(cfg.params.n_max.max(window))?;
        let tile_rows = tile_rows(width, height, cfg.params.full_scale > 255, cfg.lossy.block);
        if tile_rows == 0 {
            return Err(FirmwareError::Config(format!(
                "a row of {width} px does not fit one {MAX_PAYLOAD}-byte payload"
            )));
        }
        let sender = Sender::new(width, height, tile_rows)?;
        let schedule = Schedule {
            first: cfg.first,
            dt: cfg.dt,
            every: cfg.every,
            pairs: cfg.pairs,
        };
        let depth = window.max(cfg.params.n_max).max(2);
        let hist = HistoryBuf::new(width, height, depth)?;
        let px = usize::from(width) * usize::from(height);
        Ok(Firmware {
            width,
            height,
            hist,
            ws: WorkspaceBuf::whole(width, height),
            frame: vec![0; px],
            counts: vec![0; px],
            payload: vec![0; MAX_PAYLOAD],
            wire: vec![0; MAX_ENCODED],
            scratch: vec![0; sparse_scratch(width, tile_rows, cfg.lossy.block)],
            sender,
            schedule,
            next: 0,
            next_tick: 0,
            cfg,
            link,
            keep: None,
        })
    }

    /// Rows per tile message.
    pub fn tile_rows(&self) -> u16 {
        self.sender.tile_rows()
    }

    /// The counters so far.
    pub fn counters(&self) -> Counters {
        self.sender.sent
    }

    /// The link (to take a memory link back).
    pub fn into_link(self) -> L {
        self.link
    }

    /// Ingests the next plane (stored row order, `width·height/8` bytes) and
    /// sends every frame whose window it completes.
    pub fn push_plane(&mut self, plane: &[u8]) -> Result<(), FirmwareError> {
        let view = PlaneView::new(plane, self.width, self.height)?;
        let newest = {
            let mut hist = self.hist.resume(self.next_tick)?;
            let t = hist.push(&view)?;
            self.next_tick = hist.next_tick();
            t
        };
        self.sender.sent.planes += 1;
        let window = self.cfg.method.window(&self.cfg.params);
        while let Some(slot) = self.schedule.slot(self.next) {
            if !Schedule::ready(slot.tick, window, newest) {
                break;
            }
            self.next += 1;
            self.send_frame(slot)?;
            if slot.member == 1
                && self.cfg.status_every > 0
                && (slot.pair + 1) % self.cfg.status_every == 0
            {
                self.send_status()?;
            }
        }
        Ok(())
    }

    /// True once every scheduled pair was sent.
    pub fn done(&self) -> bool {
        self.schedule.slot(self.next).is_none()
    }

    /// Sends the final status and flushes the link.
    pub fn finish(&mut self) -> Result<Counters, FirmwareError> {
        self.send_status()?;
        self.link.flush()?;
        Ok(self.sender.sent)
    }

    fn make_frame(&mut self, k: u32) -> Result<(), FirmwareError> {
        let p = self.cfg.params;
        let hist = &self.hist.resume(self.next_tick)?;
        match self.cfg.method {
            Method::Tfp(n) => {
                tfp(hist, k, n, p.full_scale, &mut self.counts, &mut self.frame)?;
            }
            Method::Adaptive if self.cfg.caps.is_empty() => {
                reconstruct_adaptive(hist, k, &p, &mut self.ws.workspace(), &mut self.frame)?;
            }
            Method::Adaptive => {
                capped_frame(
                    hist,
                    k,
                    &p,
                    &self.cfg.caps,
                    &mut self.ws.workspace(),
                    &mut self.frame,
                )?;
            }
        }
        Ok(())
    }

    fn send_frame(&mut self, slot: Slot) -> Result<(), FirmwareError> {
        self.make_frame(slot.tick)?;
        let frame_id = self.sender.sent.frames;
        let info = FrameInfo {
            slot,
            method: self.cfg.method.code(),
            full_scale: self.cfg.params.full_scale,
            dt: self.cfg.dt,
        };
        let (encoding, lossy) = (self.cfg.encoding, self.cfg.lossy);
        let mut buf = SendBuffers {
            payload: &mut self.payload,
            wire: &mut self.wire,
            scratch: &mut self.scratch,
        };
        self.sender.send_frame(
            &mut buf,
            &mut self.frame,
            &info,
            encoding,
            &lossy,
            &mut CoreLink(&mut self.link),
        )?;
        if let Some(keep) = &mut self.keep {
            keep.push(SentFrame {
                frame_id,
                tick: slot.tick,
                pair: slot.pair,
                member: slot.member,
                data: self.frame.clone(),
            });
        }
        Ok(())
    }

    fn send_status(&mut self) -> Result<(), FirmwareError> {
        let mut buf = SendBuffers {
            payload: &mut self.payload,
            wire: &mut self.wire,
            scratch: &mut self.scratch,
        };
        self.sender
            .send_status(&mut buf, &mut CoreLink(&mut self.link))?;
        Ok(())
    }
}

/// The adaptive frame at `k` with a window limit per band of [`CAP_BAND`]
/// upright rows (`caps[0]` the top band; missing entries: `p.n_max`; each
/// clamped to `1..=p.n_max`): each band is reconstructed once, with its own
/// limit and a margin of `p.margin` rows ([`reconstruct_rows`]). The one
/// implementation of the dwell cap, for the firmware and the host.
pub fn capped_frame<G: spiv_core::Gray>(
    hist: &spiv_core::History<'_>,
    k: u32,
    p: &Params,
    caps: &[u16],
    ws: &mut spiv_core::Workspace<'_>,
    out: &mut [G],
) -> Result<(), spiv_core::Error> {
    p.validate(hist.depth())?;
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
        reconstruct_rows(hist, k, &q, ws, (e0, e1), out)?;
    }
    Ok(())
}

/// Faults a link can suffer, as probabilities per message.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Faults {
    /// The message is lost.
    pub drop: f64,
    /// One random bit of the message flips.
    pub corrupt: f64,
    /// The message is cut short (its delimiter lost with its tail).
    pub truncate: f64,
    /// The link stalls for a few milliseconds before the message.
    pub stall: f64,
    /// The message is held back and sent after the next one.
    pub reorder: f64,
}

impl Faults {
    /// Parses `drop=P,corrupt=P,truncate=P,stall=P,reorder=P` (any subset).
    pub fn parse(s: &str) -> Result<Faults, String> {
        let mut f = Faults::default();
        for part in s.split(',').filter(|p| !p.is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| format!("fault `{part}` is not NAME=P"))?;
            let p: f64 = v
                .parse()
                .map_err(|_| format!("fault {k}: `{v}` is not a number"))?;
            if !(0.0..=1.0).contains(&p) {
                return Err(format!("fault {k}: probability {p} outside 0..1"));
            }
            match k {
                "drop" => f.drop = p,
                "corrupt" => f.corrupt = p,
                "truncate" => f.truncate = p,
                "stall" => f.stall = p,
                "reorder" => f.reorder = p,
                _ => {
                    return Err(format!(
                        "unknown fault `{k}` (drop, corrupt, truncate, stall, reorder)"
                    ))
                }
            }
        }
        Ok(f)
    }
}

/// What the faulty link did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// Messages dropped.
    pub dropped: u64,
    /// Messages with a flipped bit.
    pub corrupted: u64,
    /// Messages cut short.
    pub truncated: u64,
    /// Stalls.
    pub stalled: u64,
    /// Messages sent late.
    pub reordered: u64,
}

/// A link that injects [`Faults`], deterministic for a seed.
#[derive(Debug)]
pub struct Faulty<L: Link> {
    inner: L,
    faults: Faults,
    rng: rand_chacha::ChaCha8Rng,
    held: Option<Vec<u8>>,
    /// What was done.
    pub counts: FaultCounts,
}

impl<L: Link> Faulty<L> {
    /// Faults on `inner` with `seed`.
    pub fn new(inner: L, faults: Faults, seed: u64) -> Self {
        use rand::SeedableRng;
        Faulty {
            inner,
            faults,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(seed),
            held: None,
            counts: FaultCounts::default(),
        }
    }

    /// The link underneath.
    pub fn into_inner(self) -> L {
        self.inner
    }

    fn hit(&mut self, p: f64) -> bool {
        use rand::Rng;
        p > 0.0 && self.rng.gen::<f64>() < p
    }
}

impl<L: Link> Link for Faulty<L> {
    fn send(&mut self, message: &[u8]) -> std::io::Result<()> {
        use rand::Rng;
        if self.hit(self.faults.stall) {
            self.counts.stalled += 1;
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        if self.hit(self.faults.drop) {
            self.counts.dropped += 1;
            return Ok(());
        }
        let mut m = message.to_vec();
        if self.hit(self.faults.corrupt) {
            let bit = self.rng.gen_range(0..m.len() * 8);
            m[bit / 8] ^= 1 << (bit % 8);
            self.counts.corrupted += 1;
        }
        if self.hit(self.faults.truncate) && m.len() > 1 {
            let keep = self.rng.gen_range(1..m.len());
            m.truncate(keep);
            self.counts.truncated += 1;
        }
        if self.held.is_none() && self.hit(self.faults.reorder) {
            self.held = Some(m);
            self.counts.reordered += 1;
            return Ok(());
        }
        self.inner.send(&m)?;
        if let Some(h) = self.held.take() {
            self.inner.send(&h)?;
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(h) = self.held.take() {
            self.inner.send(&h)?;
        }
        self.inner.flush()
    }
}

/// Why a driven run stopped.
#[derive(Debug, thiserror::Error)]
pub enum DriveError {
    /// The firmware.
    #[error(transparent)]
    Firmware(#[from] FirmwareError),
    /// The input.
    #[error(transparent)]
    Format(#[from] crate::formats::FormatError),
}

/// Ticks a simulated stream needs for `pairs` pairs of `cfg`'s schedule.
pub fn ticks_for(cfg: &Config, pairs: u32) -> u32 {
    let window = cfg.method.window(&cfg.params);
    let ahead = u32::from(window - window / 2);
    cfg.first + pairs.saturating_sub(1) * cfg.every + cfg.dt + ahead
}

/// Runs the firmware on a simulated scene, the planes streamed straight
/// from the sensor into the loop (never stored). `req.ticks` is set from
/// the schedule when `cfg.pairs` is given. Returns the firmware (its
/// counters, link and kept frames) and the simulation (truth, frame camera).
pub fn run_on_scene<L: Link>(
    req: &crate::simulation::Request,
    cfg: Config,
    link: L,
    keep: bool,
    progress: impl FnMut(u32, u32),
) -> Result<(Firmware<L>, crate::simulation::Simulated), DriveError> {
    let mut req = req.clone();
    if let Some(p) = cfg.pairs {
        req.ticks = Some(ticks_for(&cfg, p).max(req.scene.pair_dt + 1));
    }
    let mut fw = Firmware::new(req.scene.width, req.scene.height, cfg, link)?;
    if keep {
        fw.keep = Some(Vec::new());
    }
    let mut failed: Option<FirmwareError> = None;
    let sim = crate::simulation::simulate(&req, progress, |plane| {
        if failed.is_some() || fw.done() {
            return Ok(());
        }
        if let Err(e) = fw.push_plane(plane) {
            failed = Some(e);
        }
        Ok(())
    })?;
    if let Some(e) = failed {
        return Err(e.into());
    }
    fw.finish()?;
    Ok((fw, sim))
}

/// Runs the firmware on a `.dat` file, plane by plane.
pub fn run_on_dat<L: Link>(
    path: &std::path::Path,
    width: u16,
    height: u16,
    opts: crate::formats::dat::DatOptions,
    cfg: Config,
    link: L,
    keep: bool,
) -> Result<Firmware<L>, DriveError> {
    let mut r = crate::formats::dat::DatReader::open(path, width, height, opts)?;
    let mut fw = Firmware::new(r.width(), r.height(), cfg, link)?;
    if keep {
        fw.keep = Some(Vec::new());
    }
    let mut plane = vec![0u8; r.out_plane_bytes()];
    while !fw.done() && r.read_plane(&mut plane)? {
        fw.push_plane(&plane)?;
    }
    fw.finish()?;
    Ok(fw)
}

/// Runs the firmware on planes held in memory (back to back, stored row
/// order), from the first.
pub fn run_on_planes<L: Link>(
    planes: &[u8],
    width: u16,
    height: u16,
    cfg: Config,
    link: L,
    keep: bool,
) -> Result<Firmware<L>, FirmwareError> {
    let mut fw = Firmware::new(width, height, cfg, link)?;
    if keep {
        fw.keep = Some(Vec::new());
    }
    let pb = usize::from(width) * usize::from(height) / 8;
    for plane in planes.chunks_exact(pb.max(1)) {
        if fw.done() {
            break;
        }
        fw.push_plane(plane)?;
    }
    fw.finish()?;
    Ok(fw)
}
