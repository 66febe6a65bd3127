//! `spiv flow`: the main job on any spike recording (a Vidar `.dat` or a
//! `.npz` capture): a field per pair at a fixed schedule, and their
//! robust mean. No window needs hand-tuning.
//!
//! - `ladder` (the default, beyond the paper): the time ladder
//!   ([`crate::estimator::ladder`]). Around each pair's midpoint the
//!   recording's own planes measure the flow: disjoint frames of the
//!   spikes' innovation, compensated along the motion known so far, at
//!   separations growing from 4 ticks as long as the flow and the recording
//!   allow; each vector keeps the most certain measurement and its
//!   uncertainty, per pair (`dt` ticks).
//! - `adaptive` with a dwell cap (docs/spec.md §5): a time-resolved loop; the field
//!   of the previous pair predicts each 32-row band's fastest particle, and
//!   the band's adaptive window is capped so it blurs by at most the budget.
//!   The first pair — and any pair after one whose field is not usable
//!   ([`crate::piv::Field::usable`]) — is bootstrapped from a TFP pair.
//!   Without a cap: the paper's algorithm, one n_max everywhere.
//! - `tfp`, `tfi`: the baselines.
//!
//! A pair that measured nothing says so: its vectors are invalid, with no
//! uncertainty. Memory is bounded by the frames and the ladder's stretch
//! of planes, not by the recording: a `.dat` is read window by window, a
//! `.npz` capture is held packed (at most `spiv_formats::MAX_NPZ_SAMPLES`
//! samples).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use ndarray::Array2;
use spiv_core::{Method, Params};
use spiv_formats::capture::Capture;
use spiv_formats::dat::DatReader;
use spiv_formats::grid::Grid;
use spiv_formats::npz::read_npz_spikes;
use spiv_formats::{FormatError, State, Vector};

use crate::dwell::{adaptive_banded, caps_for};
use crate::estimator::control::{Ask, AskLink, Delivery, Heard};
use crate::estimator::joint::JointSettings;
use crate::estimator::ladder::{self, LadderSettings, Rung};
use crate::estimator::make::pair_input;
use crate::estimator::uplink::{PairBytes, PairReader, Uplink};
use crate::piv::validate::median;
use crate::piv::{piv, to_f32, Field, PivError, Settings, NO_SIGMA};
use crate::receive::assemble::FrameLimit;
use crate::reconstruct::{frame_from_planes, FileOptions, Planes};
use crate::units::Calibration;
use crate::Error;
use spiv_core::pairs::{CorePair, PairMaker, LIGHT_TRAIN};
use spiv_estimator::units::{PerPair, Ticks};

/// The TFP window of the dwell cap's bootstrap pair, ticks.
pub const BOOTSTRAP_WINDOW: u16 = 8;

pub use crate::dwell::DWELL_CAP;

/// A spike recording, opened: its size and where its planes come from.
#[derive(Debug)]
pub struct Recording {
    source: Source,
    /// Width of the planes, px (before cropping padding columns).
    pub width: u16,
    /// Height, px.
    pub height: u16,
    /// Planes in the recording.
    pub planes: u64,
    /// Stored rows are bottom-up.
    pub flip: bool,
    /// Width of the output frames, px.
    pub crop_width: u16,
    /// The pair separation `scene.json` beside a `.dat` names, ticks.
    pub meta_dt: Option<u32>,
    /// The calibration `scene.json` beside a `.dat` gives (pixel size and
    /// tick rate).
    pub meta_calibration: Option<Calibration>,
}

#[derive(Debug)]
enum Source {
    /// Read window by window; one reader, each read under its lock (the
    /// pairs of [`run_flow`]'s chains read concurrently).
    Dat(std::sync::Mutex<DatReader<std::io::BufReader<std::fs::File>>>),
    Memory(Vec<u8>),
}

impl Recording {
    /// Opens a `.dat` (size from `opts` or the `scene.json` beside it, and
    /// the two must agree) or a `.npz` capture (by extension). A missing
    /// file, and a file named or starting like an image, text or another
    /// known format, is refused before any size is asked for.
    pub fn open(path: &Path, opts: &FileOptions) -> Result<Recording, Error> {
        not_a_recording(path)?;
        let is_npz = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
        if is_npz {
            let s = read_npz_spikes(path)?;
            return Ok(Recording {
                width: s.packed_width,
                height: s.height,
                planes: s.ticks as u64,
                flip: false,
                crop_width: s.width,
                meta_dt: None,
                meta_calibration: None,
                source: Source::Memory(s.planes),
            });
        }
        let meta = Capture::beside(path)?;
        let (w, h) = match (opts.width, opts.height, &meta) {
            (Some(w), Some(h), Some(m)) if (w, h) != (m.width, m.height) => {
                return Err(FormatError::SizeAgainstMeta {
                    path: path.to_path_buf(),
                    given_w: w,
                    given_h: h,
                    meta_w: m.width,
                    meta_h: m.height,
                }
                .into())
            }
            (Some(w), Some(h), _) => (w, h),
            (None, None, Some(m)) => (m.width, m.height),
            _ => return Err(FormatError::NoSize(path.to_path_buf()).into()),
        };
        let r = DatReader::open(path, w, h, opts.dat)?;
        Ok(Recording {
            width: r.width(),
            height: r.height(),
            planes: r.planes(),
            flip: r.flip(),
            crop_width: r.width(),
            meta_dt: meta.as_ref().map(|m| m.pair[1].saturating_sub(m.pair[0])),
            meta_calibration: meta.and_then(|m| Calibration::new(m.pixel_mm, m.tick_hz).ok()),
            source: Source::Dat(std::sync::Mutex::new(r)),
        })
    }

    /// A recording held in memory: `planes` packed as the sensor stores them
    /// (bottom-up, `width × height` bits each), pairs `dt` ticks apart.
    pub fn simulated(width: u16, height: u16, planes: Vec<u8>, dt: u32) -> Recording {
        let pb = (usize::from(width) * usize::from(height) / 8).max(1);
        Recording {
            width,
            height,
            planes: (planes.len() / pb) as u64,
            flip: true,
            crop_width: width,
            meta_dt: Some(dt),
            meta_calibration: None,
            source: Source::Memory(planes),
        }
    }

    /// The planes a window of `window` ticks centred on `k` needs (clipped
    /// at the recording's ends).
    pub fn around(&self, k: u64, window: u16) -> Result<Planes, Error> {
        self.stretch(k.saturating_sub(u64::from(window / 2)), u64::from(window))
    }

    /// The planes `first..first + n` (clipped at the recording's end).
    pub fn stretch(&self, first: u64, n: u64) -> Result<Planes, Error> {
        let n = n.min(self.planes.saturating_sub(first));
        let data = match &self.source {
            Source::Dat(r) => {
                // A poisoned lock only means another pair's read panicked;
                // the reader seeks before every read.
                let mut r = r.lock().unwrap_or_else(|e| e.into_inner());
                r.read_range(first, n)?
            }
            Source::Memory(all) => {
                let pb = usize::from(self.width) * usize::from(self.height) / 8;
                let a = (first as usize).saturating_mul(pb).min(all.len());
                let e = a.saturating_add(n as usize * pb).min(all.len());
                all[a..e].to_vec()
            }
        };
        Ok(Planes {
            width: self.width,
            height: self.height,
            flip: self.flip,
            crop_width: self.crop_width,
            first,
            data,
        })
    }
}

