//! `spiv flow`: the main job on any spike recording (a Vidar `.dat` or a
//! `.npz` capture): frame pairs through the core at a fixed schedule, PIV on
//! each, with the flow predicted so long windows do not blur. No window
//! needs hand-tuning.
//!
//! - `mc` (the default, beyond the paper; issue 14): motion-compensated
//!   adaptive frames. PIV of the TFP pair (window 8) at the same ticks
//!   predicts each row's velocity, the core refines it from the spikes by
//!   contrast maximisation, and the core counts every particle along its
//!   path (`crate::predict`); the compensated pair's own field then
//!   predicts it once more (`predict::ROUNDS`).
//! - `adaptive` with a dwell cap (SPEC 5): a time-resolved loop; the field
//!   of the previous pair predicts each 32-row band's fastest particle, and
//!   the band's adaptive window is capped so it blurs by at most the budget.
//!   The first pair — and any pair after one whose PIV found less than half
//!   its vectors valid — is bootstrapped from a TFP pair. Without a cap:
//!   the paper's algorithm, one n_max everywhere.
//! - `tfp`, `tfi`: the baselines.
//!
//! Memory is bounded by the frames, not the recording: a `.dat` is read
//! window by window (only the planes a frame needs), a `.npz` capture is
//! held packed (at most `spiv_formats::MAX_NPZ_SAMPLES` samples).

use std::path::Path;

use spiv_core::{Method, Params};
use spiv_formats::capture::Capture;
use spiv_formats::dat::DatReader;
use spiv_formats::npz::read_npz_spikes;
use spiv_formats::{FormatError, State, Vector};

use crate::dwell::{adaptive_banded, caps_for};
use crate::piv::{piv, to_f32, PivError, Settings};
use crate::predict::{compensated_frame, row_velocities};
use crate::reconstruct::{frame_from_planes, FileOptions, Planes, ReconstructError};
use spiv_core::motion::Refine;

/// The TFP window of the bootstrap pair, ticks.
pub const BOOTSTRAP_WINDOW: u16 = 8;

