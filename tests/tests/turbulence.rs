//! `spiv flow` with its defaults on turbulence: eddies down to 8 px, below
//! every PIV window, at up to 25 px per pair (the third-party spike-flow
//! recordings' form: 256×256 px, 62 planes, pairs 21 ticks apart). Window
//! PIV cannot start the time ladder there; the dense ensemble
//! (`spiv_host::estimator::ensemble`) measures the pair instead.
//!
//! Before it, the same recordings gave 60 % of the vectors flagged and an
//! error of 4.0 px per pair on the rest (`spiv bench flows --seeds 1-5
//! --families turbulence`), against a mean displacement of 8.7 px. With
//! the ensemble's flows averaged per frame pair, this recording measured
//! 92 % of its vectors at 1.28 px and a dense EPE of 1.68 px; with one flow
//! fitted to every pair of frames, 100 % at 0.76 px and 0.86 px (0.855);
//! with the second pass on 12-tick frames, 100 % at 0.75 px and 0.81 px;
//! with the joint fit of `spiv flow --dense`, a dense EPE of 0.776 px.

mod common;

use common::flow_of;
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::simulation::Simulated;
use spiv_formats::State;
use spiv_host::bench::flows::{families, Family};
use spiv_host::estimator::ensemble;
use spiv_host::flow::PairResult;

/// The spectral turbulence's family of `spiv bench flows`.
fn spectral() -> Family {
    families()
        .into_iter()
        .find(|f| f.scene == SceneKind::SpectralTurbulence)
        .expect("the family")
}

#[test]
fn turbulence_is_measured_densely_with_honest_uncertainty() {
    let seed = 2;
    let mut p = SceneParams::new(SceneKind::Turbulence);
    p.flow_seed = seed;
    let (sim, dt, out) = flow_of(&p, seed, 62, true, true);
    assert!(!out.pairs.is_empty());
    let dtf = f64::from(dt);
    let (mut err, mut measured, mut all, mut within, mut comps) = (0.0, 0, 0, 0, 0);
    for pr in &out.pairs {
        assert!(
            pr.rungs
                .last()
                .is_some_and(|r| r.separation == ensemble::FRAME as u32),
            "the ensemble measured the pair: {:?}",
            pr.rungs
        );
        let pts: Vec<(f64, f64)> = pr.vectors.iter().map(|v| (v.x, v.y)).collect();
        for ((v, t), &(su, sv)) in pr
            .vectors
            .iter()
            .zip(sim.scene.truth(&pts, dtf))
            .zip(&pr.sigma)
        {
            all += 1;
            if v.state == State::Invalid {
                continue;
            }
            measured += 1;
            let (eu, ev) = (v.u - t.2, v.v - t.3);
            err += eu.hypot(ev);
            within += usize::from(eu.abs() <= su) + usize::from(ev.abs() <= sv);
            comps += 2;
        }
    }
    let share = measured as f64 / all as f64;
    let epe = err / measured.max(1) as f64;
    let coverage = within as f64 / comps.max(1) as f64;
    let dense = out
        .mean_dense
        .as_ref()
        .expect("--dense")
        .epe(&sim.scene.truth_dense(dtf), None)
        .expect("same size");
    eprintln!(
        "measured {share:.3}, EPE {epe:.3} px, coverage {coverage:.3}, dense EPE {dense:.3} px"
    );
    assert!(share >= 0.95, "measured {share}");
    assert!(epe <= 1.0, "EPE {epe}");
    assert!((0.5..=0.85).contains(&coverage), "coverage {coverage}");
    // The ensemble's first pass alone gives 0.855, both passes 0.81, the
    // joint fit after them 0.776.
    assert!(dense <= 0.80, "dense EPE {dense}");
}

/// `spiv flow --dense` on the spectral family's hardest kind of member
/// (seed 1: eddies down to 4.3 px, 4.4 px rms per pair, dim particles in a
/// light sheet): its pairs measure no usable field, and the dense stage
/// from rest on their dim 4-tick rung frames, scaled up to the pair, ran
/// off to 115 px where the truth moves at most a tenth of that. Whatever
/// the dense field holds, it stays within twice the truth's largest
/// displacement, plus a pixel; a pair that measured nothing usable on
/// frames shorter than the pair adds nothing to it.
#[test]
fn the_dense_field_never_runs_away() {
    let seed = 1;
    let fam = spectral();
    let (sim, dt, out) = flow_of(&fam.params(seed), seed, fam.ticks, true, true);
    let pair = sim.meta.capture.pair;
    let mid = Scene::pair_mid(u64::from(pair[0]), u64::from(pair[1]));
    let truth = sim.scene.truth_dense_at(mid, f64::from(dt));
    let top = |u: &[f32], v: &[f32]| {
        u.iter()
            .zip(v)
            .map(|(a, b)| a.hypot(*b))
            .fold(0f32, |m, x| {
                if x.is_finite() {
                    m.max(x)
                } else {
                    f32::INFINITY
                }
            })
    };
    let bound = 2.0 * top(&truth.u, &truth.v) + 1.0;
    match &out.mean_dense {
        Some(d) => {
            let m = top(&d.u, &d.v);
            assert!(
                m <= bound,
                "dense field up to {m} px, truth bound {bound} px"
            );
        }
        None => assert!(
            out.pairs
                .iter()
                .all(|pr| !spiv_host::piv::usable_counts(pr.counts())),
            "a pair measured a usable field but the dense stage wrote nothing"
        ),
    }
}

/// Pair `pr`'s vectors against the truth: all of them, the valid ones,
/// the valid ones off by more than 3σ and 0.3 px, and the valid ones'
/// summed error (px per pair).
#[derive(Default)]
struct ValidScore {
    all: usize,
    valid: usize,
    wrong: usize,
    err: f64,
}