/// Refuses a missing file (the I/O error names it) and one that is
/// plainly not a spike recording: a name ending like an image, text or
/// table, or first bytes of PNG, JPEG, GIF, TIFF, BMP, PDF or netCDF/HDF5.
/// A `.dat` is raw bits, so any other content may be one.
fn not_a_recording(path: &Path) -> Result<(), FormatError> {
    let io = |source| FormatError::Io {
        path: path.to_path_buf(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if meta.is_dir() {
        return Err(FormatError::NotRecording(path.to_path_buf()));
    }
    const NOT: [&str; 16] = [
        "png", "jpg", "jpeg", "gif", "tif", "tiff", "bmp", "txt", "csv", "json", "nc", "h5", "pdf",
        "md", "flo", "npy",
    ];
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    if NOT.iter().any(|n| ext.eq_ignore_ascii_case(n)) {
        return Err(FormatError::NotRecording(path.to_path_buf()));
    }
    let mut head = [0u8; 8];
    let n =
        std::io::Read::read(&mut std::fs::File::open(path).map_err(io)?, &mut head).map_err(io)?;
    const MAGIC: [&[u8]; 9] = [
        b"\x89PNG",
        b"\xff\xd8\xff",
        b"GIF8",
        b"II*\0",
        b"MM\0*",
        b"%PDF",
        b"CDF\x01",
        b"CDF\x02",
        b"\x89HDF",
    ];
    if MAGIC.iter().any(|m| head[..n].starts_with(m)) {
        return Err(FormatError::NotRecording(path.to_path_buf()));
    }
    Ok(())
}

/// What `spiv flow` does.
#[derive(Debug, Clone)]
pub struct FlowOptions {
    /// How frames are made.
    pub method: Method,
    /// The TFP window, or the adaptive / TFI window limit n_max, ticks.
    pub window: u16,
    /// Adaptive only: blur budget of the closed-loop dwell cap, px; `None`
    /// runs the paper's algorithm with one n_max everywhere.
    pub dwell_cap: Option<f64>,
    /// Ticks between the two frames of a pair.
    pub dt: u32,
    /// Ticks between pairs.
    pub every: u32,
    /// Tick of the first pair's first frame.
    pub start: u64,
    /// No frame at or after this tick.
    pub end: u64,
    /// No pair starts after this tick (the default schedule of
    /// motion-compensated pairs: every pair's ladder reaches its longest
    /// rung).
    pub last_start: Option<u64>,
    /// Core parameters (`n_max` is set from `window`).
    pub core: Params,
    /// PIV settings of TFP, TFI and adaptive pairs (and of the TFP pairs
    /// that bootstrap the dwell cap).
    pub piv: Settings,
    /// The time ladder of motion-compensated pairs.
    pub ladder: LadderSettings,
    /// Also average each pair's dense flow into [`FlowOutcome::mean_dense`]
    /// (leaving out the pairs that measured no usable field on frames
    /// shorter than the pair; none left: no dense field): the time
    /// ladder's vectors between the nodes, carried along their paths, or
    /// the dense ensemble's flow, each refined by [`FlowOptions::joint`]
    /// where the pair carries its events; the dense stage
    /// ([`crate::piv::dense`]) on a plain pair's frames.
    pub dense: bool,
    /// With `dense`, the joint fit that refines each motion-compensated
    /// pair's dense flow ([`crate::estimator::joint`]; `None`: the flow
    /// as the ladder or the dense ensemble measured it).
    pub joint: Option<JointSettings>,
    /// The recording's calibration, when known: the outputs give m/s and
    /// seconds beside px per pair and ticks.
    pub calibration: Option<Calibration>,
    /// Pixels left out (upright, `crop_width × height`; `true`: masked):
    /// plain pairs' PIV and the time ladder's bootstrap rungs leave them
    /// out of the correlation (`LadderSettings::mask`), and a node whose
    /// centre is masked is invalid in every pair, so it never predicts the
    /// next one.
    pub mask: Option<Array2<bool>>,
    /// Only the pairs with these indices in [`FlowOptions::pair_ticks`]
    /// (`None`: all). A range that starts at a multiple of
    /// [`FlowOptions::segment`] (motion-compensated pairs) or of [`CHAIN`]
    /// (the others) gives exactly the vectors of those pairs in a run of
    /// all of them with the same segments, so runs of such ranges can be
    /// spread over processes or machines.
    pub pairs: Option<std::ops::Range<usize>>,
    /// Write the outputs with y up (files, Python arrays; the figures'
    /// axes and vorticity): y = height − 1 − row and v positive up, so
    /// that plots with y up show the camera's image upright and vorticity
    /// is positive counterclockwise. The measurement is the same.
    pub y_up: bool,
    /// Motion-compensated pairs: pairs per loop (`None`: one loop over
    /// every pair, as the sidecar runs). Each loop starts from nothing,
    /// [`WARMUP`] pairs before its first, and loops run in parallel.
    pub segment: Option<usize>,
    /// How each motion-compensated pair's ask reaches the core that makes
    /// the next pairs: at once (the default, as `spiv flow` runs), or late
    /// and with losses, as a live downlink delivers it.
    pub delivery: Delivery,
    /// Send each motion-compensated pair through the live loop's uplink
    /// and measure what is read back from its messages (bit-exact: the
    /// same vectors), counting what its frames and events cost
    /// ([`PairResult::bytes`]; off by default: the coding costs time and
    /// `spiv flow` sends nothing).
    pub wire_bytes: bool,
}

impl FlowOptions {
    /// The defaults for `rec` with pairs `dt` ticks apart: motion-compensated
    /// (`ladder`, the time ladder), one pair every `4·dt` ticks over the stretch
    /// where every pair's ladder reaches its longest rung (on a recording
    /// too short for that, one pair at its centre) — see
    /// [`FlowOptions::schedule`].
    pub fn new(rec: &Recording, dt: u32) -> FlowOptions {
        let core = Params::default();
        let mut o = FlowOptions {
            method: Method::Ladder,
            window: core.n_max,
            dwell_cap: Some(DWELL_CAP),
            dt,
            every: dt.saturating_mul(4),
            start: 0,
            end: rec.planes,
            last_start: None,
            core,
            piv: Settings::for_spike_frames(),
            ladder: LadderSettings::default(),
            dense: false,
            joint: Some(JointSettings::default()),
            calibration: rec.meta_calibration,
            mask: None,
            pairs: None,
            y_up: false,
            segment: None,
            delivery: Delivery::default(),
            wire_bytes: false,
        };
        o.schedule(rec.planes);
        o
    }

    /// Sets the default first pair (and, for motion-compensated pairs, the
    /// last) for a recording of `planes` planes. Motion-compensated: the
    /// pairs whose midpoint has the ladder's longest separation of planes
    /// on both sides, so that no pair is measured from fewer planes than
    /// another; on a recording too short for one, the central pair.
    /// Otherwise: from tick `n_max/2`, where the first window is whole (or
    /// as central as a short recording allows), to the end.
    pub fn schedule(&mut self, planes: u64) {
        let dt = u64::from(self.dt);
        let last = planes.saturating_sub(1 + dt);
        if self.method != Method::Ladder {
            self.start = u64::from(self.core.n_max / 2).min(last / 2);
            self.last_start = None;
            return;
        }
        let reach = u64::from(self.ladder.separations.iter().copied().max().unwrap_or(0));
        // A pair at `ka` has its midpoint at ka + ⌈dt/2⌉.
        let half = dt.div_ceil(2);
        let (first_mid, last_mid) = (reach, planes.saturating_sub(reach));
        let mid = if first_mid <= last_mid {
            first_mid
        } else {
            planes / 2
        };
        self.start = mid.saturating_sub(half).min(last);
        self.last_start = Some(last_mid.max(mid).saturating_sub(half).max(self.start));
    }

    /// The pairs' first ticks.
    pub fn pair_ticks(&self) -> Vec<u64> {
        let every = u64::from(self.every.max(1));
        let mut out = Vec::new();
        let mut k = self.start;
        while k + u64::from(self.dt) < self.end && self.last_start.is_none_or(|l| k <= l) {
            out.push(k);
            k += every;
        }
        out
    }

    /// The PIV settings whose grid the pairs' fields live on.
    pub fn grid_settings(&self) -> &Settings {
        match self.method {
            Method::Ladder => &self.ladder.piv,
            _ => &self.piv,
        }
    }
}

/// What a user asks of a flow run (`spiv flow`'s options, the Python
/// binding's keywords); `None` takes the default [`FlowOptions::new`]
/// gives. [`FlowRequest::options`] checks it against the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct FlowRequest {
    /// Ticks between the frames of a pair (default: the `scene.json`
    /// beside the file).
    pub dt: Option<u32>,
    /// Ticks between pairs (default `4·dt`).
    pub every: Option<u32>,
    /// Tick of the first pair's first frame.
    pub start: Option<u64>,
    /// No frame at or after this tick (default: the recording's end).
    pub end: Option<u64>,
    /// Frame method (default motion-compensated).
    pub method: Method,
    /// TFP window or adaptive/TFI n_max, ticks (default 8 TFP, else 128).
    pub window: Option<u16>,
    /// Adaptive: blur budget of the window caps, px (`None`: the paper's
    /// algorithm, one n_max everywhere). Default [`DWELL_CAP`].
    pub dwell_cap: Option<f64>,
    /// PIV window side of each pass, px (default: 64,32,32, and
    /// 64,32,32,32,32,32,32 for motion-compensated pairs).
    pub windows: Option<Vec<usize>>,
    /// Average each pair's dense flow ([`FlowOptions::dense`]).
    pub dense: bool,
    /// With `dense`, refine each pair's dense flow by the joint fit of
    /// every short frame around it ([`crate::estimator::joint`]); default
    /// on.
    pub joint: bool,
    /// Pixel size on the object, mm (default: the `scene.json` beside the
    /// file).
    pub pixel_mm: Option<f64>,
    /// Ticks per second, Hz (default: the `scene.json` beside the file).
    pub tick_hz: Option<f64>,
    /// Pixels to leave out (upright, the frames' size; `true`: masked).
    pub mask: Option<Array2<bool>>,
    /// Only these pairs of the schedule ([`FlowOptions::pairs`]).
    pub pairs: Option<std::ops::Range<usize>>,
    /// Pairs per independent loop ([`FlowOptions::segment`]).
    pub segment: Option<usize>,
}

impl Default for FlowRequest {
    fn default() -> Self {
        FlowRequest {
            dt: None,
            every: None,
            start: None,
            end: None,
            method: Method::Ladder,
            window: None,
            dwell_cap: Some(DWELL_CAP),
            windows: None,
            dense: false,
            joint: true,
            pixel_mm: None,
            tick_hz: None,
            mask: None,
            pairs: None,
            segment: None,
        }
    }
}

impl FlowRequest {
    /// The run's options over `rec` (read from `input`, named in the
    /// messages).
    pub fn options(&self, rec: &Recording, input: &Path) -> Result<FlowOptions, Error> {
        let dt = self.dt.or(rec.meta_dt).ok_or_else(|| {
            Error::Schedule(format!(
                "{}: give --dt (ticks between the frames of a pair): no scene.json beside it names one",
                input.display()
            ))
        })?;
        if dt == 0 || u64::from(dt) >= rec.planes {
            return Err(Error::Schedule(format!(
                "--dt {dt}: expected 1..{} (the recording has {} planes)",
                rec.planes, rec.planes
            )));
        }
        if let Some(c) = self.dwell_cap {
            if !(c.is_finite() && c > 0.0 && c <= 1000.0) {
                return Err(Error::Schedule(format!(
                    "--dwell-cap {c}: expected px in (0, 1000] or off"
                )));
            }
        }
        let mut o = FlowOptions::new(rec, dt);
        o.method = self.method;
        o.window = self.window.unwrap_or(match self.method {
            Method::Tfp => 8,
            _ => 128,
        });
        o.dwell_cap = self.dwell_cap;
        o.every = self.every.unwrap_or(o.every);
        o.end = self.end.unwrap_or(o.end).min(rec.planes);
        o.schedule(o.end);
        if let Some(s) = self.start {
            o.start = s;
            o.last_start = None;
        }
        if let Some(w) = &self.windows {
            o.piv.windows = w.clone();
            o.ladder.piv.windows = w.clone();
        }
        o.dense = self.dense;
        if !self.joint {
            o.joint = None;
        }
        o.calibration = Calibration::resolve(self.pixel_mm, self.tick_hz, rec.meta_calibration)
            .map_err(|e| Error::Schedule(e.to_string()))?;
        if let Some(m) = &self.mask {
            let want = (usize::from(rec.height), usize::from(rec.crop_width));
            if m.dim() != want {
                return Err(Error::Schedule(format!(
                    "mask is {}x{} px but the frames are {}x{} px",
                    m.ncols(),
                    m.nrows(),
                    want.1,
                    want.0
                )));
            }
        }
        o.mask = self.mask.clone();
        o.ladder.mask = self.mask.clone();
        o.pairs = self.pairs.clone();
        if self.segment == Some(0) {
            return Err(Error::Schedule(
                "segment 0: expected at least 1 pair per loop".into(),
            ));
        }
        o.segment = self.segment;
        Ok(o)
    }
}

/// A reported pair of the ladder's loop as the outputs take it: its kept
/// rung's frames (zeros of `h × w` without one, `dt` ticks), its field,
/// rungs and dense field, and what it cost on the wire.
fn measured_pair(
    m: ladder::Measurement,
    (h, w): (usize, usize),
    dt: f64,
    bytes: Option<PairBytes>,
) -> Measured {
    let (frames, frame_ticks) = match m.frames {
        Some(f) => (f.frames, f64::from(f.separation)),
        None => {
            let zero = Array2::zeros((h, w));
            ([zero.clone(), zero], dt)
        }
    };
    Measured {
        method: Method::Ladder,
        separation: m.separation.iter().copied().collect(),
        field: m.field.into_field(),
        frames,
        caps: Vec::new(),
        bootstrapped: false,
        rungs: m.rungs,
        frame_ticks,
        // The ladder's frames carry no label table.
        lost: LabelLoss::default(),
        dense: m.dense,
        bytes,
    }
}

/// The core's pair `i` at `mid` as `heard` asks: made in process, or,
/// with `wire`, sent up the uplink and read back from its messages (with
/// what it cost).
fn make_pair(
    maker: &mut PairMaker,
    wire: Option<&mut (Uplink, PairReader)>,
    (i, mid, dt): (usize, u64, u32),
    heard: &Heard,
    cfg: &LadderSettings,
) -> Result<(CorePair, Option<PairBytes>), Error> {
    let reach = u16::try_from(cfg.bootstrap_reach).unwrap_or(u16::MAX);
    let ask = heard.asked();
    Ok(match wire {
        Some((up, down)) => {
            let dt = u16::try_from(dt).unwrap_or(u16::MAX);
            let (messages, b) = up.send(maker, (i as u32, mid as u32, dt), &ask, reach)?;
            (read_back(down, &messages)?, Some(b))
        }
        None => (maker.make(mid as u32, &ask, reach)?, None),
    })
}

/// The pair that `messages` (one pair's, in order) carry, as `reader`
/// reads them from the stream.
fn read_back(reader: &mut PairReader, messages: &[Vec<u8>]) -> Result<CorePair, Error> {
    let mut rx = vec![0u8; spiv_core::wire::MAX_ENCODED];
    let mut dec = spiv_core::wire::Decoder::new(&mut rx);
    let mut got = None;
    for m in messages {
        let mut input = m.as_slice();
        while let Some(r) = dec.feed(&mut input) {
            if let Some((_, p)) = reader.push(&r?) {
                got = Some(p);
            }
        }
    }
    got.ok_or(Error::from(spiv_core::wire::WireError::Payload))
}

/// Makes every node of `f` whose centre pixel `mask` covers invalid
/// (`u = v = 0`, infinite uncertainty): a masked region measures nothing,
/// whatever the validation's replacement filled in from its neighbours.
fn masked_out(f: &mut Field, mask: &Array2<bool>) {
    let g = f.grid;
    for r in 0..g.ny {
        for c in 0..g.nx {
            let (x, y) = g.centre(r, c);
            let at = (y.round() as usize, x.round() as usize);
            if mask.get(at).copied().unwrap_or(false) {
                f.u[[r, c]] = 0.0;
                f.v[[r, c]] = 0.0;
                f.state[[r, c]] = State::Invalid;
                f.sigma[[r, c]] = crate::piv::NO_SIGMA;
            }
        }
    }
}

/// One pair's result.
#[derive(Debug, Clone)]
pub struct PairResult {
    /// How its frames were made.
    pub method: Method,
    /// The pair's frame ticks.
    pub ticks: [u64; 2],
    /// The field in px per pair (upright, row-major on the PIV grid).
    pub vectors: Vec<Vector>,
    /// Each vector's standard uncertainty (u, v), px per pair (infinite
    /// where invalid).
    pub sigma: Vec<(f64, f64)>,
    /// Window caps per 32-row band the pair's adaptive frames used (empty:
    /// none).
    pub caps: Vec<u16>,
    /// The caps came from a TFP pair at the same ticks, not from the
    /// previous pair.
    pub bootstrapped: bool,
    /// What the core's tables could not hold in the pair's frames (left
    /// as background).
    pub lost: LabelLoss,
    /// Motion-compensated pairs: the rungs of the time ladder, shortest
    /// first.
    pub rungs: Vec<Rung>,
    /// Motion-compensated pairs: the separation (ticks) of the rung each
    /// vector came from (0: replaced or invalid).
    pub separation: Vec<u32>,
    /// Motion-compensated pairs with [`FlowOptions::wire_bytes`]: what the
    /// core's frames and events of the pair cost on the wire.
    pub bytes: Option<PairBytes>,
}

/// Particles a frame lost to the core's full tables: they are rendered as
/// background (`spiv_core::label::LabelStats`), so a run reports them
/// rather than losing them silently.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LabelLoss {
    /// Regions past a full region table.
    pub regions: u32,
    /// Particle pixels that found no provisional label.
    pub pixels: u32,
}

