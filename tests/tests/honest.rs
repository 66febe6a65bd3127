//! Never a confidently wrong field: where `spiv flow` cannot
//! measure — no particles, displacements beyond every window, a flow faster
//! than its first rung reaches, a prediction that is wrong — it says so:
//! every vector is invalid, or its error stays within its uncertainty.
//!
//! "Within" means at most four standard uncertainties (of the vector's
//! length) plus 0.1 px: a measurement as good as its uncertainty says is
//! outside one σ a third of the time, so a test of every vector must
//! allow the tail; a confidently wrong vector misses by many σ.

use ndarray::Array2;
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_formats::State;
use spiv_host::estimator::control::Ask;
use spiv_host::estimator::make::input_of;
use spiv_host::estimator::{measure, LadderSettings};
use spiv_host::flow::{run_flow, FlowOptions, PairResult, Recording};
use spiv_host::piv::{Field, NO_SIGMA};
use spiv_host::reconstruct::Planes;

/// A simulated recording of `p` with `ticks` planes, and its scene.
fn simulated(p: SceneParams, seed: u64, ticks: u32) -> (Recording, Scene, Vec<u8>) {
    let mut req = Request::new(p.clone(), seed);
    req.ticks = Some(ticks);
    let (data, sim) = simulate_planes(&req).expect("simulates");
    let rec = Recording::simulated(p.width, p.height, data.clone(), p.pair_dt);
    (rec, sim.scene, data)
}

/// Valid or replaced vectors whose error exceeds 4σ + 0.1 px, as
/// (x, y, error, σ, state).
fn confidently_wrong(p: &PairResult, scene: &Scene, dt: f64) -> Vec<(f64, f64, f64, f64, State)> {
    let pts: Vec<(f64, f64)> = p.vectors.iter().map(|v| (v.x, v.y)).collect();
    p.vectors
        .iter()
        .zip(scene.truth(&pts, dt))
        .zip(&p.sigma)
        .filter(|((v, _), _)| v.state != State::Invalid)
        .map(|((v, t), &(su, sv))| {
            let e = (v.u - t.2).hypot(v.v - t.3);
            (v.x, v.y, e, su.hypot(sv), v.state)
        })
        .filter(|&(_, _, e, s, _)| e.is_nan() || e > 4.0 * s + 0.1)
        .collect()
}

fn all_invalid(p: &PairResult) -> bool {
    p.vectors.iter().all(|v| v.state == State::Invalid)
        && p.sigma
            .iter()
            .all(|s| s.0.is_infinite() && s.1.is_infinite())
}

/// Pure noise: every pixel fires at random, no particle anywhere. Nothing
/// is measured, so nothing is valid (the 128-tick windows of the first
/// motion-compensated design correlated with themselves: 900 of 900
/// vectors valid).
#[test]
fn pure_noise_measures_nothing() {
    let (w, h, ticks) = (256u16, 256u16, 160usize);
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut bit = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        u8::from(s.is_multiple_of(20))
    };
    let px = usize::from(w) * usize::from(h);
    let mut data = vec![0u8; px / 8 * ticks];
    for byte in data.iter_mut() {
        for b in 0..8 {
            *byte |= bit() << b;
        }
    }
    let rec = Recording::simulated(w, h, data, 10);
    let o = FlowOptions::new(&rec, 10);
    let out = run_flow(&rec, &o, |_, _| {}).expect("runs");
    assert!(!out.pairs.is_empty());
    for p in &out.pairs {
        let (v, r, _) = p.counts();
        assert!(all_invalid(p), "pure noise: {v} valid, {r} replaced");
        assert!(!p.measured());
    }
}

/// Static light only (the vortex array's glare band, no particles):
/// nothing moves, nothing is measured.
#[test]
fn glare_without_particles_measures_nothing() {
    let p = SceneParams {
        particle_peak: 0.0,
        ..SceneParams::new(SceneKind::VortexArray)
    };
    let (rec, _, _) = simulated(p, 3, 160);
    let o = FlowOptions::new(&rec, 10);
    let out = run_flow(&rec, &o, |_, _| {}).expect("runs");
    for p in &out.pairs {
        let (v, r, _) = p.counts();
        assert!(all_invalid(p), "static glare: {v} valid, {r} replaced");
    }
}

/// Uniform motion far beyond every window (16 px per tick: 64 px over the
/// first rung, 160 px per pair) and beyond the first rung's reach (12 px
/// per tick): invalid, or within its uncertainty.
#[test]
fn motion_beyond_reach_is_not_confidently_wrong() {
    for speed in [12.0, 16.0] {
        let dt = 10;
        let p = SceneParams {
            width: 256,
            height: 256,
            pair_dt: dt,
            shift: (speed * f64::from(dt), 0.0),
            ..SceneParams::new(SceneKind::Uniform)
        };
        let (rec, scene, _) = simulated(p, 5, 160);
        let o = FlowOptions::new(&rec, dt);
        let out = run_flow(&rec, &o, |_, _| {}).expect("runs");
        for pr in &out.pairs {
            let bad = confidently_wrong(pr, &scene, f64::from(dt));
            let (v, r, i) = pr.counts();
            eprintln!(
                "{speed} px/tick: {v} valid, {r} replaced, {i} invalid; {} confidently wrong",
                bad.len()
            );
            assert!(
                bad.is_empty(),
                "{speed} px/tick: {:?}",
                &bad[..bad.len().min(5)]
            );
        }
    }
}

