//! Speed against error (`spiv bench speed`): every way spiv makes and
//! measures a frame pair, timed and held to the truth on one scene.

use std::path::Path;
use std::time::Instant;

use ndarray::Array2;
use spiv_firmware_sim::firmware::Config;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::simulate_planes;
use spiv_formats::grid::Grid;
use spiv_formats::vectors::Vector;

use crate::link::{dwell_caps, transfer};
use crate::metrics::{region_error, row_profile};
use crate::pipeline::Job;
use crate::piv::{piv, to_f32, Interp, Settings};
use crate::receive::upright_f32;
use crate::reconstruct::{frame_from_planes, Method, Planes};
use crate::reference::{adaptive_frame, SpikeVolume};
use crate::report::plot::{self, plot_error};
use crate::Error;
use plotters::prelude::*;

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
pub fn speed_against_error(mut progress: impl FnMut()) -> Result<Vec<SpeedRow>, Error> {
    let b = SpeedBench::new()?;
    let mut rows: Vec<SpeedRow> = Vec::new();
    let mut push = |row: SpeedRow| {
        rows.push(row);
        progress();
    };
    b.frame_camera(&mut push)?;
    b.core_frames(&mut push)?;
    b.dwell_capped(&mut push)?;
    b.sidecar(&mut push)?;
    b.compensated(&mut push)?;
    rows.push(b.reference()?);
    Ok(rows)
}

/// The scene of [`speed_against_error`], simulated once, with its truth.
struct SpeedBench {
    job: Job,
    planes: Planes,
    sim: spiv_firmware_sim::simulation::Simulated,
    /// The pair's ticks.
    ka: u64,
    kb: u64,
    /// Truth at the paper's grid (32-px windows every 16 px), px per pair.
    truth: Vec<Vector>,
}

impl SpeedBench {
    fn new() -> Result<SpeedBench, Error> {
        let job = Job::new(SceneParams::new(SceneKind::PaperLinear), 1);
        let (data, sim) = simulate_planes(&job.request)?;
        let (w, h) = (job.request.scene.width, job.request.scene.height);
        let planes = Planes::simulated(w, h, data);
        let [ka, kb] = sim.meta.capture.pair.map(u64::from);
        let centres = Grid::new(usize::from(w), usize::from(h), 32, 16).map(|g| g.centres());
        let truth = sim
            .scene
            .truth_vectors(&centres.unwrap_or_default(), (kb - ka) as f64);
        Ok(SpeedBench {
            job,
            planes,
            sim,
            ka,
            kb,
            truth,
        })
    }

    fn size(&self) -> (usize, usize) {
        (
            usize::from(self.planes.width),
            usize::from(self.planes.height),
        )
    }

    fn dt(&self) -> f64 {
        (self.kb - self.ka) as f64
    }

    fn upright(&self, d: &[u16]) -> Array2<f32> {
        let (w, h) = self.size();
        to_f32(d, w, h)
    }

    /// PIV of a pair under `s`: its time (the median of 3 runs; the first
    /// run of the process also pays for starting the thread pool and
    /// touching fresh memory), the row profile's RMSE and the field.
    fn piv(
        &self,
        a: &Array2<f32>,
        b: &Array2<f32>,
        s: &Settings,
    ) -> Result<(f64, f64, crate::piv::Field), Error> {
        let mut times = [0.0f64; 3];
        let mut field = None;
        for t in times.iter_mut() {
            let start = Instant::now();
            field = Some(piv(a, b, None, s)?);
            *t = start.elapsed().as_secs_f64() * 1e3;
        }
        times.sort_by(f64::total_cmp);
        let f = field.ok_or(Error::NoPair("PIV"))?;
        let rmse = self.rmse(&f.vectors());
        Ok((times[1], rmse, f))
    }

    /// RMSE of the row profile of `vectors` against the truth, px per pair.
    fn rmse(&self, vectors: &[Vector]) -> f64 {
        let rows = row_profile(vectors, &self.truth, f64::from(self.planes.height));
        region_error(&rows, |_| true).rmse
    }

    /// Both frames of the pair by the core's `m` with window `n`: the time
    /// and the two frames.
    fn core_pair(&self, m: Method, n: u16) -> Result<(f64, Array2<f32>, Array2<f32>), Error> {
        let t = Instant::now();
        let a = frame_from_planes(&self.planes, self.ka, m, n, &self.job.core)?;
        let b = frame_from_planes(&self.planes, self.kb, m, n, &self.job.core)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        Ok((ms, self.upright(&a.data), self.upright(&b.data)))
    }