impl LabelLoss {
    /// Adds one frame's losses.
    pub fn add(&mut self, s: &spiv_core::label::LabelStats) {
        self.merge(LabelLoss {
            regions: s.overflow_regions,
            pixels: s.dropped_pixels,
        });
    }

    /// Adds another count of losses.
    pub fn merge(&mut self, o: LabelLoss) {
        self.regions = self.regions.saturating_add(o.regions);
        self.pixels = self.pixels.saturating_add(o.pixels);
    }

    /// Nothing lost.
    pub fn is_none(&self) -> bool {
        self.regions == 0 && self.pixels == 0
    }
}

impl PairResult {
    /// Valid, replaced and invalid vectors.
    pub fn counts(&self) -> (usize, usize, usize) {
        let n = |s: State| self.vectors.iter().filter(|v| v.state == s).count();
        (n(State::Valid), n(State::Replaced), n(State::Invalid))
    }

    /// Whether the pair measured anything (a valid vector).
    pub fn measured(&self) -> bool {
        self.vectors.iter().any(|v| v.state == State::Valid)
    }
}

/// The robust mean of the pairs' fields.
#[derive(Debug, Clone, PartialEq)]
pub struct MeanField {
    /// Per node the median over pairs of the valid vectors (u and v each),
    /// valid; invalid where no pair measured the node.
    pub vectors: Vec<Vector>,
    /// The median's standard uncertainty, px per pair ([`median_sigma`]).
    pub sigma: Vec<(f64, f64)>,
    /// Pairs whose valid vector entered each node.
    pub pairs: Vec<u32>,
}