impl ValidScore {
    fn add(&mut self, sim: &Simulated, dt: u32, pr: &PairResult) {
        let mid = Scene::pair_mid(pr.ticks[0], pr.ticks[1]);
        let pts: Vec<(f64, f64)> = pr.vectors.iter().map(|v| (v.x, v.y)).collect();
        for ((v, t), &(su, sv)) in pr
            .vectors
            .iter()
            .zip(sim.scene.truth_at(&pts, mid, f64::from(dt)))
            .zip(&pr.sigma)
        {
            self.all += 1;
            if v.state != State::Valid {
                continue;
            }
            self.valid += 1;
            let (eu, ev) = (v.u - t.2, v.v - t.3);
            self.err += eu.hypot(ev);
            self.wrong +=
                usize::from(eu.hypot(ev) > 0.3 && (eu.abs() > 3.0 * su || ev.abs() > 3.0 * sv));
        }
    }
}

/// `spiv flow` on the spectral family's dimmest slow members (seeds 107
/// and 109: 0.11 thresholds/tick, 0.5-1.1 px per pair): their pixels fire
/// every 9 ticks, so the 4-tick rung's frames anticorrelate and its peak
/// sits a particle radius off; it reported 8.7 and 7.4 px errors with
/// every valid vector beyond 3σ. Now no more than 5 % of what it reports
/// valid is off by more than 3σ and 0.3 px.
#[test]
fn dim_slow_turbulence_is_not_confidently_wrong() {
    let fam = spectral();
    for seed in [107, 109] {
        let p = fam.params(seed);
        assert!(p.particle_peak < 0.12, "seed {seed} is a dim member");
        let (sim, dt, out) = flow_of(&p, seed, fam.ticks, false, true);
        let mut score = ValidScore::default();
        for pr in &out.pairs {
            score.add(&sim, dt, pr);
        }
        let ValidScore { valid, wrong, .. } = score;
        assert!(
            wrong * 20 <= valid,
            "seed {seed}: {wrong} of {valid} valid vectors confidently wrong"
        );
    }
}

/// `spiv flow` on a slow spectral member of 62 planes (tuning seed 4:
/// 0.64 px per pair, eddies down to 17 px, dim particles in a light
/// sheet): its central pair climbs to the 31 ticks the recording holds on
/// each side, and the particles that sit through the recording's start
/// are not trained into the static light. Before both, it measured 2 % of
/// the vectors (0.40 px off); stopping at the 16-tick rung with the
/// particles trained on their background, 9 % (0.56 px); with the 31-tick
/// rung but the particles trained in, 53 % at 0.50 px (the rung frames
/// showed only where the particles went, and their peak lay a particle
/// radius along the motion).
#[test]
fn a_short_slow_recording_measures_its_particles() {
    let seed = 4;
    let fam = spectral();
    let p = fam.params(seed);
    let (sim, dt, out) = flow_of(&p, seed, fam.ticks, false, true);
    let (mut all, mut measured, mut err) = (0, 0, 0.0);
    for pr in &out.pairs {
        assert!(
            pr.rungs.iter().any(|r| r.separation == 31),
            "the rung the recording holds: {:?}",
            pr.rungs
        );
        let mid = Scene::pair_mid(pr.ticks[0], pr.ticks[1]);
        let pts: Vec<(f64, f64)> = pr.vectors.iter().map(|v| (v.x, v.y)).collect();
        for (v, t) in pr
            .vectors
            .iter()
            .zip(sim.scene.truth_at(&pts, mid, f64::from(dt)))
        {
            all += 1;
            if v.state.is_measured() {
                measured += 1;
                err += (v.u - t.2).hypot(v.v - t.3);
            }
        }
    }
    let share = measured as f64 / all as f64;
    let epe = err / measured.max(1) as f64;
    assert!(
        share >= 0.6,
        "{:.0} % of the vectors measured",
        100.0 * share
    );
    assert!(epe <= 0.4, "measured vectors {epe:.3} px off");
}

/// `spiv flow` on a dim, slow spectral member that neither the bootstrap
/// rungs nor the dense ensemble measure (seed 21: 0.15 thresholds/tick,
/// 1.4 px per pair, eddies down to 16 px, 62 planes): its 4-tick rung's
/// peak sits a particle radius off and is refuted, its 8-tick rung and
/// the ensemble's 6-tick frames hold too few spikes. Climbed from rest
/// (the 16- and 31-tick rungs, uncompensated, predicted by a still
/// flow), it measures 76 % of the vectors at 0.39 px, 3.5 % of them
/// beyond 3σ; before, it measured nothing.
#[test]
fn a_dim_slow_flow_is_climbed_from_rest() {
    let seed = 21;
    let fam = spectral();
    let p = fam.params(seed);
    let (sim, dt, out) = flow_of(&p, seed, fam.ticks, false, true);
    let mut score = ValidScore::default();
    for pr in &out.pairs {
        let bootstrap_refuted = pr.rungs.iter().any(|r| r.separation == 8 && r.kept == 0);
        let from_rest = pr.rungs.iter().any(|r| r.separation == 16 && r.kept > 0);
        assert!(bootstrap_refuted && from_rest, "rungs {:?}", pr.rungs);
        score.add(&sim, dt, pr);
    }
    let ValidScore {
        all,
        valid,
        wrong,
        err,
    } = score;
    let share = valid as f64 / all as f64;
    let epe = err / valid.max(1) as f64;
    assert!(share >= 0.6, "{:.0} % of the vectors valid", 100.0 * share);
    assert!(epe <= 0.5, "valid vectors {epe:.3} px off");
    assert!(
        wrong * 20 <= valid,
        "{wrong} of {valid} valid vectors confidently wrong"
    );
}