    /// The frame camera through three PIV configurations.
    fn frame_camera(&self, push: &mut impl FnMut(SpeedRow)) -> Result<(), Error> {
        let base = self.job.piv.clone();
        let cfgs = [
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
                    ..base
                },
            ),
        ];
        let (fa, fb) = (
            self.upright(&self.sim.frames[0]),
            self.upright(&self.sim.frames[1]),
        );
        for (name, s) in &cfgs {
            let (ms, rmse, _) = self.piv(&fa, &fb, s)?;
            push(SpeedRow {
                name: format!("frame camera, {name}"),
                ms,
                rmse,
            });
        }
        Ok(())
    }

    /// The core's TFP and adaptive frames at several window limits.
    fn core_frames(&self, push: &mut impl FnMut(SpeedRow)) -> Result<(), Error> {
        let spike = &self.job.piv;
        for (m, n) in [
            (Method::Tfp, 8),
            (Method::Tfp, 16),
            (Method::Adaptive, 32),
            (Method::Adaptive, 64),
            (Method::Adaptive, 128),
        ] {
            let (rms, a, b) = self.core_pair(m, n)?;
            let (ms, rmse, _) = self.piv(&a, &b, spike)?;
            push(SpeedRow {
                name: format!("core {m:?} n={n} (fixed point), {}", piv_name(spike)),
                ms: rms + ms,
                rmse,
            });
        }
        Ok(())
    }

    /// Adaptive windows capped per band by the TFP pair's field.
    fn dwell_capped(&self, push: &mut impl FnMut(SpeedRow)) -> Result<(), Error> {
        let (spike, core) = (&self.job.piv, &self.job.core);
        let (_, h) = self.size();
        for cap in [6.0, 8.0, 16.0] {
            let t = Instant::now();
            let (_, ta, tb) = self.core_pair(Method::Tfp, 8)?;
            let tfp_field = piv(&ta, &tb, None, spike)?;
            let caps = crate::dwell::band_caps(&tfp_field.vectors(), h, self.dt(), cap, core);
            let (a, _) = crate::dwell::adaptive_banded(&self.planes, self.ka, core, &caps)?;
            let (b, _) = crate::dwell::adaptive_banded(&self.planes, self.kb, core, &caps)?;
            let rec_ms = t.elapsed().as_secs_f64() * 1e3;
            let (ms, rmse, _) = self.piv(&self.upright(&a), &self.upright(&b), spike)?;
            push(SpeedRow {
                name: format!("core Adaptive, dwell cap {cap} px, {}", piv_name(spike)),
                ms: rec_ms + ms,
                rmse,
            });
        }
        Ok(())
    }

    /// The sidecar as `spiv run` drives it: firmware (core frames, dwell
    /// caps from the TFP pair sent through the link), tile coding, the
    /// host's decoder and reassembly; lossless and lossy. Time = firmware +
    /// wire + receiver for both pairs (TFP and adaptive) + PIV on the
    /// adaptive pair.
    fn sidecar(&self, push: &mut impl FnMut(SpeedRow)) -> Result<(), Error> {
        use spiv_core::wire::Encoding;
        let spike = &self.job.piv;
        let (w, h) = (self.planes.width, self.planes.height);
        for (enc, label) in [
            (Encoding::Rice, "lossless Rice"),
            (Encoding::Context, "lossless Context"),
            (Encoding::Sparse, "lossy Sparse"),
            (Encoding::SparseContext, "lossy SparseContext"),
        ] {
            let t = Instant::now();
            let mut base = Config::new(self.ka as u32, (self.kb - self.ka) as u32);
            base.params = self.job.core;
            base.schedule.pairs = Some(1);
            base.encoding = enc;
            let (caps, _) = dwell_caps(&self.planes.data, w, h, &base, 8, 8.0, spike)?;
            let ad_t = transfer(&self.planes.data, w, h, base, caps)?;
            let [a, b] = ad_t.pairs.first().ok_or(Error::NoPair("adaptive"))?;
            let (a, b) = (upright_f32(a), upright_f32(b));
            let rec_ms = t.elapsed().as_secs_f64() * 1e3;
            let (ms, rmse, _) = self.piv(&a, &b, spike)?;
            push(SpeedRow {
                name: format!(
                    "sidecar + wire {label}, {:.0} KB/pair, dwell cap 8 px, {}",
                    ad_t.bytes as f64 / 1e3,
                    piv_name(spike)
                ),
                ms: rec_ms + ms,
                rmse,
            });
        }
        Ok(())
    }

    /// Motion-compensated frames: the TFP pair's PIV predicts each row's
    /// velocity (or each tile column's, `crate::predict::motion_grid`), the
    /// core refines it and counts along the path (time = the
    /// TFP pair and its PIV + both compensated frames + PIV); then the
    /// wide baseline on top (`crate::baseline`: two more compensated
    /// frames 4·dt apart around the pair, their PIV from the pair's field,
    /// each vector chosen; time = the pair's row + that).
    fn compensated(&self, push: &mut impl FnMut(SpeedRow)) -> Result<(), Error> {
        let (job, planes) = (&self.job, &self.planes);
        let t = Instant::now();
        let (_, ta, tb) = self.core_pair(Method::Tfp, 8)?;
        let tfp_field = piv(&ta, &tb, None, &job.piv)?;
        let vel = crate::predict::motion_grid(
            &tfp_field.vectors(),
            (planes.width, planes.height),
            planes.flip,
            self.dt(),
            crate::predict::MotionModel::Auto,
        );
        let refine = Some(spiv_core::motion::Refine::default());
        let frame = |k: u64| -> Result<Array2<f32>, Error> {
            let f = crate::predict::compensated_frame(planes, k, &job.core, &vel, refine)?.0;
            Ok(self.upright(&f))
        };
        let (a, b) = (frame(self.ka)?, frame(self.kb)?);
        let rec_ms = t.elapsed().as_secs_f64() * 1e3;
        let (ms, rmse, narrow) = self.piv(&a, &b, &job.mc_piv)?;
        push(SpeedRow {
            name: format!(
                "core motion-compensated n=128, TFP prediction refined, {}",
                piv_name(&job.mc_piv)
            ),
            ms: rec_ms + ms,
            rmse,
        });
        let s = crate::baseline::SEPARATION;
        let pair_dt = u32::try_from(self.kb - self.ka).unwrap_or(u32::MAX);
        let held = self.sim.meta.capture.planes;
        let Some((k0, k1)) =
            crate::baseline::ticks_within(self.ka, pair_dt, s, job.core.n_max, held)
        else {
            return Ok(());
        };
        let t = Instant::now();
        let predicted = crate::baseline::scaled(&narrow, s);
        let wide = crate::piv::piv_predicted(
            &frame(k0)?,
            &frame(k1)?,
            None,
            &job.mc_piv,
            Some(&predicted),
        )?;
        let vectors = crate::baseline::combine(&narrow, &wide, s);
        let wide_ms = t.elapsed().as_secs_f64() * 1e3;
        push(SpeedRow {
            name: format!(
                "the same + wide baseline {s}·dt (two more compensated frames, PIV predicted)"
            ),
            ms: rec_ms + ms + wide_ms,
            rmse: self.rmse(&vectors),
        });
        Ok(())
    }

    /// The f64 reference of the adaptive frame.
    fn reference(&self) -> Result<SpeedRow, Error> {
        let (job, (wu, hu)) = (&self.job, self.size());
        let t = Instant::now();
        let vol = SpikeVolume::from_packed(&self.planes.data, wu, hu, 0);
        let fs = f64::from(job.core.full_scale);
        let ra = adaptive_frame(&vol, self.ka as u32, &job.core, fs);
        let rb = adaptive_frame(&vol, self.kb as u32, &job.core, fs);
        let ref_ms = t.elapsed().as_secs_f64() * 1e3;
        let up = |v: &[f64]| -> Array2<f32> {
            // The reference works in stored (bottom-up) rows.
            Array2::from_shape_fn((hu, wu), |(i, j)| v[(hu - 1 - i) * wu + j] as f32)
        };
        let (ms, rmse, _) = self.piv(&up(&ra.gray), &up(&rb.gray), &job.piv)?;
        Ok(SpeedRow {
            name: format!("f64 reference Adaptive n=128, {}", piv_name(&job.piv)),
            ms: ref_ms + ms,
            rmse,
        })
    }
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

/// The speed-against-error chart of `spiv bench speed` (log time, error).
pub fn pareto(path: &Path, rows: &[SpeedRow]) -> Result<(), Error> {
    pareto_inner(path, rows).map_err(|m| plot_error(path, m))
}

fn pareto_inner(path: &Path, rows: &[SpeedRow]) -> Result<(), String> {
    plot::ensure_font();
    let root = BitMapBackend::new(path, (760, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let tmax = rows.iter().map(|r| r.ms).fold(1.0, f64::max) * 1.3;
    let emax = rows.iter().map(|r| r.rmse).fold(0.1, f64::max) * 1.2;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "speed against error (paper-linear, 400x250)",
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d((1.0..tmax).log_scale(), 0.0..emax)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("ms per frame pair (log)")
        .y_desc("RMSE of u(y), px per pair")
        .draw()
        .map_err(|e| e.to_string())?;
    for r in rows {
        chart
            .draw_series(std::iter::once(Circle::new(
                (r.ms.max(1.0), r.rmse),
                5,
                RED.filled(),
            )))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(std::iter::once(Text::new(
                r.name.split(',').next().unwrap_or("").to_string(),
                (r.ms.max(1.0) * 1.05, r.rmse),
                ("sans-serif", 11),
            )))
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}