/// Everything `spiv flow` can refuse.
#[derive(Debug, thiserror::Error)]
pub enum FlowError {
    /// Reading the recording.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// Making a frame.
    #[error(transparent)]
    Reconstruct(#[from] ReconstructError),
    /// PIV.
    #[error(transparent)]
    Piv(#[from] PivError),
    /// A schedule the recording cannot hold, or a bad option.
    #[error("{0}")]
    Schedule(String),
}

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
}

#[derive(Debug)]
enum Source {
    Dat(DatReader<std::io::BufReader<std::fs::File>>),
    Memory(Vec<u8>),
}

impl Recording {
    /// Opens a `.dat` (size from `opts` or the `scene.json` beside it) or a
    /// `.npz` capture (by extension).
    pub fn open(path: &Path, opts: &FileOptions) -> Result<Recording, FlowError> {
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
                source: Source::Memory(s.planes),
            });
        }
        let meta = Capture::beside(path)?;
        let (w, h) = match (opts.width, opts.height, &meta) {
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
            meta_dt: meta.map(|m| m.pair[1].saturating_sub(m.pair[0])),
            source: Source::Dat(r),
        })
    }

    /// The planes a window of `window` ticks centred on `k` needs (clipped
    /// at the recording's ends).
    pub fn around(&mut self, k: u64, window: u16) -> Result<Planes, FlowError> {
        let first = k.saturating_sub(u64::from(window / 2));
        let n = u64::from(window).min(self.planes.saturating_sub(first));
        let data = match &mut self.source {
            Source::Dat(r) => r.read_range(first, n)?,
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
    /// Core parameters (`n_max` is set from `window`).
    pub core: Params,
    /// PIV settings of TFP, TFI and adaptive pairs (and of the TFP pairs
    /// that predict motion).
    pub piv: Settings,
    /// PIV settings of motion-compensated pairs (more passes: their
    /// deformation converges where glare hides a window's lower particles).
    pub mc_piv: Settings,
    /// Also run the dense stage on every pair ([`crate::piv::dense`]) and
    /// average it into [`FlowOutcome::mean_dense`].
    pub dense: bool,
    /// Motion-compensated pairs: the wide baseline's separation in pair
    /// separations ([`crate::baseline`]; `None` or below 2: none). A pair
    /// whose wide frames' windows do not fit the recording keeps its own
    /// field.
    pub wide: Option<u32>,
}

impl FlowOptions {
    /// The defaults for `rec` with pairs `dt` ticks apart: motion-compensated
    /// adaptive frames (`mc`), n_max 128, one pair
    /// every `4·dt` ticks from the first tick whose window is whole (or, on
    /// a recording too short for that, the first pair as central as it
    /// fits), to the end, spike-frame PIV settings.
    pub fn new(rec: &Recording, dt: u32) -> FlowOptions {
        let core = Params::default();
        let last = rec.planes.saturating_sub(1 + u64::from(dt));
        FlowOptions {
            method: Method::Mc,
            window: core.n_max,
            dwell_cap: Some(8.0),
            dt,
            every: dt.saturating_mul(4),
            start: u64::from(core.n_max / 2).min(last / 2),
            end: rec.planes,
            core,
            piv: Settings::for_spike_frames(),
            mc_piv: Settings::for_compensated_frames(),
            dense: false,
            wide: Some(crate::baseline::SEPARATION),
        }
    }

    /// The pairs' first ticks.
    pub fn pair_ticks(&self) -> Vec<u64> {
        let every = u64::from(self.every.max(1));
        let mut out = Vec::new();
        let mut k = self.start;
        while k + u64::from(self.dt) < self.end {
            out.push(k);
            k += every;
        }
        out
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
    /// algorithm, one n_max everywhere). Default 8.
    pub dwell_cap: Option<f64>,
    /// PIV window side of each pass, px (default: 64,32,32, and
    /// 64,32,32,32,32 for motion-compensated pairs).
    pub windows: Option<Vec<usize>>,
    /// Run the dense stage on every pair and average it.
    pub dense: bool,
    /// Motion-compensated pairs: the wide baseline's separation in pair
    /// separations (default [`crate::baseline::SEPARATION`]; `None`: off).
    pub wide: Option<u32>,
}

impl Default for FlowRequest {
    fn default() -> Self {
        FlowRequest {
            dt: None,
            every: None,
            start: None,
            end: None,
            method: Method::Mc,
            window: None,
            dwell_cap: Some(8.0),
            windows: None,
            dense: false,
            wide: Some(crate::baseline::SEPARATION),
        }
    }
}

impl FlowRequest {
    /// The run's options over `rec` (read from `input`, named in the
    /// messages).
    pub fn options(&self, rec: &Recording, input: &Path) -> Result<FlowOptions, FlowError> {
        let dt = self.dt.or(rec.meta_dt).ok_or_else(|| {
            FlowError::Schedule(format!(
                "{}: give --dt (ticks between the frames of a pair): no scene.json beside it names one",
                input.display()
            ))
        })?;
        if dt == 0 || u64::from(dt) >= rec.planes {
            return Err(FlowError::Schedule(format!(
                "--dt {dt}: expected 1..{} (the recording has {} planes)",
                rec.planes, rec.planes
            )));
        }
        if let Some(c) = self.dwell_cap {
            if !(c.is_finite() && c > 0.0 && c <= 1000.0) {
                return Err(FlowError::Schedule(format!(
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
        o.start = self.start.unwrap_or(o.start);
        o.end = self.end.unwrap_or(o.end).min(rec.planes);
        if let Some(w) = &self.windows {
            o.piv.windows = w.clone();
            o.mc_piv.windows = w.clone();
        }
        o.dense = self.dense;
        if let Some(s) = self.wide {
            if !(2..=64).contains(&s) {
                return Err(FlowError::Schedule(format!(
                    "--wide {s}: expected 2..=64 pair separations, or off"
                )));
            }
        }
        o.wide = self.wide;
        Ok(o)
    }
}

/// One pair's result.
#[derive(Debug, Clone)]
pub struct PairResult {
    /// How its frames were made: the method asked for, or `Adaptive` where
    /// `Mc` had no flow to predict from (fewer than half of the TFP pair's
    /// vectors valid).
    pub method: Method,
    /// The pair's frame ticks.
    pub ticks: [u64; 2],
    /// The field (upright, row-major on the PIV grid).
    pub vectors: Vec<Vector>,
    /// Window caps per 32-row band the pair's adaptive frames used (empty:
    /// none).
    pub caps: Vec<u16>,
    /// The caps came from a TFP pair at the same ticks, not from the
    /// previous pair.
    pub bootstrapped: bool,
    /// What the core's tables could not hold in the pair's compensated
    /// frames (left as background).
    pub lost: LabelLoss,
    /// The wide pair's frame ticks, when one measured the field
    /// ([`crate::baseline`]).
    pub wide: Option<[u64; 2]>,
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
    /// With [`FlowOptions::dense`]: the mean over pairs of the dense stage's
    /// field (px per pair, v down, upright).
    pub mean_dense: Option<spiv_formats::dense::DenseField>,
}

impl FlowOutcome {
    /// What the core's full tables lost over all pairs.
    pub fn lost(&self) -> LabelLoss {
        let mut l = LabelLoss::default();
        for p in &self.pairs {
            l.merge(p.lost);
        }
        l
    }

    /// The mean field over pairs: per grid node the mean of the measured
    /// (valid or replaced) vectors, invalid where no pair measured it.
    pub fn mean_field(&self) -> Vec<Vector> {
        let Some(first) = self.pairs.first() else {
            return Vec::new();
        };
        first
            .vectors
            .iter()
            .enumerate()
            .map(|(i, v0)| {
                let (mut u, mut v, mut n) = (0.0, 0.0, 0usize);
                for p in &self.pairs {
                    if let Some(x) = p.vectors.get(i).filter(|x| x.state.is_measured()) {
                        u += x.u;
                        v += x.v;
                        n += 1;
                    }
                }
                let state = if n > 0 { State::Valid } else { State::Invalid };
                let n = n.max(1) as f64;
                Vector {
                    u: u / n,
                    v: v / n,
                    state,
                    ..*v0
                }
            })
            .collect()
    }
}

/// Both frames of a motion-compensated pair at `ticks`, counted along
/// `vel` as the core refines it, and what their labelling lost.
fn compensated_pair(
    rec: &mut Recording,
    ticks: [u64; 2],
    core: &Params,
    vel: &crate::predict::RowVelocities,
) -> Result<([Vec<u16>; 2], LabelLoss), FlowError> {
    let mut out = [Vec::new(), Vec::new()];
    let mut lost = LabelLoss::default();
    for (o, k) in out.iter_mut().zip(ticks) {
        let pl = rec.around(k, core.n_max)?;
        let (f, _, labels) = compensated_frame(&pl, k, core, vel, Some(Refine::default()))?;
        *o = f;
        lost.add(&labels);
    }
    Ok((out, lost))
}

/// Runs the flow job over `rec`; `progress` is told (pairs done, pairs).
pub fn run_flow(
    rec: &mut Recording,
    opts: &FlowOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<FlowOutcome, FlowError> {
    if !(1..=255).contains(&opts.window) {
        return Err(FlowError::Schedule(format!(
            "window {}: expected 1..=255 ticks",
            opts.window
        )));
    }
    if opts.dt == 0 || opts.every < opts.dt {
        return Err(FlowError::Schedule(format!(
            "pairs every {} ticks, {} apart: dt must be at least 1 and every at least dt",
            opts.every, opts.dt
        )));
    }
    let ticks = opts.pair_ticks();
    if ticks.is_empty() {
        return Err(FlowError::Schedule(format!(
            "no pair fits: {} planes, first frame at {}, frames {} ticks apart (end {})",
            rec.planes, opts.start, opts.dt, opts.end
        )));
    }
    let core = Params {
        n_max: opts.window.max(opts.core.n0),
        ..opts.core
    };
    let dt = f64::from(opts.dt);
    let (w, h) = (rec.crop_width, rec.height);
    let (wu, hu) = (usize::from(w), usize::from(h));
    let field_with = |a: &[u16], b: &[u16], s: &Settings| -> Result<Vec<Vector>, FlowError> {
        Ok(piv(&to_f32(a, wu, hu), &to_f32(b, wu, hu), None, s)?.vectors())
    };
    let field = |a: &[u16], b: &[u16]| field_with(a, b, &opts.piv);
    let mut prediction: Option<Vec<Vector>> = None;
    let mut pairs = Vec::with_capacity(ticks.len());
    let mut first_frames = None;
    let mut dense_sum: Option<(Vec<f64>, Vec<f64>, usize)> = None;
    for (i, &ka) in ticks.iter().enumerate() {
        let kb = ka + u64::from(opts.dt);
        let frames =
            |rec: &mut Recording, method: Method, n: u16| -> Result<[Vec<u16>; 2], FlowError> {
                let mut out = [Vec::new(), Vec::new()];
                for (o, k) in out.iter_mut().zip([ka, kb]) {
                    *o = frame_from_planes(&rec.around(k, n)?, k, method, n, &core)?.data;
                }
                Ok(out)
            };
        let mut made = opts.method;
        let mut lost = LabelLoss::default();
        // The compensated pair's last control, for its wide pair.
        let mut mc_vel: Option<crate::predict::RowVelocities> = None;
        let (pair, caps, bootstrapped) = match (opts.method, opts.dwell_cap) {
            (Method::Adaptive, Some(budget)) => {
                let (pred, boot) = match prediction.take() {
                    Some(p) => (p, false),
                    None => {
                        let [a, b] = frames(rec, Method::Tfp, BOOTSTRAP_WINDOW)?;
                        (field(&a, &b)?, true)
                    }
                };
                let pa = rec.around(ka, core.n_max)?;
                let caps = caps_for(&pa, &pred, dt, budget, &core);
                let a = adaptive_banded(&pa, ka, &core, &caps)?;
                let b = adaptive_banded(&rec.around(kb, core.n_max)?, kb, &core, &caps)?;
                ([a, b], caps, boot)
            }
            (Method::Mc, _) => {
                // Predicted by the TFP pair at the same ticks, every pair:
                // chaining each pair's field into the next drifted in the
                // glare rows (paper-linear, 11 pairs: glare RMAE 0.13/0.27
                // against 0.03/0.09), while contrast maximisation makes the
                // TFP prediction exact enough outside them.
                let [a, b] = frames(rec, Method::Tfp, BOOTSTRAP_WINDOW)?;
                let pred = field(&a, &b)?;
                if !crate::predict::predicts(&pred) {
                    // No flow to predict from (a TFP pair too dark or too
                    // noisy for PIV): compensating a guess would move static
                    // light into "particles". The plain adaptive frames,
                    // capped by whatever the field says.
                    let pa = rec.around(ka, core.n_max)?;
                    let caps = caps_for(&pa, &pred, dt, 8.0, &core);
                    let a = adaptive_banded(&pa, ka, &core, &caps)?;
                    let b = adaptive_banded(&rec.around(kb, core.n_max)?, kb, &core, &caps)?;
                    made = Method::Adaptive;
                    ([a, b], caps, true)
                } else {
                    let mut out = [Vec::new(), Vec::new()];
                    let mut pred = pred;
                    // The TFP field, then the compensated pair's own
                    // (`predict::ROUNDS`).
                    for round in 0..crate::predict::ROUNDS {
                        if round > 0 {
                            let own = field_with(&out[0], &out[1], &opts.mc_piv)?;
                            if !crate::predict::predicts(&own) {
                                break;
                            }
                            pred = own;
                        }
                        let vel = row_velocities(&pred, rec.height, rec.flip, dt);
                        (out, lost) = compensated_pair(rec, [ka, kb], &core, &vel)?;
                        mc_vel = Some(vel);
                    }
                    (out, Vec::new(), true)
                }
            }
            (m, _) => (frames(rec, m, opts.window)?, Vec::new(), false),
        };
        let settings = match made {
            Method::Mc => &opts.mc_piv,
            _ => &opts.piv,
        };
        let mut pair = pair;
        let (mut fa, mut fb) = (to_f32(&pair[0], wu, hu), to_f32(&pair[1], wu, hu));
        let mut f = piv(&fa, &fb, None, settings)?;
        // The wide baseline: compensated frames s·dt apart centred on the
        // pair, with the pair's last control, where their windows fit;
        // their combined field predicts both pairs once more
        // (`baseline::ROUNDS`).
        let planes = rec.planes.min(opts.end);
        let wide_ticks = match (made, &mc_vel, opts.wide.filter(|&s| s >= 2)) {
            (Method::Mc, Some(_), Some(s)) => {
                crate::baseline::ticks_within(ka, opts.dt, s, core.n_max, planes)
                    .map(|(k0, k1)| (k0, k1, s))
            }
            _ => None,
        };
        let (vectors, wide) = match (wide_ticks, mc_vel) {
            (Some((k0, k1, s)), Some(mut vel)) => {
                let mut round = 0;
                loop {
                    let (wf, wide_lost) = compensated_pair(rec, [k0, k1], &core, &vel)?;
                    let (wa, wb) = (to_f32(&wf[0], wu, hu), to_f32(&wf[1], wu, hu));
                    let combined = crate::baseline::measure(&f, (&wa, &wb), s, settings)?;
                    if round == crate::baseline::ROUNDS || !crate::predict::predicts(&combined) {
                        lost.merge(wide_lost);
                        break (combined, Some([k0, k1]));
                    }
                    round += 1;
                    vel = row_velocities(&combined, rec.height, rec.flip, dt);
                    (pair, lost) = compensated_pair(rec, [ka, kb], &core, &vel)?;
                    (fa, fb) = (to_f32(&pair[0], wu, hu), to_f32(&pair[1], wu, hu));
                    f = piv(&fa, &fb, None, settings)?;
                }
            }
            _ => (f.vectors(), None),
        };
        if opts.dense {
            let (flow, _) = crate::piv::dense::for_piv(&fa, &fb, &f);
            let d = dense_sum.get_or_insert_with(|| (vec![0.0; wu * hu], vec![0.0; wu * hu], 0));
            for (s, x) in d.0.iter_mut().zip(flow.u.iter()) {
                *s += f64::from(*x);
            }
            for (s, x) in d.1.iter_mut().zip(flow.v.iter()) {
                *s += f64::from(*x);
            }
            d.2 += 1;
        }
        let valid = vectors.iter().filter(|v| v.state == State::Valid).count();
        // A pair that mostly failed predicts nothing: bootstrap again.
        prediction = (2 * valid >= vectors.len()).then(|| vectors.clone());
        if first_frames.is_none() {
            first_frames = Some(pair);
        }
        pairs.push(PairResult {
            method: made,
            ticks: [ka, kb],
            vectors,
            caps,
            bootstrapped,
            lost,
            wide,
        });
        progress(i + 1, ticks.len());
    }
    Ok(FlowOutcome {
        pairs,
        first_frames: first_frames.unwrap_or_default(),
        size: (w, h),
        full_scale: core.full_scale,
        mean_dense: dense_sum.map(|(u, v, n)| {
            let k = 1.0 / n.max(1) as f64;
            spiv_formats::dense::DenseField {
                width: wu,
                height: hu,
                u: u.iter().map(|x| (x * k) as f32).collect(),
                v: v.iter().map(|x| (x * k) as f32).collect(),
            }
        }),
    })
}
