//! `summary.json` of `spiv run`: the scene, every setting, the paper's
//! metrics per kind of frames, stage times and the wire.

use serde_json::json;

use crate::metrics::rmae_ratio;
use crate::pipeline::{Job, Outcome};

/// The summary of one run.
pub fn run_summary(o: &Outcome, job: &Job) -> serde_json::Value {
    let (w, h) = (o.sim.meta.capture.width, o.sim.meta.capture.height);
    let dt = f64::from(o.sim.meta.capture.pair[1] - o.sim.meta.capture.pair[0]);
    json!({
        "scene": o.sim.meta.scene.name,
        "seed": o.sim.meta.seed,
        "width": w,
        "height": h,
        "pair": o.sim.meta.capture.pair,
        "dt_ticks": dt,
        "glare_rows_below_px": o.glare_limit,
        "core": { "n0": job.core.n0, "n_max": job.core.n_max, "n_fs": job.core.n_fs },
        "tfp_window": job.tfp_window,
        "dwell_cap_px": job.dwell_cap,
        "piv": job.piv,
        "results": o.measured.iter().map(|x| json!({
            "source": x.source,
            "glare": x.glare,
            "rest": x.rest,
            "rows": x.rows,
            "piv_ms": x.piv_ms,
        })).collect::<Vec<_>>(),
        "frame_over_adaptive_rmae": {
            "glare": rmae_ratio(o.measured[0].glare.rmae, o.measured[2].glare.rmae),
            "rest": rmae_ratio(o.measured[0].rest.rmae, o.measured[2].rest.rmae),
        },
        "frame_over_mc_rmae": {
            "glare": rmae_ratio(o.measured[0].glare.rmae, o.measured[3].glare.rmae),
            "rest": rmae_ratio(o.measured[0].rest.rmae, o.measured[3].rest.rmae),
        },
        "frame_over_mc_wide_rmae": {
            "glare": rmae_ratio(o.measured[0].glare.rmae, o.measured[4].glare.rmae),
            "rest": rmae_ratio(o.measured[0].rest.rmae, o.measured[4].rest.rmae),
        },
        "stage_ms": { "simulate": o.stage_ms[0], "sidecar": o.stage_ms[1], "piv": o.stage_ms[2] },
        "wire": {
            "encoding": format!("{:?}", job.encoding),
            "adaptive_pair_bytes": o.link.adaptive_bytes,
            "mc_pair_bytes": o.link.mc_bytes,
            "mc_wide_pair_bytes": o.link.wide_bytes,
            "tfp_pair_bytes": o.link.tfp_bytes,
            "raw_spike_bytes_per_pair_period": o.link.raw_bytes_per_period,
            "reduction_adaptive": o.link.raw_bytes_per_period as f64 / o.link.adaptive_bytes.max(1) as f64,
            "lost_frames": o.link.lost_frames,
            "bit_exact": o.link.bit_exact,
        },
    })
}
