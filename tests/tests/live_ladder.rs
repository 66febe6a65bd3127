//! The live loop of the time ladder as a user runs it: `spiv-firmware-sim
//! --input rec.dat --method ladder --tcp ADDR --control-wait MS` makes each
//! pair in the core (its events, or its rung frames along the flow the
//! host asked for) and `spiv receive --tcp ADDR --piv --control --out DIR`
//! measures it with `spiv flow`'s ladder and sends the next ask back on
//! the connection. With every ask heard before the next pair (the
//! sidecar waits for it), the vectors are those `spiv flow` writes for the
//! same recording, number for number: one algorithm, two transports.
//!
//! The recording: a vortex array at 1 px/tick (256 × 256 px, 420 planes,
//! seed 3). The sidecar's first pair is `spiv flow`'s first warm-up pair
//! (midpoint 48 with pairs 40 ticks apart), so its pairs 2, 3, … are
//! `spiv flow`'s pairs 0, 1, …. Its first pair, cold, is measured too:
//! on this seed 89 % of its vectors are valid, and the bar is 80 %.

use std::path::Path;
use std::process::Stdio;

use spiv_formats::vectors::{read_vectors, State, Vector};
use spiv_tests::{command, listening_sidecar, run};

fn simulate(dir: &Path) {
    let out = run(
        "spiv",
        &[
            "simulate",
            "--scene",
            "vortex-array",
            "--speed",
            "1.0",
            "--seed",
            "3",
            "--ticks",
            "420",
            "--out",
            dir.to_str().expect("utf-8 path"),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Runs `spiv-firmware-sim --input dat --method ladder --tcp` with `extra`
/// into `spiv receive --piv --control --out live`; what the receiver
/// printed.
fn live_loop(dat: &Path, extra: &[&str], live: &Path) -> String {
    let args: Vec<String> = ["--input", dat.to_str().expect("utf-8")]
        .iter()
        .chain(&["--method", "ladder", "--tcp", "127.0.0.1:0"])
        .chain(extra)
        .map(|s| s.to_string())
        .collect();
    let (mut sidecar, _err, addr) = listening_sidecar(&args);
    let rx = command("spiv")
        .args(["receive", "--tcp", &addr, "--piv", "--control", "--out"])
        .arg(live)
        .stderr(Stdio::piped())
        .output()
        .expect("spiv receive");
    assert!(
        rx.status.success(),
        "{}",
        String::from_utf8_lossy(&rx.stderr)
    );
    assert!(sidecar.wait().expect("sidecar").success());
    String::from_utf8_lossy(&rx.stdout).into_owned()
}

fn vectors(dir: &Path, i: usize) -> Vec<Vector> {
    read_vectors(&dir.join(format!("vectors_{i:05}.csv"))).expect("vectors")
}

fn valid(v: &[Vector]) -> f64 {
    v.iter().filter(|v| v.state == State::Valid).count() as f64 / v.len().max(1) as f64
}

#[test]
fn the_sidecar_and_spiv_flow_measure_the_same_vectors() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let sim = tmp.path().join("sim");
    simulate(&sim);
    let dat = sim.join("spikes.dat");
    let flow = tmp.path().join("flow");
    let out = run(
        "spiv",
        &[
            "flow",
            dat.to_str().expect("utf-8"),
            "--quiet",
            "--out",
            flow.to_str().expect("utf-8"),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let extra = &["--first", "43", "--control-wait", "60000"];
    let live = tmp.path().join("live");
    let said = live_loop(&dat, extra, &live);
    assert!(said.contains("0 broken pairs"), "{said}");

    let mut compared = 0;
    for i in 0.. {
        if !flow.join(format!("vectors_{i:05}.csv")).is_file() {
            break;
        }
        let (a, b) = (vectors(&flow, i), vectors(&live, i + 2));
        assert_eq!(a.len(), b.len(), "pair {i}");
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(
                (x.x, x.y, x.u, x.v, x.state),
                (y.x, y.y, y.u, y.v, y.state),
                "spiv flow's pair {i} against the live loop's pair {}",
                i + 2
            );
        }
        compared += 1;
    }
    assert!(compared >= 4, "{compared} pairs compared");
    let first = vectors(&live, 0);
    assert!(
        valid(&first) >= 0.80,
        "first pair {:.2} valid",
        valid(&first)
    );
}

/// Unpaced, the sidecar runs ahead of the host (its pairs go cold while
/// the asks are late) and ends its link gracefully: every pair it sent
/// reaches the host and is measured, none lost to a reset connection.
#[test]
fn an_unpaced_sidecar_loses_no_pair_at_the_end() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let sim = tmp.path().join("sim");
    simulate(&sim);
    let dat = sim.join("spikes.dat");
    let extra = &[];
    let live = tmp.path().join("live");
    let said = live_loop(&dat, extra, &live);
    // Pairs every 40 ticks from midpoint 32 while frame A + 10 < 420.
    assert!(said.contains("(10 pairs,"), "{said}");
    assert!(
        said.contains("0 broken pairs") && !said.contains("refused"),
        "{said}"
    );
    for i in 0..10 {
        assert!(!vectors(&live, i).is_empty(), "pair {i}");
    }
}
