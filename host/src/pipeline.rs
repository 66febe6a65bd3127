//! The main job, one pair end to end: the simulated scene through the frame
//! camera and the spike camera; the spike stream through the sidecar
//! firmware loop (the core, then the wire: adaptive frames and the TFP
//! baseline) and the host's receiver; PIV on the three pairs; the paper's
//! metrics against the truth.

use serde::Serialize;
use spiv_core::Params;
use spiv_firmware_sim::scene::SceneParams;
use spiv_firmware_sim::simulation::{simulate_planes, Request, Simulated};
use spiv_formats::vectors::Vector;

use crate::baseline;
use crate::link::{dwell_caps, mc_transfer, transfer, transfer_with, Transfer};
use crate::metrics::{region_error, row_profile, ProfileRow, RegionError};
use crate::piv::{piv, to_f32, Field, Settings};
use crate::Error;
use spiv_core::motion::Refine;
use spiv_core::Method;
use spiv_firmware_sim::firmware::Config;

/// What one run does.
#[derive(Debug, Clone)]
pub struct Job {
    /// The scene and its seed.
    pub request: Request,
    /// The core's parameters (n_max is the adaptive window limit).
    pub core: Params,
    /// TFP window, ticks (the baseline).
    pub tfp_window: u16,
    /// PIV settings for all three pairs.
    pub piv: Settings,
    /// PIV settings of the motion-compensated pair.
    pub mc_piv: Settings,
    /// Beyond the paper (docs/spec.md §5): cap each band's adaptive window so that
    /// the fastest particle the TFP pair's PIV sees there blurs by at most
    /// this many px (`None`: the paper's algorithm, one n_max everywhere).
    pub dwell_cap: Option<f64>,
    /// How the sidecar codes the frames it sends (lossless Rice by default).
    pub encoding: spiv_core::wire::Encoding,
    /// Lossy mode settings.
    pub lossy: spiv_core::wire::codec::Lossy,
    /// The wide baseline's separation in pair separations (beyond the
    /// paper, [`crate::baseline`]): a second compensated pair this many
    /// `dt` apart, centred on the pair (`None` or below 2: none). The
    /// request's margin must hold its frames' windows ([`Job::new`] sets
    /// it so).
    pub wide: Option<u32>,
}

impl Job {
    /// The defaults for `scene` and `seed`: the simulation keeps ⌊n_max/2⌋
    /// ticks beyond the frames of the wide pair as well.
    pub fn new(scene: SceneParams, seed: u64) -> Job {
        let s = baseline::SEPARATION;
        let extra = baseline::reach(scene.pair_dt, s);
        let mut request = Request::new(scene, seed);
        request.margin += extra;
        Job {
            request,
            core: Params::default(),
            tfp_window: 8,
            piv: Settings::for_spike_frames(),
            mc_piv: Settings::for_compensated_frames(),
            dwell_cap: None,
            encoding: spiv_core::wire::Encoding::Rice,
            lossy: spiv_core::wire::codec::Lossy::default(),
            wide: Some(s),
        }
    }
}

/// The kinds of frames compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameKind {
    /// The frame camera.
    Frame,
    /// TFP of the spike stream.
    Tfp,
    /// The adaptive reconstruction.
    Adaptive,
    /// The adaptive reconstruction on motion-compensated counts (beyond the
    /// paper): the TFP pair's PIV predicts each row's velocity,
    /// the sidecar refines it from the spikes and sends the pair through
    /// the wire (in process: the prediction is handed to the firmware as the
    /// control link will carry it).
    Mc,
    /// The motion-compensated pair's field, each vector measured over a
    /// wide baseline where the flow allows it ([`crate::baseline`]): a
    /// second compensated pair `s·dt` apart centred on the pair, made
    /// with the same control, its PIV predicted by the pair's field.
    /// Without that pair (no prediction, or its ticks outside the
    /// recording), the motion-compensated pair's field.
    #[serde(rename = "mc_wide")]
    McWide,
}