/// One pair's field as [`MeanField::of`] takes it: its vectors and their
/// standard uncertainties `(σu, σv)`, px per pair, in grid order.
pub type PairField<'a> = (&'a [Vector], &'a [(f64, f64)]);

impl MeanField {
    /// The robust mean of `pairs` (each pair's vectors and their
    /// uncertainties, on one grid, in time order): per node the median of
    /// the valid vectors (u and v each), their count and the median's
    /// uncertainty ([`median_sigma`]).
    pub fn of(pairs: &[PairField<'_>]) -> MeanField {
        let Some(first) = pairs.first() else {
            return MeanField {
                vectors: Vec::new(),
                sigma: Vec::new(),
                pairs: Vec::new(),
            };
        };
        let n = first.0.len();
        let mut out = MeanField {
            vectors: Vec::with_capacity(n),
            sigma: Vec::with_capacity(n),
            pairs: Vec::with_capacity(n),
        };
        for (i, v0) in first.0.iter().enumerate() {
            let valid: Vec<Measure> = pairs
                .iter()
                .filter_map(|(vectors, sigma)| {
                    let v = vectors.get(i).filter(|v| v.state == State::Valid)?;
                    Some((v.u, v.v, sigma.get(i).copied().unwrap_or(NO_SIGMA)))
                })
                .collect();
            let n = valid.len();
            let (u, v, state) = if n == 0 {
                (0.0, 0.0, State::Invalid)
            } else {
                let mut us: Vec<f64> = valid.iter().map(|x| x.0).collect();
                let mut vs: Vec<f64> = valid.iter().map(|x| x.1).collect();
                (median(&mut us), median(&mut vs), State::Valid)
            };
            out.vectors.push(Vector { u, v, state, ..*v0 });
            out.sigma.push(median_sigma(&valid));
            out.pairs.push(n as u32);
        }
        out
    }
}

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct FlowOutcome {
    /// Per pair, in time order.
    pub pairs: Vec<PairResult>,
    /// The first pair's frames (upright, `width × height`), for plots.
    pub first_frames: [Vec<u16>; 2],
    /// Width and height of the frames, px.
    pub size: (u16, u16),
    /// Gray level of full scale of those frames.
    pub full_scale: u16,
    /// The grid of every pair's field.
    pub grid: Grid,
    /// With [`FlowOptions::dense`]: the mean of the dense stage's field
    /// over the pairs ([`FlowOptions::dense`] says which), px per pair, v
    /// down, upright; `None` when no pair was kept.
    pub mean_dense: Option<spiv_formats::dense::DenseField>,
    /// Pixels under glare around the first pair (upright, `width × height`,
    /// [`glare`]).
    pub glare: Vec<bool>,
    /// Pairs the schedule held; more than `pairs.len()` when the run was
    /// stopped ([`run_flow_until`]).
    pub scheduled: usize,
}

impl FlowOutcome {
    /// The outcome as its outputs show it: itself, or with `y_up` a copy
    /// turned by [`FlowOutcome::flip_y`].
    pub fn oriented(&self, y_up: bool) -> std::borrow::Cow<'_, FlowOutcome> {
        if !y_up {
            return std::borrow::Cow::Borrowed(self);
        }
        let mut o = self.clone();
        o.flip_y();
        std::borrow::Cow::Owned(o)
    }

