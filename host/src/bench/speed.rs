//! Speed against error (`spiv bench speed`): every way spiv makes and
//! measures a frame pair, timed and held to the truth on one scene.

use std::time::Instant;

use ndarray::Array2;
use spiv_firmware_sim::firmware::Config;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::simulate_planes;
use spiv_formats::grid::Grid;

use crate::link::{dwell_caps, transfer, upright_f32};
use crate::metrics::{region_error, row_profile};
use crate::pipeline::{Job, JobError};
use crate::piv::{piv, to_f32, Interp, Settings};
use crate::reconstruct::{frame_from_planes, Method, Planes};
use crate::reference::{adaptive_frame, SpikeVolume};

/// One configuration: its name, wall time per frame pair and error.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedRow {
    /// What ran: reconstruction and PIV settings.
    pub name: String,
    /// Wall time per frame pair (both frames and PIV; PIV the median of
    /// 3 runs), ms.
    pub ms: f64,
    /// RMSE of the row profile u(y) against the truth, px per pair.
    pub rmse: f64,
}

/// Speed against error on paper-linear seed 1 (400×250): the frame camera
/// and the core's frames (TFP, adaptive at several window limits, dwell
/// caps, through the sidecar and the wire, the f64 reference), each with
/// PIV; `progress` is called after each of the 15 groups.
pub fn speed_against_error(mut progress: impl FnMut()) -> Result<Vec<SpeedRow>, JobError> {
    let job = Job::new(SceneParams::new(SceneKind::PaperLinear), 1);
    let p = &job.request.scene;
    let (w, h) = (p.width, p.height);
    let (data, sim) = simulate_planes(&job.request)?;
    let planes = Planes::simulated(w, h, data);
    let [ka, kb] = sim.meta.capture.pair.map(u64::from);
    let dt = (kb - ka) as f64;
    let (wu, hu) = (usize::from(w), usize::from(h));
    // The paper's grid: 32-px windows every 16 px.
    let centres = Grid::new(wu, hu, 32, 16).map(|g| g.centres());
    let truth = sim.scene.truth_vectors(&centres.unwrap_or_default(), dt);
    let to = |d: &[u16]| to_f32(d, wu, hu);
    // PIV time: the median of 3 runs (the first run of the process also
    // pays for starting the thread pool and touching fresh memory).
    let err = |a: &Array2<f32>,
               b: &Array2<f32>,
               s: &Settings|
     -> Result<(f64, f64, crate::piv::Field), JobError> {
        let mut times = [0.0f64; 3];
        let mut field = None;
        for t in times.iter_mut() {
            let start = Instant::now();
            field = Some(piv(a, b, None, s)?);
            *t = start.elapsed().as_secs_f64() * 1e3;
        }
        times.sort_by(f64::total_cmp);
        let ms = times[1];
        let f = field.ok_or(JobError::NoPair("PIV"))?;
        let rows = row_profile(&f.vectors(), &truth, f64::from(h));
        Ok((ms, region_error(&rows, |_| true).rmse, f))
    };
    let mut rows: Vec<SpeedRow> = Vec::new();
    let base = job.piv.clone();
    let spike = job.piv.clone();
    let mc_name = piv_name(&job.mc_piv);
    let spike_name = piv_name(&spike);
    let piv_cfgs = [
        ("PIV 64,32,32 B-spline", base.clone()),
        (
            "PIV 64,32 B-spline",
            Settings {
                windows: vec![64, 32],
                ..base.clone()
            },
        ),
        (
            "PIV 64,32,32 bilinear",
            Settings {
                interp: Interp::Bilinear,
                ..base.clone()
            },
        ),
    ];
    // Frame camera.
    let (fa, fb) = (to(&sim.frames[0]), to(&sim.frames[1]));
    for (name, s) in &piv_cfgs {
        let (ms, e, _) = err(&fa, &fb, s)?;
        rows.push(SpeedRow {
            name: format!("frame camera, {name}"),
            ms,
            rmse: e,
        });
        progress();
    }
    // Core: TFP and adaptive at several window limits.
    let recon = |m: Method, n: u16| -> Result<(f64, Array2<f32>, Array2<f32>), JobError> {
        let t = Instant::now();
        let a = frame_from_planes(&planes, ka, m, n, &job.core)?;
        let bb = frame_from_planes(&planes, kb, m, n, &job.core)?;
        Ok((t.elapsed().as_secs_f64() * 1e3, to(&a.data), to(&bb.data)))
    };
    for (m, n) in [
        (Method::Tfp, 8),
        (Method::Tfp, 16),
        (Method::Adaptive, 32),
        (Method::Adaptive, 64),
        (Method::Adaptive, 128),
    ] {
        let (rms, a, bb) = recon(m, n)?;
        let (ms, e, _) = err(&a, &bb, &spike)?;
        rows.push(SpeedRow {
            name: format!("core {m:?} n={n} (fixed point), {spike_name}"),
            ms: rms + ms,
            rmse: e,
        });
        progress();
    }
    // Beyond the paper: adaptive windows capped per band by the TFP field.
    for cap in [6.0, 8.0, 16.0] {
        let t = Instant::now();
        let (_, ta, tb) = recon(Method::Tfp, 8)?;
        let tfp_field = piv(&ta, &tb, None, &spike)?;
        let caps = crate::dwell::band_caps(&tfp_field.vectors(), hu, dt, cap, &job.core);
        let a = crate::dwell::adaptive_banded(&planes, ka, &job.core, &caps)?;
        let bb = crate::dwell::adaptive_banded(&planes, kb, &job.core, &caps)?;
        let rec_ms = t.elapsed().as_secs_f64() * 1e3;
        let (ms, e, _) = err(&to(&a), &to(&bb), &spike)?;
        rows.push(SpeedRow {
            name: format!("core Adaptive, dwell cap {cap} px, {spike_name}"),
            ms: rec_ms + ms,
            rmse: e,
        });
        progress();
    }
    // The sidecar as `spiv run` drives it: firmware (core frames, dwell caps
    // from the TFP pair sent through the link), tile coding, the host's
    // decoder and reassembly; lossless and lossy. Time = firmware + wire +
    // receiver for both pairs (TFP and adaptive) + PIV on the adaptive pair.
    for (enc, label) in [
        (spiv_core::wire::Encoding::Rice, "lossless Rice"),
        (spiv_core::wire::Encoding::Context, "lossless Context"),
        (spiv_core::wire::Encoding::Sparse, "lossy Sparse"),
        (
            spiv_core::wire::Encoding::SparseContext,
            "lossy SparseContext",
        ),
    ] {
        let t = Instant::now();
        let mut base = Config::new(ka as u32, (kb - ka) as u32);
        base.params = job.core;
        base.schedule.pairs = Some(1);
        base.encoding = enc;
        let (caps, _) = dwell_caps(&planes.data, w, h, &base, 8, 8.0, &spike)?;
        let ad_t = transfer(&planes.data, w, h, base, caps)?;
        let [a, bb] = ad_t.pairs.first().ok_or(JobError::NoPair("adaptive"))?;
        let (a, bb) = (upright_f32(a), upright_f32(bb));
        let rec_ms = t.elapsed().as_secs_f64() * 1e3;
        let (ms, e, _) = err(&a, &bb, &spike)?;
        rows.push(SpeedRow {
            name: format!(
                "sidecar + wire {label}, {:.0} KB/pair, dwell cap 8 px, {spike_name}",
                ad_t.bytes as f64 / 1e3
            ),
            ms: rec_ms + ms,
            rmse: e,
        });
        progress();
    }
    // Motion-compensated (issue 14): the TFP pair's PIV predicts each row's
    // velocity, the core refines it and counts along the path. Time = the
    // TFP pair and its PIV + both compensated frames + PIV.
    {
        let t = Instant::now();
        let (_, ta, tb) = recon(Method::Tfp, 8)?;
        let tfp_field = piv(&ta, &tb, None, &spike)?;
        let vel = crate::predict::row_velocities(&tfp_field.vectors(), h, planes.flip, dt);
        let refine = Some(spiv_core::motion::Refine::default());
        let a = crate::predict::compensated_frame(&planes, ka, &job.core, &vel, refine)?.0;
        let bb = crate::predict::compensated_frame(&planes, kb, &job.core, &vel, refine)?.0;
        let rec_ms = t.elapsed().as_secs_f64() * 1e3;
        let (ms, e, narrow) = err(&to(&a), &to(&bb), &job.mc_piv)?;
        rows.push(SpeedRow {
            name: format!("core motion-compensated n=128, TFP prediction refined, {mc_name}"),
            ms: rec_ms + ms,
            rmse: e,
        });
        progress();
        // The wide baseline on top (`crate::baseline`): two more
        // compensated frames 4·dt apart around the pair, their PIV from the
        // pair's field, each vector chosen. Time = the pair's row + that.
        let s = crate::baseline::SEPARATION;
        let pair_dt = u32::try_from(kb - ka).unwrap_or(u32::MAX);
        let held = sim.meta.capture.planes;
        if let Some((k0, k1)) = crate::baseline::ticks_within(ka, pair_dt, s, job.core.n_max, held)
        {
            let t = Instant::now();
            let wa = crate::predict::compensated_frame(&planes, k0, &job.core, &vel, refine)?.0;
            let wb = crate::predict::compensated_frame(&planes, k1, &job.core, &vel, refine)?.0;
            let wide = crate::piv::piv_predicted(
                &to(&wa),
                &to(&wb),
                None,
                &job.mc_piv,
                Some(&crate::baseline::scaled(&narrow, s)),
            )?;
            let vectors = crate::baseline::combine(&narrow, &wide, s);
            let wide_ms = t.elapsed().as_secs_f64() * 1e3;
            let prof = row_profile(&vectors, &truth, f64::from(h));
            rows.push(SpeedRow {
                name: format!(
                    "the same + wide baseline {s}·dt (two more compensated frames, PIV predicted)"
                ),
                ms: rec_ms + ms + wide_ms,
                rmse: region_error(&prof, |_| true).rmse,
            });
            progress();
        }
    }
    // The f64 reference of the adaptive frame.
    let t = Instant::now();
    let vol = SpikeVolume::from_packed(&planes.data, wu, hu, 0);
    let ra = adaptive_frame(&vol, ka as u32, &job.core, f64::from(job.core.full_scale));
    let rb = adaptive_frame(&vol, kb as u32, &job.core, f64::from(job.core.full_scale));
    let ref_ms = t.elapsed().as_secs_f64() * 1e3;
    let up = |v: &[f64]| -> Array2<f32> {
        // The reference works in stored (bottom-up) rows.
        Array2::from_shape_fn((hu, wu), |(i, j)| v[(hu - 1 - i) * wu + j] as f32)
    };
    let (a, bb) = (up(&ra.gray), up(&rb.gray));
    let (ms, e, _) = err(&a, &bb, &spike)?;
    rows.push(SpeedRow {
        name: format!("f64 reference Adaptive n=128, {spike_name}"),
        ms: ref_ms + ms,
        rmse: e,
    });
    Ok(rows)
}

/// A PIV configuration as the table names it: passes, resampling and (when
/// not the parabola) the sub-pixel peak.
fn piv_name(s: &Settings) -> String {
    use crate::piv::{Interp, Subpixel};
    let w: Vec<String> = s.windows.iter().map(|w| w.to_string()).collect();
    let interp = match s.interp {
        Interp::Bilinear => "bilinear",
        Interp::Bicubic => "bicubic",
        Interp::Bspline => "B-spline",
        Interp::Bspline5 => "quintic B-spline",
    };
    let peak = match s.subpixel {
        Subpixel::Parabolic => "",
        Subpixel::Gaussian => ", Gaussian peak",
        Subpixel::Gaussian2d => ", 2-D Gaussian peak",
    };
    format!("PIV {} {interp}{peak}", w.join(","))
}