impl FrameKind {
    /// All of them, in table order.
    pub const ALL: [FrameKind; 5] = [
        FrameKind::Frame,
        FrameKind::Tfp,
        FrameKind::Adaptive,
        FrameKind::Mc,
        FrameKind::McWide,
    ];

    /// File-name stem.
    pub fn name(self) -> &'static str {
        match self {
            FrameKind::Frame => "frame",
            FrameKind::Tfp => "tfp",
            FrameKind::Adaptive => "adaptive",
            FrameKind::Mc => "mc",
            FrameKind::McWide => "mc_wide",
        }
    }
}

/// One source's pair, field and errors.
#[derive(Debug, Clone)]
pub struct Measured {
    /// Which frames.
    pub source: FrameKind,
    /// The pair as gray levels (upright), with the full-scale value.
    pub pair: [Vec<u16>; 2],
    /// Gray level of full scale.
    pub full_scale: u16,
    /// The vectors.
    pub vectors: Vec<Vector>,
    /// Row profiles against the truth.
    pub rows: Vec<ProfileRow>,
    /// Errors in the glare rows.
    pub glare: RegionError,
    /// Errors in the other rows.
    pub rest: RegionError,
    /// PIV time, ms.
    pub piv_ms: f64,
}

/// A finished run.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The simulation (scene, metadata, frame camera pair).
    pub sim: Simulated,
    /// The truth on the PIV grid.
    pub truth: Vec<Vector>,
    /// Each of [`FrameKind::ALL`], in that order.
    pub measured: Vec<Measured>,
    /// Height above the wall below which a vector row is in the glare band, px.
    pub glare_limit: f64,
    /// Time of each stage, ms: simulate, sidecar (core and wire), PIV (all three).
    pub stage_ms: [f64; 3],
    /// What the link carried.
    pub link: LinkSummary,
}

/// What the sidecar link carried in a run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct LinkSummary {
    /// Bytes of the adaptive pair on the wire.
    pub adaptive_bytes: u64,
    /// Bytes of the TFP pair on the wire.
    pub tfp_bytes: u64,
    /// Bytes of the motion-compensated pair on the wire (0 when it fell
    /// back to the adaptive pair).
    pub mc_bytes: u64,
    /// Bytes of the wide-baseline pair on the wire (0 when none was made).
    pub wide_bytes: u64,
    /// Raw spike bytes over the ticks of one pair period (4·dt).
    pub raw_bytes_per_period: u64,
    /// Frames lost or corrupted on the way (0 in process).
    pub lost_frames: u64,
    /// Whether the received frames equal what the firmware made.
    pub bit_exact: bool,
}

/// Runs `job`; `stage` is told the name of each stage as it starts.
pub fn run(job: &Job, mut stage: impl FnMut(&str)) -> Result<Outcome, Error> {
    let t0 = std::time::Instant::now();
    stage("simulating both cameras");
    let (data, sim) = simulate_planes(&job.request)?;
    let t_sim = t0.elapsed().as_secs_f64() * 1e3;

    stage("sidecar: core and wire");
    let (frames, link) = sidecar_frames(job, &sim, &data)?;
    let t_rec = t0.elapsed().as_secs_f64() * 1e3 - t_sim;

    stage("PIV on three pairs");
    let (truth, measured) = measure_pairs(job, &sim, frames)?;
    let t_piv = t0.elapsed().as_secs_f64() * 1e3 - t_sim - t_rec;
    Ok(Outcome {
        sim,
        truth,
        measured,
        glare_limit: 2.0 * job.request.scene.glare_sigma,
        stage_ms: [t_sim, t_rec, t_piv],
        link,
    })
}