    /// Every vector's y as `height − 1 − y` (pixel centres on integers, so
    /// the bottom row's centre is 0) and its v negated (positive up).
    pub fn flip_y(&mut self) {
        let top = f64::from(self.size.1) - 1.0;
        for p in &mut self.pairs {
            for v in &mut p.vectors {
                v.y = top - v.y;
                if v.state.is_measured() {
                    v.v = -v.v;
                }
            }
        }
    }

    /// What the core's tables lost over all pairs.
    pub fn lost(&self) -> LabelLoss {
        let mut l = LabelLoss::default();
        for p in &self.pairs {
            l.merge(p.lost);
        }
        l
    }

    /// The robust mean over pairs ([`MeanField::of`]).
    pub fn mean(&self) -> MeanField {
        MeanField::of(
            &self
                .pairs
                .iter()
                .map(|p| (p.vectors.as_slice(), p.sigma.as_slice()))
                .collect::<Vec<_>>(),
        )
    }

    /// The mean field's vectors ([`FlowOutcome::mean`]).
    pub fn mean_field(&self) -> Vec<Vector> {
        self.mean().vectors
    }
}

/// A valid vector's `(u, v, (σu, σv))`.
pub type Measure = (f64, f64, (f64, f64));

/// The standard uncertainty of the median of `valid`: the larger of what
/// the vectors' own uncertainties give (the median of them, over √n,
/// times 1.2533, the median's efficiency) and what their scatter gives
/// (1.4826 × the median absolute deviation, likewise); infinite with no
/// vector.
pub fn median_sigma(valid: &[Measure]) -> (f64, f64) {
    let n = valid.len();
    if n == 0 {
        return NO_SIGMA;
    }
    let k = 1.2533 / (n as f64).sqrt();
    let one = |mut xs: Vec<f64>, mut own: Vec<f64>| {
        let m = median(&mut xs);
        let mut dev: Vec<f64> = xs.iter().map(|x| (x - m).abs()).collect();
        k * median(&mut own).max(1.4826 * median(&mut dev))
    };
    (
        one(
            valid.iter().map(|x| x.0).collect(),
            valid.iter().map(|x| x.2 .0).collect(),
        ),
        one(
            valid.iter().map(|x| x.1).collect(),
            valid.iter().map(|x| x.2 .1).collect(),
        ),
    )
}

/// A pair's field and how it was made, before it becomes a [`PairResult`].
struct Measured {
    method: Method,
    field: Field,
    frames: [Array2<f32>; 2],
    caps: Vec<u16>,
    bootstrapped: bool,
    rungs: Vec<Rung>,
    separation: Vec<u32>,
    /// Ticks the frames' displacement spans (`dt` but for ladder frames).
    frame_ticks: f64,
    /// The dense flow, px per `dt`, when the pair was measured densely.
    dense: Option<crate::piv::dense::Flow>,
    /// What the core's label tables lost in the pair's frames.
    lost: LabelLoss,
    bytes: Option<PairBytes>,
}

/// Pairs per chain of [`run_flow`]: within a chain each pair starts from
/// the previous pair's field, the first from nothing; chains run in
/// parallel. Fixed, not derived from the cores, so the output is the same
/// on any number of cores. A chain's first pair costs about 1.5× a warm
/// one (the ladder's bootstrap rungs), so 8 pairs per chain cost about 6 %
/// over one chain of all pairs on one core.
pub const CHAIN: usize = 8;

/// Runs the flow job over `rec` on every core (rayon: [`CHAIN`]s of pairs
/// in parallel; the output is identical on any number of threads);
/// `progress` is told (pairs done, pairs).
pub fn run_flow(
    rec: &Recording,
    opts: &FlowOptions,
    progress: impl FnMut(usize, usize) + Send,
) -> Result<FlowOutcome, Error> {
    run_flow_until(rec, opts, progress, &AtomicBool::new(false))
}

/// [`run_flow`], stopping between pairs once `stop` is set (Ctrl-C): every
/// pair already measured is kept, in time order, each with its vectors
/// exactly as a whole run gives them; [`FlowOutcome::scheduled`] says how
/// many the schedule held. A pair being measured when `stop` is set is
/// finished first, so a run stops within one pair's time.
pub fn run_flow_until(
    rec: &Recording,
    opts: &FlowOptions,
    progress: impl FnMut(usize, usize) + Send,
    stop: &AtomicBool,
) -> Result<FlowOutcome, Error> {
    use rayon::prelude::*;
    let ticks = check(rec, opts)?;
    let core = Params {
        n_max: opts.window.max(opts.core.n0),
        ..opts.core
    };
    let (w, h) = (usize::from(rec.crop_width), usize::from(rec.height));
    let grid = opts
        .grid_settings()
        .grid(w, h)
        .ok_or(PivError::TooSmall(w, h, 32))?;
    let total = ticks.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let progress = std::sync::Mutex::new(progress);
    let tell = || {
        let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if let Ok(mut p) = progress.lock() {
            p(n, total);
        }
    };
    let chains: Vec<Result<Chain, Error>> = match (opts.method, opts.segment) {
        (Method::Ladder, None) => vec![ladder_loop(rec, opts, &ticks, &tell, stop)],
        (Method::Ladder, Some(n)) => ticks
            .par_chunks(n.max(1))
            .map(|seg| ladder_loop(rec, opts, seg, &tell, stop))
            .collect(),
        _ => ticks
            .par_chunks(CHAIN)
            .map(|chain| measure_chain(rec, opts, &core, chain, &tell, stop))
            .collect(),
    };
    let mut pairs = Vec::with_capacity(total);
    let mut first_frames = None;
    let mut dense = DenseSum::default();
    for c in chains {
        let c = c?;
        first_frames = first_frames.or(c.first_frames);
        dense.merge(c.dense);
        pairs.extend(c.pairs);
    }
    Ok(FlowOutcome {
        pairs,
        first_frames: first_frames.unwrap_or_default(),
        size: (rec.crop_width, rec.height),
        full_scale: core.full_scale,
        grid,
        mean_dense: dense.mean(w, h),
        glare: glare(rec, ticks[0] + u64::from(opts.dt) / 2)?,
        scheduled: total,
    })
}

