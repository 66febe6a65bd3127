//! `spiv flow --dense` against the truth: each pair's dense flow refined by
//! the joint fit of every short frame around it
//! (`spiv_host::estimator::joint`) where the pair carries its events, and
//! a steady flow's dense field made of its vectors between the nodes where
//! the pair is made from rung frames alone.

mod common;

use common::flow_of;
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::simulation::Simulated;
use spiv_host::bench::flows::families;
use spiv_host::flow::FlowOutcome;

/// The dense EPE of `out`'s mean dense field against the mean of its
/// pairs' truths, px per pair.
fn dense_epe(sim: &Simulated, out: &FlowOutcome) -> f64 {
    let d = out.mean_dense.as_ref().expect("a dense field");
    let dt = f64::from(sim.meta.capture.pair[1] - sim.meta.capture.pair[0]);
    let mut truth = spiv_formats::dense::DenseField::zeros(d.width, d.height);
    let k = 1.0 / out.pairs.len() as f32;
    for pr in &out.pairs {
        let t = sim
            .scene
            .truth_dense_at(Scene::pair_mid(pr.ticks[0], pr.ticks[1]), dt);
        truth.u.iter_mut().zip(&t.u).for_each(|(a, b)| *a += k * b);
        truth.v.iter_mut().zip(&t.v).for_each(|(a, b)| *a += k * b);
    }
    d.epe(&truth, None).expect("same size")
}

/// A spectral-turbulence member outside the report seeds (23: eddies
/// down to 17 px, 1.7 px rms per pair, 62 planes): the pair carries its
/// events, and the joint fit takes its dense flow well below the dense
/// ensemble's.
#[test]
fn the_joint_fit_sharpens_the_dense_flow_of_a_pair_with_events() {
    let fam = families()
        .into_iter()
        .find(|f| f.scene == SceneKind::SpectralTurbulence)
        .expect("the family");
    let seed = 23;
    let p = fam.params(seed);
    let (sim, _, joint) = flow_of(&p, seed, fam.ticks, true, true);
    let (_, _, without) = flow_of(&p, seed, fam.ticks, true, false);
    let (a, b) = (dense_epe(&sim, &joint), dense_epe(&sim, &without));
    eprintln!("dense EPE: joint {a:.3}, without {b:.3} px per pair");
    assert!(a <= 0.85 * b, "joint {a} against {b}");
    assert!(a <= JOINT_BOUND, "joint {a}");
}

/// Dense EPE the joint fit holds member 23 to, px per pair (it measures
/// 0.559; the ensemble alone 0.751).
const JOINT_BOUND: f64 = 0.65;

/// Paper-linear's wall shear, long enough for its reported pair to be
/// made from rung frames along a confirmed field: its dense field is its
/// vectors between the nodes, carried along their paths (the dense stage
/// on the rung frames read 0.24 px), and asking for it changes no vector.
#[test]
fn a_steady_flows_dense_field_is_its_vectors_between_the_nodes() {
    let p = SceneParams::new(SceneKind::PaperLinear);
    let seed = 3;
    let (sim, _, dense) = flow_of(&p, seed, 142, true, true);
    let (_, _, plain) = flow_of(&p, seed, 142, false, true);
    assert!(plain.mean_dense.is_none());
    assert_eq!(dense.pairs.len(), plain.pairs.len());
    for (a, b) in dense.pairs.iter().zip(&plain.pairs) {
        assert_eq!(a.vectors, b.vectors, "--dense changed the vectors");
    }
    let e = dense_epe(&sim, &dense);
    eprintln!("dense EPE {e:.3} px per pair");
    assert!(e <= STEADY_BOUND, "dense EPE {e}");
}

/// Dense EPE of the steady wall shear, px per pair (it measures 0.114).
const STEADY_BOUND: f64 = 0.15;