/// The spike camera's pairs as the host received them (upright): TFP,
/// adaptive, motion-compensated and its wide pair (`None` where the
/// recording does not hold its windows), with the wide pair's separation.
struct SpikeFrames {
    tfp: [Vec<u16>; 2],
    adaptive: [Vec<u16>; 2],
    mc: [Vec<u16>; 2],
    wide: Option<[Vec<u16>; 2]>,
    wide_s: Option<u32>,
}

/// Whether every frame `t` received is the one the firmware sent.
fn exact(t: &Transfer) -> bool {
    t.pairs.iter().flatten().all(|r| {
        t.sent
            .iter()
            .any(|s| s.frame_id == r.frame_id && s.data == r.data)
    })
}

/// The first pair `t` received, upright; `what` names it in the error.
fn upright(t: &Transfer, what: &'static str) -> Result<[Vec<u16>; 2], Error> {
    let [a, b] = t.pairs.first().ok_or(Error::NoPair(what))?;
    Ok([a.upright(), b.upright()])
}

/// Runs the sidecar firmware on the spikes for each kind of spike frames
/// and carries them over the wire: the TFP and adaptive pairs (the
/// adaptive windows capped by the dwell cap), then the motion-compensated
/// pair predicted by the TFP pair's PIV, and its wide pair.
fn sidecar_frames(
    job: &Job,
    sim: &Simulated,
    data: &[u8],
) -> Result<(SpikeFrames, LinkSummary), Error> {
    let p = &job.request.scene;
    let (w, h) = (p.width, p.height);
    let [ka, kb] = sim.meta.capture.pair;
    let mut base = Config::new(ka, kb - ka);
    base.params = job.core;
    base.schedule.pairs = Some(1);
    base.encoding = job.encoding;
    base.lossy = job.lossy;
    let (caps, tfp_t) = match job.dwell_cap {
        Some(budget) => dwell_caps(data, w, h, &base, job.tfp_window, budget, &job.piv)?,
        None => {
            let cfg = Config {
                method: Method::Tfp,
                tfp_window: job.tfp_window,
                ..base
            };
            (Vec::new(), transfer(data, w, h, cfg, Vec::new())?)
        }
    };
    let ad_t = transfer(data, w, h, base, caps)?;
    let tfp = upright(&tfp_t, "TFP")?;
    let adaptive = upright(&ad_t, "adaptive")?;
    let mc = compensated(job, sim, data, base, &tfp, &adaptive)?;
    let link = LinkSummary {
        adaptive_bytes: ad_t.bytes,
        tfp_bytes: tfp_t.bytes,
        mc_bytes: mc.pair_t.as_ref().map_or(0, |t| t.bytes),
        wide_bytes: mc.wide_t.as_ref().map_or(0, |t| t.bytes),
        raw_bytes_per_period: u64::from(base.schedule.every) * u64::from(w) * u64::from(h) / 8,
        lost_frames: ad_t.report.lost_frames
            + tfp_t.report.lost_frames
            + mc.pair_t.as_ref().map_or(0, |t| t.report.lost_frames)
            + mc.wide_t.as_ref().map_or(0, |t| t.report.lost_frames),
        bit_exact: exact(&ad_t)
            && exact(&tfp_t)
            && mc.pair_t.as_ref().is_none_or(exact)
            && mc.wide_t.as_ref().is_none_or(exact),
    };
    let frames = SpikeFrames {
        tfp,
        adaptive,
        mc: mc.pair,
        wide: mc.wide,
        wide_s: mc.wide_s,
    };
    Ok((frames, link))
}

/// The motion-compensated pair and its wide pair, with what carried them.
struct Compensated {
    pair: [Vec<u16>; 2],
    pair_t: Option<Transfer>,
    wide: Option<[Vec<u16>; 2]>,
    wide_t: Option<Transfer>,
    wide_s: Option<u32>,
}