/// Ticks over which [`glare`] counts each pixel's spikes.
pub const GLARE_TICKS: u16 = 128;
/// A pixel is under glare when it fires at least this many times the
/// median pixel's rate (and at least [`GLARE_MIN_RATE`]): static light far
/// above the scene's background. On the paper's scenes (background about
/// 0.025 spikes per tick, glare rising to the sensor's 0.5 at the wall)
/// this marks the band the paper calls glare, 50 px above the wall, and no
/// particle (at most 0.05 spikes per tick over 128 ticks).
pub const GLARE_FACTOR: f64 = 4.0;
/// The lowest rate called glare, spikes per tick.
pub const GLARE_MIN_RATE: f64 = 0.1;
/// Glare is extended light: a bright pixel is glare only when at least
/// half of the `(2R+1)²` pixels around it (R = this) are bright too. A
/// particle that lingers (at a vortex centre, in a stagnation point) is
/// a few pixels across and fails it; a glare band's edge passes.
pub const GLARE_RADIUS: usize = 4;

/// The pixels of `rec` under glare around tick `k` (upright, cropped):
/// each pixel's spikes per tick over [`GLARE_TICKS`] ticks, against
/// [`GLARE_FACTOR`] × the median pixel's and [`GLARE_MIN_RATE`], where
/// the bright pixels are extended ([`GLARE_RADIUS`]).
pub fn glare(rec: &Recording, k: u64) -> Result<Vec<bool>, Error> {
    let p = rec.around(k, GLARE_TICKS)?;
    let (w, h) = (usize::from(p.width), usize::from(p.height));
    let cw = usize::from(p.crop_width);
    let pb = w * h / 8;
    let mut counts = vec![0u32; cw * h];
    let mut n = 0u32;
    for plane in p.data.chunks_exact(pb.max(1)) {
        let px = spiv_formats::dat::unpack_upright(plane, p.width, p.height, p.flip);
        for (r, row) in px.chunks_exact(w).enumerate() {
            for (c, &b) in row[..cw].iter().enumerate() {
                counts[r * cw + c] += u32::from(b);
            }
        }
        n += 1;
    }
    let rate: Vec<f64> = counts
        .iter()
        .map(|&c| f64::from(c) / f64::from(n.max(1)))
        .collect();
    let mut sorted = rate.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let limit = (GLARE_FACTOR * median).max(GLARE_MIN_RATE);
    let bright: Vec<bool> = rate.iter().map(|&r| n > 0 && r >= limit).collect();
    Ok(extended(&bright, cw, h, GLARE_RADIUS))
}

/// The pixels of `bright` (`w × h`, row-major) with at least half of the
/// `(2r+1)²` window around them bright too (the window clipped at the
/// frame's edges, and the half taken of what remains), by a summed-area
/// table.
fn extended(bright: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    let mut sum = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            sum[(y + 1) * (w + 1) + x + 1] = u32::from(bright[y * w + x])
                + sum[y * (w + 1) + x + 1]
                + sum[(y + 1) * (w + 1) + x]
                - sum[y * (w + 1) + x];
        }
    }
    (0..w * h)
        .map(|i| {
            let (y, x) = (i / w, i % w);
            if !bright[i] {
                return false;
            }
            let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
            let n = sum[y1 * (w + 1) + x1] + sum[y0 * (w + 1) + x0]
                - sum[y0 * (w + 1) + x1]
                - sum[y1 * (w + 1) + x0];
            2 * n as usize >= (y1 - y0) * (x1 - x0)
        })
        .collect()
}

#[cfg(test)]
mod glare_tests {
    use super::extended;

    /// A band stays glare to its edge; a lingering particle's few pixels
    /// do not.
    #[test]
    fn only_extended_light_is_glare() {
        let (w, h) = (40, 30);
        let mut bright = vec![false; w * h];
        for y in 20..30 {
            for x in 0..w {
                bright[y * w + x] = true;
            }
        }
        for (y, x) in [(8, 10), (8, 11), (9, 10), (9, 11), (9, 12), (10, 11)] {
            bright[y * w + x] = true;
        }
        let g = extended(&bright, w, h, 4);
        assert!((20..30).all(|y| (0..w).all(|x| g[y * w + x])), "the band");
        assert!(g.iter().take(20 * w).all(|&b| !b), "the particle");
    }
}

/// One chain's pairs, the first pair's frames and its dense sums.
#[derive(Default)]
struct Chain {
    pairs: Vec<PairResult>,
    first_frames: Option<[Vec<u16>; 2]>,
    dense: DenseSum,
}

impl Chain {
    /// Adds a measured pair at `ticks` (frames shown up to `full_scale`).
    fn take(&mut self, mut m: Measured, ticks: [u64; 2], opts: &FlowOptions, full_scale: u16) {
        if opts.dense {
            // A pair that measured nothing usable on frames shorter than
            // the pair adds nothing to the mean: its dense flow would start
            // from rest on those frames and be scaled up to the pair (dim
            // 4-tick rungs: the pyramid walks off to 20 px, times 5).
            let measured = m.dense.take();
            if measured.is_some() || m.field.usable() || m.frame_ticks >= f64::from(opts.dt) {
                self.dense.add(&m, measured, f64::from(opts.dt));
            }
        }
        if self.first_frames.is_none() {
            self.first_frames = Some(m.frames.clone().map(|f| gray(&f, full_scale)));
        }
        self.pairs.push(pair_result(m, ticks));
    }
}

/// The pairs whose first ticks are `chain`, in order: each from the
/// previous one's usable field, the first from nothing.
fn measure_chain(
    rec: &Recording,
    opts: &FlowOptions,
    core: &Params,
    chain: &[u64],
    tell: &(impl Fn() + Sync),
    stop: &AtomicBool,
) -> Result<Chain, Error> {
    let mut prediction: Option<Field> = None;
    let mut out = Chain {
        pairs: Vec::with_capacity(chain.len()),
        first_frames: None,
        dense: DenseSum::default(),
    };
    for &ka in chain {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let kb = ka + u64::from(opts.dt);
        let mut m = match (opts.method, opts.dwell_cap) {
            (Method::Adaptive, Some(budget)) => {
                capped_pair(rec, [ka, kb], opts, core, budget, prediction.take())?
            }
            (m, _) => plain_pair(rec, [ka, kb], opts, core, m)?,
        };
        if let Some(mask) = &opts.mask {
            masked_out(&mut m.field, mask);
        }
        prediction = m.field.usable().then(|| m.field.clone());
        out.take(m, [ka, kb], opts, core.full_scale);
        tell();
    }
    Ok(out)
}

/// Warm-up pairs a loop of motion-compensated pairs measures before its
/// first reported pair (as room allows), `every` ticks before it: it
/// carries its events and starts the ladder from nothing, so the first
/// reported pair is made with rung frames along a field, as the rest are.
/// It is not rescued by the dense ensemble when its field is usable
/// (`ladder::measure`'s `rescue`): the first reported pair's first rung
/// confirms or drops that field.
pub const WARMUP: usize = 2;

/// Ticks of spikes the core's static-light model sees before a loop's
/// first pair reads any (from the recording's start when it has fewer;
/// a loop that starts with the recording is trained on its first planes
/// played backwards instead: [`PairMaker::train`]).
pub const LIGHT_WARMUP: u64 = 512;

/// Planes read from the recording at once.
const READ_PLANES: u64 = 64;

