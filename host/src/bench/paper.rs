//! `spiv bench paper` and `spiv bench blasius`: `spiv run`'s job over
//! seeds, the paper's Tables 1–2 per profile and the Blasius layer's
//! profile deviation, as means with 95 % intervals.

use serde::Serialize;
use spiv_firmware_sim::scene::{SceneKind, SceneParams};

use crate::metrics::{mean_ci, rmae_ratio, MeanCi};
use crate::pipeline::{run as run_job, FrameKind, Job};
use crate::Error;

/// The paper's own numbers for a profile (Li et al. 2025, Table 2): the
/// spike camera's glare-row RMAE, and the frame/spike RMAE ratio where it
/// gives one.
pub const PAPER: [(SceneKind, f64, Option<f64>); 3] = [
    (SceneKind::PaperLinear, 0.084, Some(8.594)),
    (SceneKind::PaperQuadratic, 0.028, None),
    (SceneKind::PaperLog, 0.113, None),
];

/// One kind of frames on one profile over the seeds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PaperRow {
    /// The frames.
    pub source: FrameKind,
    /// Glare rows' RMAE.
    pub glare_rmae: MeanCi,
    /// Glare rows' RMSE, px per pair.
    pub glare_rmse: MeanCi,
    /// Other rows' RMAE.
    pub rest_rmae: MeanCi,
    /// Other rows' RMSE, px per pair.
    pub rest_rmse: MeanCi,
}

/// The frame camera's RMAE over another kind's, per seed, averaged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PaperRatio {
    /// The other kind of frames.
    pub ratio: FrameKind,
    /// In the glare rows.
    pub glare: MeanCi,
    /// In the other rows.
    pub rest: MeanCi,
}

/// One profile's table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PaperTable {
    /// The profile.
    #[serde(serialize_with = "scene_name")]
    pub scene: SceneKind,
    /// Seeds run.
    pub seeds: u64,
    /// The paper's spike-camera glare RMAE.
    pub paper_rmae: f64,
    /// The paper's frame/spike ratio, where it gives one.
    pub paper_ratio: Option<f64>,
    /// Every kind of frames.
    pub rows: Vec<PaperRow>,
    /// The frame camera against each other kind.
    pub ratios: Vec<PaperRatio>,
}

fn scene_name<S: serde::Serializer>(k: &SceneKind, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(k.name())
}

/// Runs `spiv run`'s job on each of the paper's profiles for seeds
/// `1..=seeds`, with the adaptive frames' `dwell_cap` (px; `None`: the
/// paper's one n_max). `progress` is called after each run.
pub fn paper_bench(
    seeds: u64,
    dwell_cap: Option<f64>,
    mut progress: impl FnMut(),
) -> Result<Vec<PaperTable>, Error> {
    let mut tables = Vec::new();
    for (kind, paper_rmae, paper_ratio) in PAPER {
        // [kind][glare rmae, glare rmse, rest rmae, rest rmse]
        let mut acc = vec![[Vec::new(), Vec::new(), Vec::new(), Vec::new()]; FrameKind::ALL.len()];
        let mut ratios = vec![[Vec::new(), Vec::new()]; FrameKind::ALL.len() - 1];
        for seed in 1..=seeds {
            let mut job = Job::new(SceneParams::new(kind), seed);
            job.dwell_cap = dwell_cap;
            let o = run_job(&job, |_| {})?;
            for (k, x) in o.measured.iter().enumerate() {
                acc[k][0].push(x.glare.rmae);
                acc[k][1].push(x.glare.rmse);
                acc[k][2].push(x.rest.rmae);
                acc[k][3].push(x.rest.rmse);
            }
            let f = &o.measured[0];
            for (k, x) in o.measured[1..].iter().enumerate() {
                ratios[k][0].push(rmae_ratio(f.glare.rmae, x.glare.rmae));
                ratios[k][1].push(rmae_ratio(f.rest.rmae, x.rest.rmae));
            }
            progress();
        }
        tables.push(PaperTable {
            scene: kind,
            seeds,
            paper_rmae,
            paper_ratio,
            rows: FrameKind::ALL
                .iter()
                .zip(&acc)
                .map(|(&source, a)| PaperRow {
                    source,
                    glare_rmae: mean_ci(&a[0]),
                    glare_rmse: mean_ci(&a[1]),
                    rest_rmae: mean_ci(&a[2]),
                    rest_rmse: mean_ci(&a[3]),
                })
                .collect(),
            ratios: FrameKind::ALL[1..]
                .iter()
                .zip(&ratios)
                .map(|(&ratio, r)| PaperRatio {
                    ratio,
                    glare: mean_ci(&r[0]),
                    rest: mean_ci(&r[1]),
                })
                .collect(),
        });
    }
    Ok(tables)
}

/// The Blasius layer over seeds: per kind of frames, the RMS deviation of
/// the measured row profile from the solution in % of U, and the rows
/// without a vector.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Blasius {
    /// U, the free stream, px per pair.
    pub u_pair: f64,
    /// Per kind of frames: the deviation (NaN for a seed with no measured
    /// row) and the rows without a vector over all seeds.
    pub rows: Vec<(FrameKind, MeanCi, usize)>,
}

/// Runs `spiv run`'s job on the Blasius scene for seeds `1..=seeds`, with
/// the default dwell cap. `progress` is called after each run.
pub fn blasius_bench(seeds: u64, mut progress: impl FnMut()) -> Result<Blasius, Error> {
    let mut dev = vec![Vec::new(); FrameKind::ALL.len()];
    let mut lost = vec![0usize; FrameKind::ALL.len()];
    let mut u_pair = 0.0;
    for seed in 1..=seeds {
        let mut job = Job::new(SceneParams::new(SceneKind::Blasius), seed);
        job.dwell_cap = Some(crate::dwell::DWELL_CAP);
        let o = run_job(&job, |_| {})?;
        let dt = f64::from(o.sim.meta.capture.pair[1] - o.sim.meta.capture.pair[0]);
        u_pair = job.request.scene.top_speed * dt;
        for (k, x) in o.measured.iter().enumerate() {
            let used: Vec<f64> = x
                .rows
                .iter()
                .filter_map(|r| r.measured.map(|m| (m - r.truth).powi(2)))
                .collect();
            lost[k] += x.rows.iter().filter(|r| r.measured.is_none()).count();
            // No measured row: undefined (NaN), not a perfect 0.
            let rms = if used.is_empty() {
                f64::NAN
            } else {
                (used.iter().sum::<f64>() / used.len() as f64).sqrt()
            };
            dev[k].push(100.0 * rms / u_pair);
        }
        progress();
    }
    Ok(Blasius {
        u_pair,
        rows: FrameKind::ALL
            .iter()
            .zip(dev.iter().zip(lost))
            .map(|(&k, (d, l))| (k, mean_ci(d), l))
            .collect(),
    })
}
