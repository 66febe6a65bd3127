//! `spiv bench live`: every family of `spiv bench flows` through the loop
//! between the core and the estimator as a live downlink runs it — each
//! pair's ask arriving one or three pairs late, or one late with a share
//! of asks lost — beside `spiv flow` on the same recording (its asks
//! arrive at once). Both run the same loop ([`crate::flow::run_flow`]
//! with [`Delivery`]); only the delivery of the asks differs.
//!
//! Per family, seed and mode it reports the EPE of the measured vectors
//! (px per pair) in the glare and other rows over the pairs after the
//! third, the share of vectors flagged there, the pair's frames and
//! events on the wire ([`crate::estimator::uplink`]) against the raw spikes
//! between pairs, and the lateness of the asks in pairs.

use spiv_firmware_sim::scene::Scene;
use spiv_firmware_sim::simulation::{simulate_planes, Request};

use super::flows::{Family, Score};
use crate::estimator::control::Delivery;
use crate::flow::{run_flow, FlowOptions, Recording};
use crate::Error;

/// Pairs whose errors count: those after the third.
pub const SKIPPED: usize = 3;

/// One mode on one recording.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LiveRow {
    /// Family.
    pub family: String,
    /// Seed of particles, noise, flow and losses.
    pub seed: u64,
    /// "spiv flow", "1 pair late", "3 pairs late", "1 late, 10 % lost" or
    /// "1 late, 5 % lost, 5 % corrupted".
    pub mode: String,
    /// Pairs by which each ask arrived late.
    pub late: usize,
    /// Share of asks lost.
    pub loss: f64,
    /// Mean EPE of the measured vectors in the glare rows, pairs after
    /// the third, px per pair.
    pub glare: Option<f64>,
    /// The same in the other rows.
    pub other: Option<f64>,
    /// Share of vectors flagged invalid, pairs after the third.
    pub flagged: f64,
    /// Mean bytes of a pair's frames and events on the wire.
    pub bytes_per_pair: f64,
    /// Bytes of the raw spikes between two pairs (1 bit per pixel and
    /// tick).
    pub raw_per_pair: f64,
    /// Pairs measured (after the third).
    pub pairs: usize,
    /// Mean EPE of each scored pair's measured vectors, px per pair
    /// (`None`: none measured), in order: the drift over a long run.
    pub per_pair: Vec<Option<f64>>,
}

impl LiveRow {
    /// The mean of the scored pairs' EPE over `range` (indices among the
    /// scored pairs), `None` when none of them measured anything.
    pub fn epe_over(&self, range: std::ops::Range<usize>) -> Option<f64> {
        let v: Vec<f64> = self
            .per_pair
            .get(range)
            .unwrap_or_default()
            .iter()
            .flatten()
            .copied()
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    }
}

/// The modes: `spiv flow`'s immediate asks, asks one and three pairs
/// late, one late with a tenth of the ask messages lost, and one late with
/// 5 % lost and 5 % corrupted.
pub fn modes(seed: u64) -> Vec<(&'static str, Delivery)> {
    let d = |late, loss, corrupt| Delivery {
        late,
        loss,
        corrupt,
        seed,
    };
    vec![
        ("spiv flow", Delivery::default()),
        ("1 pair late", d(1, 0.0, 0.0)),
        ("3 pairs late", d(3, 0.0, 0.0)),
        ("1 late, 10 % lost", d(1, 0.1, 0.0)),
        ("1 late, 5 % lost, 5 % corrupted", d(1, 0.05, 0.05)),
    ]
}

/// The rows of one family and seed, `pairs` pairs after the third.
pub fn live_rows(fam: &Family, seed: u64, pairs: usize) -> Result<Vec<LiveRow>, Error> {
    let p = fam.params(seed);
    let dt = p.pair_dt.max(1);
    let every = 4 * dt;
    let wanted = SKIPPED + pairs;
    // The longest rung's reach on both sides, and the pairs between.
    let longest = crate::estimator::ladder::SEPARATIONS
        .iter()
        .copied()
        .max()
        .unwrap_or(0);
    let reach = 2 * (longest + u32::from(spiv_core::light::MAX_TOLERANCE));
    let mut req = Request::new(p.clone(), seed);
    req.ticks = Some(reach + every * (wanted as u32 + 2));
    let (data, sim) = simulate_planes(&req)?;
    let pair = sim.meta.capture.pair;
    let dt = pair[1] - pair[0];
    let rec = Recording::simulated(p.width, p.height, data, dt);
    let raw = f64::from(every) * f64::from(p.width) * f64::from(p.height) / 8.0;
    let mut rows = Vec::new();
    for (name, delivery) in modes(seed) {
        let mut o = FlowOptions::new(&rec, dt);
        let n = o.pair_ticks().len();
        o.pairs = Some(0..wanted.min(n));
        o.delivery = delivery;
        o.wire_bytes = true;
        let out = run_flow(&rec, &o, |_, _| {})?;
        let mut s = Score::default();
        let (mut bytes, mut counted) = (0u64, 0usize);
        let mut per_pair = Vec::new();
        for pr in out.pairs.iter().skip(SKIPPED) {
            let at = (Scene::pair_mid(pr.ticks[0], pr.ticks[1]), f64::from(dt));
            s.add(&sim.scene, at, &pr.vectors, Some(&pr.sigma));
            let mut one = Score::default();
            one.add(&sim.scene, at, &pr.vectors, None);
            per_pair.push(one.measured_epe());
            if let Some(b) = pr.bytes {
                bytes += b.total();
                counted += 1;
            }
        }
        let r = s.row(&fam.name, seed, name, None, 0.0);
        rows.push(LiveRow {
            family: fam.name.clone(),
            seed,
            mode: name.into(),
            late: delivery.late,
            loss: delivery.loss,
            glare: r.glare,
            other: r.other,
            flagged: r.flagged,
            bytes_per_pair: bytes as f64 / counted.max(1) as f64,
            raw_per_pair: raw,
            pairs: out.pairs.len().saturating_sub(SKIPPED),
            per_pair,
        });
    }
    Ok(rows)
}