/// The vortex array's true velocities at the ladder's nodes, times `k`.
fn predicted(scene: &Scene, (w, h): (usize, usize), k: f64) -> Field {
    let cfg = LadderSettings::default();
    let grid = cfg.piv.grid(w, h).expect("grid");
    let shape = (grid.ny, grid.nx);
    let mut u = Array2::zeros(shape);
    let mut v = Array2::zeros(shape);
    for (r, c) in ndarray::indices(shape) {
        let (x, y) = grid.centre(r, c);
        let (a, b) = scene.flow.velocity(x + 0.5, y + 0.5);
        u[[r, c]] = k * a;
        v[[r, c]] = k * b;
    }
    Field {
        grid,
        u,
        v,
        state: Array2::from_elem(shape, State::Valid),
        peak_ratio: Array2::zeros(shape),
        peak_height: Array2::zeros(shape),
        sigma: Array2::from_elem(shape, NO_SIGMA),
    }
}

/// A pair made along a flow twice the truth, and one with its sign
/// flipped (its rung frames warped along it, its events beside them): its
/// first rung does not confirm the flow, and the ladder climbs from the
/// events instead. Every valid vector whose uncertainty tells the truth
/// from the prediction lies nearer the truth (in the glare band's bottom
/// corner a vector 2 px off with σ above half the difference lies nearer
/// neither by its own account), and so does every replaced one: a
/// replaced vector in the grid's outer column is filled from the column
/// inside it, and where a vortex's edge runs between the two (u −2.5 px
/// per pair inside, −0.6 at the edge) it reads the inside's speed, nearer
/// twice the truth; its uncertainty carries the field's change over the
/// next step inwards (without it, two such vectors carried the inside's
/// 0.18 px and one of them lay nearer the prediction by its own account).
/// At most 2 % of the valid and replaced vectors miss by more than
/// 4σ + 0.1 px: the remainder is the bottom grid row in the glare band,
/// where the glare's fixed pattern pulls the wall-normal component towards
/// zero by about 0.5 px per pair, a bias the correlation statistics cannot
/// see.
#[test]
fn a_wrong_prediction_is_not_confirmed() {
    let p = SceneParams {
        top_speed: 0.5,
        ..SceneParams::new(SceneKind::VortexArray)
    };
    let dt = p.pair_dt;
    let (_, scene, data) = simulated(p.clone(), 7, 160);
    let planes = Planes::simulated(p.width, p.height, data);
    let size = (usize::from(p.width), usize::from(p.height));
    let cfg = LadderSettings::default();
    for k in [2.0, -1.0] {
        let ask = Ask {
            flow: Some(spiv_host::estimator::units::PerTick(predicted(
                &scene, size, k,
            ))),
            rungs: vec![16, 32, 64],
            reach: cfg.bootstrap_reach,
        };
        let input = input_of(&planes, 80, &ask, cfg.bootstrap_reach).expect("made");
        assert_eq!(input.rungs.len(), 3);
        let m = measure(
            &input,
            80,
            spiv_host::estimator::units::Ticks(f64::from(dt)),
            &cfg,
            size,
            true,
        )
        .expect("measures");
        assert_eq!(m.confirmed, Some(false), "prediction × {k} confirmed");
        let pr = PairResult {
            method: spiv_core::Method::Ladder,
            ticks: [75, 85],
            vectors: m.field.vectors(),
            sigma: m.field.sigma.iter().copied().collect(),
            caps: Vec::new(),
            bootstrapped: false,
            lost: Default::default(),
            rungs: m.rungs.clone(),
            separation: Vec::new(),
            bytes: None,
        };
        let (v, r, i) = pr.counts();
        let pts: Vec<(f64, f64)> = pr.vectors.iter().map(|v| (v.x, v.y)).collect();
        let truth = scene.truth(&pts, f64::from(dt));
        // Vectors of a state whose uncertainty tells the truth from the
        // prediction (they differ by more than 2σ there) and that lie
        // nearer the prediction.
        let nearer_prediction = |state: State| {
            pr.vectors
                .iter()
                .zip(&truth)
                .zip(&pr.sigma)
                .filter(|((v, _), _)| v.state == state)
                .filter(|((v, t), &(su, sv))| {
                    let apart = ((k - 1.0) * t.2).hypot((k - 1.0) * t.3);
                    let e = (v.u - t.2).hypot(v.v - t.3);
                    let ep = (v.u - k * t.2).hypot(v.v - k * t.3);
                    apart > 2.0 * su.hypot(sv) && ep < e
                })
                .count()
        };
        let (measured, filled) = (
            nearer_prediction(State::Valid),
            nearer_prediction(State::Replaced),
        );
        let bad = confidently_wrong(&pr, &scene, f64::from(dt));
        eprintln!(
            "prediction × {k}: {v} valid, {r} replaced, {i} invalid; {measured} valid and {filled} replaced nearer the prediction; {} confidently wrong",
            bad.len()
        );
        assert_eq!(measured, 0, "prediction × {k} confirmed");
        assert_eq!(filled, 0, "prediction × {k}: replaced vectors nearer it");
        assert!(
            bad.len() * 50 <= v + r,
            "prediction × {k}: {:?}",
            &bad[..bad.len().min(5)]
        );
    }
}