/// The motion-compensated pair: the TFP pair's PIV predicts each row's
/// velocity (as `spiv flow` does), sent to the sidecar as a control
/// message on its downlink; the sidecar refines it from the spikes and
/// sends the pair, whose own field predicts it once more. Without a
/// usable field, the adaptive pair. The wide pair takes the same control,
/// frames `s·dt` apart centred on the pair (when the recording holds their
/// windows), and the two measure together for [`baseline::ROUNDS`] more
/// rounds, their combined field the next control.
fn compensated(
    job: &Job,
    sim: &Simulated,
    data: &[u8],
    base: Config,
    tfp: &[Vec<u16>; 2],
    adaptive: &[Vec<u16>; 2],
) -> Result<Compensated, Error> {
    let p = &job.request.scene;
    let (w, h) = (p.width, p.height);
    let (wu, hu) = (usize::from(w), usize::from(h));
    let [ka, kb] = sim.meta.capture.pair;
    let dt_ticks = f64::from(kb - ka);
    let pred = piv(
        &to_f32(&tfp[0], wu, hu),
        &to_f32(&tfp[1], wu, hu),
        None,
        &job.piv,
    )?
    .vectors();
    let cfg = Config {
        refine: Some(Refine::default()),
        ..base
    };
    let Some((control, pair_t)) = mc_transfer(data, (w, h), cfg, &pred, dt_ticks, &job.mc_piv)?
    else {
        return Ok(Compensated {
            pair: adaptive.clone(),
            pair_t: None,
            wide: None,
            wide_t: None,
            wide_s: job.wide.filter(|&s| s >= 2),
        });
    };
    let mut out = Compensated {
        pair: upright(&pair_t, "motion-compensated")?,
        pair_t: Some(pair_t),
        wide: None,
        wide_t: None,
        wide_s: job.wide.filter(|&s| s >= 2),
    };
    let Some((s, wcfg)) = out
        .wide_s
        .and_then(|s| wide_config(cfg, s, [ka, kb], job, sim).map(|c| (s, c)))
    else {
        return Ok(out);
    };
    let wt = transfer_with(data, w, h, wcfg, control)?;
    out.wide = Some(upright(&wt, "wide-baseline")?);
    out.wide_t = Some(wt);
    for _ in 0..baseline::ROUNDS {
        let Some(wp) = &out.wide else { break };
        let narrow = piv(
            &to_f32(&out.pair[0], wu, hu),
            &to_f32(&out.pair[1], wu, hu),
            None,
            &job.mc_piv,
        )?;
        let (wa, wb) = (to_f32(&wp[0], wu, hu), to_f32(&wp[1], wu, hu));
        let field = baseline::measure(&narrow, (&wa, &wb), s, &job.mc_piv)?;
        if !crate::predict::predicts(&field) {
            break;
        }
        let control =
            crate::predict::motion_grid(&field, (w, h), true, dt_ticks, Default::default())
                .control();
        let pair_cfg = Config {
            method: Method::Mc,
            ..cfg
        };
        let pair_t = transfer_with(data, w, h, pair_cfg, control.clone())?;
        let wt = transfer_with(data, w, h, wcfg, control)?;
        out.pair = upright(&pair_t, "motion-compensated")?;
        out.pair_t = Some(pair_t);
        out.wide = Some(upright(&wt, "wide-baseline")?);
        out.wide_t = Some(wt);
    }
    Ok(out)
}

/// The sidecar's configuration of the wide pair `s·dt` apart centred on
/// the pair `[ka, kb]`, when the recording holds its windows.
fn wide_config(
    cfg: Config,
    s: u32,
    [ka, kb]: [u32; 2],
    job: &Job,
    sim: &Simulated,
) -> Option<Config> {
    let planes = sim.meta.capture.planes;
    baseline::ticks_within(u64::from(ka), kb - ka, s, job.core.n_max, planes).map(|(k0, k1)| {
        // Frame ticks are u32 on the sidecar: ticks_within found both
        // below ka + s·dt.
        let (k0, k1) = (k0 as u32, k1 as u32);
        let mut wcfg = Config {
            method: Method::Mc,
            ..cfg
        };
        wcfg.schedule.first = k0;
        wcfg.schedule.dt = k1 - k0;
        wcfg.schedule.every = (k1 - k0).saturating_mul(4);
        wcfg
    })
}