/// The pairs whose first ticks are `seg`, measured in one loop as the
/// sidecar makes and the host measures them: the core's static-light
/// model and event ring take the recording's planes in order
/// ([`PairMaker`]); each pair, once the planes of its longest rung are
/// in, is made as the estimator asked after the pair before ([`Ask`]) and
/// measured by the time ladder; [`WARMUP`] pairs before the first are
/// measured but not reported.
fn ladder_loop(
    rec: &Recording,
    opts: &FlowOptions,
    seg: &[u64],
    tell: &(impl Fn() + Sync),
    stop: &AtomicBool,
) -> Result<Chain, Error> {
    // The joint fit runs only where its dense flow is written.
    let cfg = &LadderSettings {
        joint: opts.joint.clone().filter(|_| opts.dense),
        ..opts.ladder.clone()
    };
    let dt = u64::from(opts.dt);
    let every = u64::from(opts.every.max(1));
    let half = dt.div_ceil(2);
    let (longest16, reach16) = (
        u16::try_from(cfg.separations.iter().copied().max().unwrap_or(0)).unwrap_or(u16::MAX),
        u16::try_from(cfg.bootstrap_reach).unwrap_or(u16::MAX),
    );
    let (longest, reach) = (u64::from(longest16), u64::from(reach16));
    // The sidecar's loop makes a pair when its ring holds these ticks
    // after the midpoint, in a ring this deep (`spiv_firmware_sim::ladder`).
    let ahead = u64::from(spiv_core::rungs::lead(longest16, reach16));
    let end = opts.end.min(rec.planes);
    let Some(&m0) = seg.first().map(|ka| ka + half).as_ref() else {
        return Ok(Chain::default());
    };
    // Warm-up pairs where the shortest rungs fit before the first.
    let least = 2 * u64::from(cfg.bootstrap_longest);
    let all: Vec<(u64, bool)> = (1..=WARMUP as u64)
        .rev()
        .filter_map(|k| m0.checked_sub(k * every))
        .filter(|&m| m >= least)
        .map(|m| (m, false))
        .chain(seg.iter().map(|&ka| (ka + half, true)))
        .collect();
    let mut wire = opts
        .wire_bytes
        .then(|| {
            Ok::<_, Error>((
                Uplink::new((rec.width, rec.height))?,
                PairReader::new(FrameLimit::default()),
            ))
        })
        .transpose()?;
    if end > u64::from(u32::MAX) {
        return Err(Error::Schedule(format!(
            "{end} planes: the core counts ticks in 32 bits"
        )));
    }
    let (sw, h) = (rec.width, rec.height);
    let (w, hu) = (usize::from(rec.crop_width), usize::from(h));
    let pb = (usize::from(sw) * usize::from(h) / 8).max(1);
    let first_read = all[0].0.saturating_sub(longest.max(reach) + LIGHT_WARMUP);
    let depth = spiv_core::rungs::ring_depth(longest16, reach16) as usize;
    let mut maker = PairMaker::new((sw, h), first_read as u32, depth)?;
    if first_read == 0 {
        let n = (LIGHT_TRAIN as u64).min(end.saturating_sub(1));
        let pl = rec.stretch(1, n)?;
        let planes: Vec<&[u8]> = pl.data.chunks_exact(pb).collect();
        maker.train(&planes, LIGHT_TRAIN)?;
    }
    let mut link = AskLink::new(opts.delivery, cfg, (sw, h), rec.flip);
    let mut out = Chain::default();
    let mut read = first_read;
    // The core takes the recording's planes in order, up to `build`.
    let feed = |maker: &mut PairMaker, read: &mut u64, build: u64| -> Result<(), Error> {
        while *read < build {
            let n = READ_PLANES.min(build - *read);
            let planes = rec.stretch(*read, n)?;
            for plane in planes.data.chunks_exact(pb) {
                maker.push(plane)?;
            }
            *read += n;
        }
        Ok(())
    };
    let build = |mid: u64| (mid + ahead).min(end);
    for (i, &(mid, reported)) in all.iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        feed(&mut maker, &mut read, build(mid))?;
        let heard = link.ask_for(i);
        let (core, bytes) = make_pair(&mut maker, wire.as_mut(), (i, mid, opts.dt), heard, cfg)?;
        let bytes = bytes.filter(|_| reported);
        let input = pair_input(&core, w, rec.flip, heard.start.as_ref());
        // The pair is made (what it needs is copied out of the core), so
        // the next pair's planes go into the core while it is measured,
        // on another core when there is one: the same state either way.
        let next = all.get(i + 1).map(|&(m, _)| build(m));
        let (m, fed) = rayon::join(
            || ladder::measure(&input, mid, Ticks(dt as f64), cfg, (w, hu), reported),
            || next.map_or(Ok(()), |b| feed(&mut maker, &mut read, b)),
        );
        let mut m = m?;
        fed?;
        if let Some(mask) = &opts.mask {
            masked_out(&mut m.field, mask);
        }
        link.send(i, Ask::after(&m, cfg))?;
        if !reported {
            continue;
        }
        let ka = mid - half;
        let measured = measured_pair(m, (hu, w), dt as f64, bytes);
        out.take(measured, [ka, ka + dt], opts, opts.core.full_scale);
        tell();
    }
    Ok(out)
}

/// The pairs' first ticks, once the options are known to fit `rec`.
fn check(rec: &Recording, opts: &FlowOptions) -> Result<Vec<u64>, Error> {
    if opts.method == Method::Mc {
        return Err(Error::Schedule(
            "method mc is the sidecar's frames along the host's motion over a link (spiv-firmware-sim, spiv run); spiv flow's motion-compensated pairs are `ladder`, the default".into(),
        ));
    }
    if !(1..=255).contains(&opts.window) {
        return Err(Error::Schedule(format!(
            "window {}: expected 1..=255 ticks",
            opts.window
        )));
    }
    if opts.dt == 0 || opts.every < opts.dt {
        return Err(Error::Schedule(format!(
            "pairs every {} ticks, {} apart: dt must be at least 1 and every at least dt",
            opts.every, opts.dt
        )));
    }
    let ticks = opts.pair_ticks();
    if ticks.is_empty() {
        return Err(Error::Schedule(format!(
            "no pair fits: {} planes, first frame at {}, frames {} ticks apart (end {})",
            rec.planes, opts.start, opts.dt, opts.end
        )));
    }
    match &opts.pairs {
        None => Ok(ticks),
        Some(r) if r.start < r.end && r.end <= ticks.len() => Ok(ticks[r.clone()].to_vec()),
        Some(r) if r.start >= r.end => Err(Error::Schedule(format!(
            "pairs {}..{}: an empty range (the first pair, then one past the last; the schedule has pairs 0..{})",
            r.start,
            r.end,
            ticks.len()
        ))),
        Some(r) => Err(Error::Schedule(format!(
            "pairs {}..{}: the schedule has pairs 0..{}",
            r.start,
            r.end,
            ticks.len()
        ))),
    }
}

