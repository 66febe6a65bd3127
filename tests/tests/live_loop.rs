//! The loop between the core and the estimator as a live downlink runs it:
//! the estimator's asks arrive late by whole pairs, and some are lost
//! or corrupted (`FlowOptions::delivery`: each ask goes as its wire
//! messages, which the core hears through its CRC and checks). On a steady
//! flow the loop stays as accurate
//! as `spiv flow` (asks at once) after its first pairs, and what each pair
//! costs on the wire is counted.

use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_to_dir, Request};
use spiv_formats::dat::DatOptions;
use spiv_formats::vectors::read_vectors;
use spiv_formats::{State, Vector};
use spiv_host::estimator::control::Delivery;
use spiv_host::flow::{run_flow, FlowOptions, FlowOutcome, Recording};
use spiv_host::reconstruct::FileOptions;

/// A recording of `ticks` planes of the scene `p` at `seed`, in a
/// temporary folder (kept while the first value lives), and its truth.
fn recorded(p: SceneParams, seed: u64, ticks: u32) -> (tempfile::TempDir, Recording, Vec<Vector>) {
    let dir = tempfile::tempdir().unwrap();
    let mut req = Request::new(p, seed);
    req.ticks = Some(ticks);
    simulate_to_dir(&req, dir.path(), |_, _| {}).expect("simulates");
    let o = FileOptions {
        width: None,
        height: None,
        dat: DatOptions::default(),
    };
    let rec = Recording::open(&dir.path().join("spikes.dat"), &o).expect("opens");
    let truth = read_vectors(&dir.path().join("truth.csv")).expect("truth.csv");
    (dir, rec, truth)
}

/// Mean EPE (px per pair) of the measured vectors of the pairs after the
/// third, against the truth, and the share of them measured.
fn after_third(out: &FlowOutcome, truth: &[Vector]) -> (f64, f64) {
    let (mut e, mut n, mut all) = (0.0, 0usize, 0usize);
    for p in out.pairs.iter().skip(3) {
        for (v, t) in p.vectors.iter().zip(truth) {
            all += 1;
            if v.state.is_measured() {
                e += (v.u - t.u).hypot(v.v - t.v);
                n += 1;
            }
        }
    }
    (e / n.max(1) as f64, n as f64 / all.max(1) as f64)
}

/// Asks one and three pairs late, one late with a tenth lost, and one late
/// with 5 % lost and 5 % corrupted: after the third pair each measures the
/// paper's linear profile within 1.2× of `spiv flow`'s EPE with as many
/// vectors.
#[test]
fn late_and_lost_asks_measure_as_well_as_immediate_ones() {
    let mut p = SceneParams::new(SceneKind::PaperLinear);
    (p.width, p.height) = (192, 128);
    let (_dir, rec, truth) = recorded(p, 3, 700);
    let base = FlowOptions {
        wire_bytes: true,
        ..FlowOptions::new(&rec, rec.meta_dt.expect("scene.json names the pair"))
    };
    let now = run_flow(&rec, &base, |_, _| {}).expect("runs");
    assert!(now.pairs.len() >= 6, "{} pairs", now.pairs.len());
    // One algorithm, two transports: every pair sent up the wire and read
    // back from its messages measures exactly what the pair made in
    // process does.
    let plain = FlowOptions {
        wire_bytes: false,
        ..base.clone()
    };
    let in_process = run_flow(&rec, &plain, |_, _| {}).expect("runs");
    assert_eq!(in_process.pairs.len(), now.pairs.len());
    for (a, b) in in_process.pairs.iter().zip(&now.pairs) {
        assert!(a.bytes.is_none() && b.bytes.is_some());
        assert_eq!(a.vectors, b.vectors);
        assert_eq!(a.sigma, b.sigma);
    }
    let (e0, m0) = after_third(&now, &truth);
    eprintln!("asks at once: EPE {e0:.4}, {:.0} % measured", 100.0 * m0);
    assert!(e0 < 0.1, "{e0}");
    // Every pair's frames and events were counted; a pair of rung frames
    // alone (whole spikes above the rungs' floors) costs less than a third
    // of the raw spikes between pairs.
    let raw = u64::from(base.every) * 192 * 128 / 8;
    for pr in &now.pairs {
        let b = pr.bytes.expect("counted");
        eprintln!("{b:?}: raw / wire {:.1}", raw as f64 / b.total() as f64);
        assert!(b.total() > 0 && b.total() < raw, "{b:?} against {raw}");
        if b.events == 0 {
            assert!(3 * b.total() < raw, "{b:?} against {raw}");
        }
    }
    for (late, loss, corrupt) in [(1, 0.0, 0.0), (3, 0.0, 0.0), (1, 0.1, 0.0), (1, 0.05, 0.05)] {
        let o = FlowOptions {
            delivery: Delivery {
                late,
                loss,
                corrupt,
                seed: 11,
            },
            ..base.clone()
        };
        let out = run_flow(&rec, &o, |_, _| {}).expect("runs");
        let (e, m) = after_third(&out, &truth);
        eprintln!(
            "{late} late, {:.0} % lost, {:.0} % corrupted: EPE {e:.4}, {:.0} % measured",
            100.0 * loss,
            100.0 * corrupt,
            100.0 * m
        );
        assert!(e <= 1.2 * e0, "{late} late, {loss} lost: {e} against {e0}");
        assert!(
            m >= m0 - 0.02,
            "{late} late, {loss} lost: {m} measured against {m0}"
        );
    }
}

/// A vortex array at 1 px per tick (10 px per pair), measured from the
/// loop's very first pair: the loop starts cold (no warm-up pair fits
/// before tick 40), and a pair with no field before it carries its
/// events, whose short rungs nothing blurs, and climbs them again along
/// what they measured. The first pair has at least 80 % of its vectors
/// valid and errs about as the later pairs do.
#[test]
fn a_fast_flow_is_measured_from_the_first_pair() {
    let p = SceneParams {
        top_speed: 1.0,
        ..SceneParams::new(SceneKind::VortexArray)
    };
    let (_dir, rec, truth) = recorded(p, 3, 400);
    let mut opts = FlowOptions::new(&rec, rec.meta_dt.expect("scene.json names the pair"));
    opts.start = 40;
    let out = run_flow(&rec, &opts, |_, _| {}).expect("runs");
    assert!(out.pairs.len() >= 4, "{} pairs", out.pairs.len());
    let score = |p: &spiv_host::flow::PairResult| {
        let (mut e, mut n, mut valid) = (0.0, 0usize, 0usize);
        for (v, t) in p.vectors.iter().zip(&truth) {
            valid += usize::from(v.state == State::Valid);
            if v.state.is_measured() {
                e += (v.u - t.u).hypot(v.v - t.v);
                n += 1;
            }
        }
        (valid as f64 / p.vectors.len() as f64, e / n.max(1) as f64)
    };
    let (valid, first) = score(&out.pairs[0]);
    let later: f64 =
        out.pairs[1..].iter().map(|p| score(p).1).sum::<f64>() / (out.pairs.len() - 1) as f64;
    eprintln!(
        "first pair: {:.0} % valid, EPE {first:.3} px; later pairs {later:.3} px",
        100.0 * valid
    );
    assert!(valid >= 0.8, "{valid}");
    assert!(first <= 1.5 * later, "{first} against {later}");
    assert!(later < 1.0, "{later}");
}