/// PIV on the frame camera's pair and each spike pair, against the truth
/// on each field's grid: returns the truth on `job.piv`'s grid and every
/// kind's measurement. The wide pair is measured with the compensated
/// pair's field ([`baseline::measure`]), or is that field where there is
/// no wide pair.
fn measure_pairs(
    job: &Job,
    sim: &Simulated,
    frames: SpikeFrames,
) -> Result<(Vec<Vector>, Vec<Measured>), Error> {
    let p = &job.request.scene;
    let (w, h) = (p.width, p.height);
    let (wu, hu) = (usize::from(w), usize::from(h));
    let dt = f64::from(sim.meta.capture.pair[1] - sim.meta.capture.pair[0]);
    let truth = sim.scene.truth_vectors(&job.piv.centres(w, h), dt);
    let glare_limit = 2.0 * p.glare_sigma;
    let has_wide = frames.wide.is_some();
    let wide_pair = frames.wide.unwrap_or_else(|| frames.mc.clone());
    let pairs: [(FrameKind, [Vec<u16>; 2], u16); 5] = [
        (
            FrameKind::Frame,
            sim.frames.clone(),
            job.request.camera.max_dn(),
        ),
        (FrameKind::Tfp, frames.tfp, job.core.full_scale),
        (FrameKind::Adaptive, frames.adaptive, job.core.full_scale),
        (FrameKind::Mc, frames.mc, job.core.full_scale),
        (FrameKind::McWide, wide_pair, job.core.full_scale),
    ];
    let mut measured: Vec<Measured> = Vec::new();
    let mut mc_field: Option<(Field, f64)> = None;
    for (source, pair, full_scale) in pairs {
        let t = std::time::Instant::now();
        let settings = match source {
            FrameKind::Mc | FrameKind::McWide => &job.mc_piv,
            _ => &job.piv,
        };
        let (vectors, piv_ms) = match (source, &mc_field, frames.wide_s) {
            (FrameKind::McWide, Some((narrow, narrow_ms)), Some(s)) if has_wide => {
                let (a, b) = (to_f32(&pair[0], wu, hu), to_f32(&pair[1], wu, hu));
                let v = baseline::measure(narrow, (&a, &b), s, settings)?;
                (v, narrow_ms + t.elapsed().as_secs_f64() * 1e3)
            }
            (FrameKind::McWide, Some((narrow, narrow_ms)), _) => (narrow.vectors(), *narrow_ms),
            _ => {
                let field = piv(
                    &to_f32(&pair[0], wu, hu),
                    &to_f32(&pair[1], wu, hu),
                    None,
                    settings,
                )?;
                let ms = t.elapsed().as_secs_f64() * 1e3;
                let v = field.vectors();
                if source == FrameKind::Mc {
                    mc_field = Some((field, ms));
                }
                (v, ms)
            }
        };
        // The truth on this field's grid (the compensated pair's settings
        // may end on another window).
        let own_truth;
        let truth = if settings.centres(w, h) == job.piv.centres(w, h) {
            &truth
        } else {
            own_truth = sim.scene.truth_vectors(&settings.centres(w, h), dt);
            &own_truth
        };
        let rows = row_profile(&vectors, truth, f64::from(h));
        let glare = region_error(&rows, |y| y < glare_limit);
        let rest = region_error(&rows, |y| y >= glare_limit);
        measured.push(Measured {
            source,
            pair,
            full_scale,
            vectors,
            rows,
            glare,
            rest,
            piv_ms,
        });
    }
    Ok((truth, measured))
}