/// An adaptive pair with its windows capped per band by `prediction` (the
/// previous pair's usable field) or, without one, by the TFP pair at the
/// same ticks.
fn capped_pair(
    rec: &Recording,
    [ka, kb]: [u64; 2],
    opts: &FlowOptions,
    core: &Params,
    budget: f64,
    prediction: Option<Field>,
) -> Result<Measured, Error> {
    let (pred, bootstrapped) = match prediction {
        Some(p) => (p, false),
        None => {
            let ([a, b], _) = frames(rec, [ka, kb], Method::Tfp, BOOTSTRAP_WINDOW, core)?;
            (piv(&a, &b, opts.mask.as_ref(), &opts.piv)?, true)
        }
    };
    let dt = f64::from(opts.dt);
    let pa = rec.around(ka, core.n_max)?;
    let caps = caps_for(&pa, &pred.vectors(), dt, budget, core);
    let (a, la) = adaptive_banded(&pa, ka, core, &caps)?;
    let (b, lb) = adaptive_banded(&rec.around(kb, core.n_max)?, kb, core, &caps)?;
    let mut lost = LabelLoss::default();
    lost.add(&la);
    lost.add(&lb);
    let (w, h) = (usize::from(rec.crop_width), usize::from(rec.height));
    let frames = [to_f32(&a, w, h), to_f32(&b, w, h)];
    let field = piv(&frames[0], &frames[1], opts.mask.as_ref(), &opts.piv)?;
    Ok(Measured {
        method: Method::Adaptive,
        field,
        frames,
        caps,
        bootstrapped,
        rungs: Vec::new(),
        separation: Vec::new(),
        frame_ticks: dt,
        dense: None,
        lost,
        bytes: None,
    })
}

/// A pair of plain frames by `method` (TFP, TFI, adaptive with one n_max).
fn plain_pair(
    rec: &Recording,
    ticks: [u64; 2],
    opts: &FlowOptions,
    core: &Params,
    method: Method,
) -> Result<Measured, Error> {
    let (frames, lost) = frames(rec, ticks, method, opts.window, core)?;
    let field = piv(&frames[0], &frames[1], opts.mask.as_ref(), &opts.piv)?;
    Ok(Measured {
        method,
        field,
        frames,
        caps: Vec::new(),
        bootstrapped: false,
        rungs: Vec::new(),
        separation: Vec::new(),
        frame_ticks: f64::from(opts.dt),
        dense: None,
        lost,
        bytes: None,
    })
}

/// Both frames of a pair by `method` with window (or n_max) `n`.
fn frames(
    rec: &Recording,
    ticks: [u64; 2],
    method: Method,
    n: u16,
    core: &Params,
) -> Result<([Array2<f32>; 2], LabelLoss), Error> {
    let (w, h) = (usize::from(rec.crop_width), usize::from(rec.height));
    let mut out = [Array2::zeros((0, 0)), Array2::zeros((0, 0))];
    let mut lost = LabelLoss::default();
    for (o, k) in out.iter_mut().zip(ticks) {
        let f = frame_from_planes(&rec.around(k, n)?, k, method, n, core)?;
        if let Some(s) = &f.stats {
            lost.add(&s.labels);
        }
        *o = to_f32(&f.data, w, h);
    }
    Ok((out, lost))
}

fn pair_result(m: Measured, ticks: [u64; 2]) -> PairResult {
    PairResult {
        method: m.method,
        ticks,
        vectors: m.field.vectors(),
        sigma: m.field.sigma.iter().copied().collect(),
        caps: m.caps,
        bootstrapped: m.bootstrapped,
        lost: m.lost,
        rungs: m.rungs,
        separation: m.separation,
        bytes: m.bytes,
    }
}

/// A frame as gray levels `0..=full_scale` for plots and images: its
/// positive part scaled so its largest value is full scale.
fn gray(f: &Array2<f32>, full_scale: u16) -> Vec<u16> {
    let top = f.iter().copied().fold(0.0f32, f32::max);
    let k = if top > 0.0 {
        f32::from(full_scale) / top
    } else {
        0.0
    };
    f.iter()
        .map(|&x| (x.max(0.0) * k).round().min(f32::from(full_scale)) as u16)
        .collect()
}

/// The running sum of the pairs' dense fields.
#[derive(Default)]
struct DenseSum {
    sum: Option<(Vec<f64>, Vec<f64>, usize)>,
}

impl DenseSum {
    /// Adds `measured`, the dense flow `m` was measured by; else, for a
    /// pair of the time ladder with a usable field, its vectors
    /// interpolated between the nodes and carried along their paths over
    /// the pair; else the dense stage's field of `m`'s frames; in px per
    /// `dt` ticks.
    fn add(&mut self, m: &Measured, measured: Option<crate::piv::dense::Flow>, dt: f64) {
        let [a, b] = &m.frames;
        let (flow, k) = match measured {
            Some(f) => (f, 1.0),
            None if m.method == Method::Ladder && m.field.usable() => {
                let per_tick = PerPair::new(m.field.clone(), Ticks(dt)).per_tick();
                let (h, w) = a.dim();
                let (u, v) = per_tick.predictor(h, w);
                let (u, v) = crate::estimator::Velocity { u, v }.displacements(dt);
                (crate::piv::dense::Flow { u, v }, 1.0)
            }
            None => {
                let start = PerPair::new(m.field.clone(), Ticks(dt)).over(Ticks(m.frame_ticks));
                (
                    crate::piv::dense::for_piv(a, b, &start).0,
                    dt / m.frame_ticks,
                )
            }
        };
        let n = a.len();
        let d = self
            .sum
            .get_or_insert_with(|| (vec![0.0; n], vec![0.0; n], 0));
        for (s, x) in d.0.iter_mut().zip(flow.u.iter()) {
            *s += f64::from(*x) * k;
        }
        for (s, x) in d.1.iter_mut().zip(flow.v.iter()) {
            *s += f64::from(*x) * k;
        }
        d.2 += 1;
    }

    /// Adds another chain's sums (chains are merged in their order, so
    /// the sums do not depend on which thread ran which chain).
    fn merge(&mut self, other: DenseSum) {
        let Some((u, v, n)) = other.sum else {
            return;
        };
        match &mut self.sum {
            None => self.sum = Some((u, v, n)),
            Some(d) => {
                for (s, x) in d.0.iter_mut().zip(&u) {
                    *s += x;
                }
                for (s, x) in d.1.iter_mut().zip(&v) {
                    *s += x;
                }
                d.2 += n;
            }
        }
    }

    fn mean(self, w: usize, h: usize) -> Option<spiv_formats::dense::DenseField> {
        self.sum.map(|(u, v, n)| {
            let k = 1.0 / n.max(1) as f64;
            spiv_formats::dense::DenseField {
                width: w,
                height: h,
                u: u.iter().map(|x| (x * k) as f32).collect(),
                v: v.iter().map(|x| (x * k) as f32).collect(),
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_and_its_uncertainty() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(median_sigma(&[]), NO_SIGMA);
        // Four agreeing vectors of σ 0.2: 1.2533·0.2/2.
        let same = [(1.0, 2.0, (0.2, 0.2)); 4];
        let (su, sv) = median_sigma(&same);
        assert!((su - 0.125_33).abs() < 1e-9 && (sv - su).abs() < 1e-12);
        // Scattered ones: their spread wins.
        let spread = [
            (0.0, 0.0, (0.01, 0.01)),
            (1.0, 0.0, (0.01, 0.01)),
            (2.0, 0.0, (0.01, 0.01)),
        ];
        let (su, sv) = median_sigma(&spread);
        assert!((su - 1.2533 / 3f64.sqrt() * 1.4826).abs() < 1e-9, "{su}");
        assert!((sv - 1.2533 / 3f64.sqrt() * 0.01).abs() < 1e-9, "{sv}");
    }
}
