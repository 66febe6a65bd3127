//! The sidecar link end to end, as a user runs it: `spiv-firmware-sim`
//! → a real OS pipe, a loopback TCP socket or a recorded file → `spiv
//! receive --piv`. Every frame that arrives must equal, sample for sample,
//! the frame the same firmware computes in process; every frame that does not
//! must be counted lost; and the vectors written for each received pair must
//! equal PIV run in process on the in-process frames.

use std::collections::BTreeMap;

use std::path::Path;
use std::process::Stdio;

use ndarray::Array2;
use spiv_firmware_sim::drive::run_on_scene;
use spiv_firmware_sim::firmware::{Config, SentFrame};
use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::Request;
use spiv_formats::image::read_gray;
use spiv_formats::vectors::write_vectors;
use spiv_host::piv::piv;
use spiv_host::receive::receiver_settings;
use spiv_host::reconstruct::upright;
use spiv_tests::{command, listening_sidecar, run};

/// The paper's camera (paper-linear at its own size).
const W: u16 = 400;
const H: u16 = 250;
/// Adaptive window limit n_max, ticks (`--window`).
const WINDOW: u16 = 16;
const SEED: u64 = 2;

/// The firmware-sim arguments of every test but the output (`seed` seeds
/// the scene and the faults).
fn sim_args(pairs: u32, seed: u64) -> Vec<String> {
    [
        "--scene",
        "paper-linear",
        "--width",
        &W.to_string(),
        "--height",
        &H.to_string(),
        "--window",
        &WINDOW.to_string(),
        "--pairs",
        &pairs.to_string(),
        "--seed",
        &seed.to_string(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

/// The frames the same firmware makes in process, by (pair, member) — the
/// configuration `spiv-firmware-sim` documents for these flags.
fn in_process(pairs: u32, seed: u64) -> BTreeMap<(u32, u8), SentFrame> {
    let mut p = SceneParams::new(SceneKind::from_name("paper-linear").expect("scene"));
    p.width = W;
    p.height = H;
    let mut cfg = Config::new(0, p.pair_dt);
    cfg.params.n_max = WINDOW;
    cfg.schedule.first = u32::from(WINDOW / 2);
    cfg.schedule.every = 4 * p.pair_dt;
    cfg.schedule.pairs = Some(pairs);
    let (mut fw, _) = run_on_scene(
        &Request::new(p, seed),
        cfg,
        Vec::new(),
        true,
        None,
        |_, _| {},
    )
    .expect("firmware");
    let sent = fw.keep.take().expect("kept frames");
    assert_eq!(sent.len(), 2 * pairs as usize, "two frames per pair");
    sent.into_iter().map(|f| ((f.pair, f.member), f)).collect()
}

fn upright_f32(f: &SentFrame) -> Array2<f32> {
    let up = upright(&f.data, W, true);
    let w = usize::from(W);
    Array2::from_shape_fn((usize::from(H), w), |(i, j)| f32::from(up[i * w + j]))
}

/// `spiv receive --json` counts.
fn counts(stdout: &[u8]) -> serde_json::Value {
    serde_json::from_slice(stdout).unwrap_or_else(|e| {
        panic!(
            "receive --json printed no JSON ({e}): {}",
            String::from_utf8_lossy(stdout)
        )
    })
}

fn count(report: &serde_json::Value, key: &str) -> u64 {
    report[key]
        .as_u64()
        .unwrap_or_else(|| panic!("no count {key} in {report}"))
}

/// Checks a receive directory against the in-process frames: every frame
/// file equals its in-process frame, and every pair with both frames has the
/// vectors of in-process PIV (written the same way, compared byte for byte).
/// Returns the frames found.
fn check_received(dir: &Path, sent: &BTreeMap<(u32, u8), SentFrame>) -> usize {
    let settings = receiver_settings(vec![64, 32, 32]);
    let mut found = 0;
    let scratch = tempfile::tempdir().expect("tempdir");
    let mut pairs: BTreeMap<u32, u8> = BTreeMap::new();
    for (&(pair, member), f) in sent {
        let name = format!(
            "frame_{pair:05}_{}.png",
            if member == 0 { "a" } else { "b" }
        );
        let path = dir.join(&name);
        if !path.exists() {
            continue;
        }
        let img = read_gray(&path).expect("read received frame");
        assert_eq!((img.width, img.height), (u32::from(W), u32::from(H)));
        assert!(
            img.data == upright(&f.data, W, true),
            "{name} differs from the frame computed in process"
        );
        found += 1;
        *pairs.entry(pair).or_default() += 1;
    }
    let files = std::fs::read_dir(dir)
        .expect("read out dir")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("frame_"))
        .count();
    assert_eq!(files, found, "a frame file that was never sent");
    for (pair, members) in pairs {
        let csv = dir.join(format!("vectors_{pair:05}.csv"));
        if members < 2 {
            assert!(!csv.exists(), "vectors for broken pair {pair}");
            continue;
        }
        let (a, b) = (&sent[&(pair, 0)], &sent[&(pair, 1)]);
        let field = piv(&upright_f32(a), &upright_f32(b), None, &settings).expect("piv");
        let want = scratch.path().join("want.csv");
        write_vectors(&want, &field.vectors()).expect("write");
        let got = std::fs::read(&csv).unwrap_or_else(|e| panic!("{}: {e}", csv.display()));
        assert!(
            got == std::fs::read(&want).expect("read"),
            "pair {pair}: vectors from the received frames differ from in-process PIV"
        );
        assert!(
            field
                .vectors()
                .iter()
                .filter(|v| v.state == spiv_formats::State::Valid)
                .count()
                > 0,
            "pair {pair}: no valid vector at all, the comparison would be empty"
        );
    }
    found
}

fn receive_args(out: &Path) -> Vec<String> {
    ["--out", out.to_str().expect("utf-8"), "--piv", "--json"]
        .iter()
        .map(|s| s.to_string())
        .collect()
}

/// `spiv-firmware-sim ARGS | spiv receive --pipe --out OUT --piv --json`
/// through a real OS pipe; returns receive's counts.
fn through_pipe(sim: &[String], out: &Path) -> serde_json::Value {
    let mut fw = command("spiv-firmware-sim")
        .args(sim)
        .arg("--quiet")
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn spiv-firmware-sim");
    let pipe = fw.stdout.take().expect("stdout");
    let rx = command("spiv")
        .args(["receive", "--pipe"])
        .args(receive_args(out))
        .stdin(Stdio::from(pipe))
        .output()
        .expect("spawn spiv receive");
    assert!(fw.wait().expect("wait").success(), "firmware-sim failed");
    assert!(
        rx.status.success(),
        "spiv receive: {}",
        String::from_utf8_lossy(&rx.stderr)
    );
    counts(&rx.stdout)
}

/// `spiv-firmware-sim ARGS --out FILE`, then `spiv receive --file FILE`.
fn through_file(sim: &[String], out: &Path) -> serde_json::Value {
    let file = out.with_extension("bin");
    let fw = run(
        "spiv-firmware-sim",
        &sim.iter()
            .map(String::as_str)
            .chain(["--quiet", "--out", file.to_str().expect("utf-8")])
            .collect::<Vec<_>>(),
    );
    assert!(
        fw.status.success(),
        "firmware-sim: {}",
        String::from_utf8_lossy(&fw.stderr)
    );
    let rx = command("spiv")
        .args(["receive", "--file", file.to_str().expect("utf-8")])
        .args(receive_args(out))
        .output()
        .expect("spawn spiv receive");
    assert!(
        rx.status.success(),
        "spiv receive: {}",
        String::from_utf8_lossy(&rx.stderr)
    );
    counts(&rx.stdout)
}

#[test]
fn pipe_delivers_every_frame_bit_exact_and_piv_equals_in_process() {
    let pairs = 3;
    let sent = in_process(pairs, SEED);
    let out = tempfile::tempdir().expect("tempdir");
    let report = through_pipe(&sim_args(pairs, SEED), out.path());
    assert_eq!(count(&report, "frames"), 2 * u64::from(pairs));
    assert_eq!(count(&report, "pairs"), u64::from(pairs));
    for key in ["lost_frames", "corrupted", "lost_messages", "broken_pairs"] {
        assert_eq!(count(&report, key), 0, "{key} on a clean pipe");
    }
    assert_eq!(check_received(out.path(), &sent), sent.len());
}

#[test]
fn loopback_tcp_delivers_every_frame_bit_exact() {
    let pairs = 2;
    let sent = in_process(pairs, SEED);
    let out = tempfile::tempdir().expect("tempdir");
    // Port 0: the OS picks a free port and firmware-sim prints it.
    let mut args = sim_args(pairs, SEED);
    args.extend(["--tcp".to_string(), "127.0.0.1:0".to_string()]);
    let (mut sim, mut err, addr) = listening_sidecar(&args);
    let rx = command("spiv")
        .args(["receive", "--tcp", &addr])
        .args(receive_args(out.path()))
        .output()
        .expect("spawn spiv receive");
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).expect("drain stderr");
    assert!(sim.wait().expect("wait").success(), "firmware-sim: {rest}");
    assert!(
        rest.contains("frames"),
        "firmware-sim prints its throughput: {rest}"
    );
    assert!(
        rx.status.success(),
        "spiv receive: {}",
        String::from_utf8_lossy(&rx.stderr)
    );
    let report = counts(&rx.stdout);
    assert_eq!(count(&report, "frames"), 2 * u64::from(pairs));
    assert_eq!(count(&report, "lost_frames"), 0);
    assert_eq!(check_received(out.path(), &sent), sent.len());
}

/// With every kind of fault injected, through a pipe and from a recorded
/// file: nothing wrong is ever delivered and nothing is silently lost.
#[test]
fn faults_lose_frames_only_counted_never_deliver_a_wrong_one() {
    let pairs = 8;
    let mut total_lost = 0;
    for (seed, via_pipe) in [(3, true), (4, true), (5, false)] {
        let sent = in_process(pairs, seed);
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("rx");
        let mut args = sim_args(pairs, seed);
        args.extend([
            "--fault".to_string(),
            "drop=0.04,corrupt=0.04,truncate=0.04,stall=0.04,reorder=0.08,duplicate=0.08"
                .to_string(),
        ]);
        let report = if via_pipe {
            through_pipe(&args, &out)
        } else {
            through_file(&args, &out)
        };
        let frames = count(&report, "frames");
        let lost = count(&report, "lost_frames");
        assert_eq!(check_received(&out, &sent) as u64, frames);
        assert_eq!(
            frames + lost,
            sent.len() as u64,
            "seed {seed}: every frame arrives or is counted lost: {report}"
        );
        total_lost += lost;
    }
    assert!(
        total_lost > 0,
        "the faults never hit a frame: the test proves nothing"
    );
}

/// The context-modelled codecs as a user picks them (`--encoding`):
/// `context` frames arrive bit-exact with in-process PIV, in under 60 % of
/// `rice`'s bytes (measured: 42 %); `sparse-context` frames are exactly
/// `sparse`'s, in under 70 % of its bytes (measured: 51 %).
#[test]
fn context_codecs_cross_the_pipe() {
    let pairs = 2;
    let sent = in_process(pairs, SEED);
    let dir = tempfile::tempdir().expect("tempdir");
    let send = |enc: &str| {
        let out = dir.path().join(enc);
        let mut args = sim_args(pairs, SEED);
        args.extend(["--encoding".to_string(), enc.to_string()]);
        let report = through_pipe(&args, &out);
        assert_eq!(count(&report, "frames"), 2 * u64::from(pairs), "{enc}");
        assert_eq!(count(&report, "corrupted"), 0, "{enc}");
        (out, count(&report, "bytes"))
    };
    let (_, rice) = send("rice");
    let (context_dir, context) = send("context");
    assert_eq!(check_received(&context_dir, &sent), sent.len());
    assert!(
        10 * context < 6 * rice,
        "context {context} B, rice {rice} B"
    );
    let (sparse_dir, sparse) = send("sparse");
    let (sc_dir, sc) = send("sparse-context");
    for (pair, member) in sent.keys() {
        let name = format!(
            "frame_{pair:05}_{}.png",
            if *member == 0 { "a" } else { "b" }
        );
        let a = read_gray(&sparse_dir.join(&name)).expect("sparse frame");
        let b = read_gray(&sc_dir.join(&name)).expect("sparse-context frame");
        assert!(
            a.data == b.data,
            "{name}: sparse-context differs from sparse"
        );
    }
    assert!(
        100 * sc < 70 * sparse,
        "sparse-context {sc} B, sparse {sparse} B"
    );
}

#[test]
fn file_replay_equals_the_pipe() {
    let pairs = 2;
    let sent = in_process(pairs, SEED);
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("rx");
    let report = through_file(&sim_args(pairs, SEED), &out);
    assert_eq!(count(&report, "frames"), 2 * u64::from(pairs));
    assert_eq!(count(&report, "lost_frames"), 0);
    assert_eq!(check_received(&out, &sent), sent.len());
}

/// One clear line and a non-zero exit, never a panic.
fn one_line_failure(name: &str, args: &[&str]) -> String {
    let o = run(name, args);
    assert!(!o.status.success(), "{name} {args:?} should fail");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(err.trim_end().lines().count(), 1, "one line, got: {err}");
    assert!(err.starts_with(&format!("{name}: ")), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[test]
fn bad_links_and_arguments_fail_with_one_line() {
    // No sidecar on the bus (or no USB at all on a CI machine).
    one_line_failure("spiv", &["receive", "--usb"]);
    one_line_failure("spiv", &["receive", "--usb", "nonsense"]);
    // Nobody listening.
    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port");
    one_line_failure("spiv", &["receive", "--tcp", &free.to_string()]);
    // A stream that is not the wire format at all.
    let dir = tempfile::tempdir().expect("tempdir");
    let junk = dir.path().join("junk.bin");
    std::fs::write(
        &junk,
        (0..50_000u32)
            .map(|i| (i * 7919 % 251) as u8 + 1)
            .collect::<Vec<_>>(),
    )
    .expect("write");
    let err = one_line_failure(
        "spiv",
        &["receive", "--file", junk.to_str().expect("utf-8")],
    );
    assert!(err.contains("no valid message"), "{err}");
    one_line_failure("spiv", &["receive", "--file", "/nonexistent/link.bin"]);
    // The sidecar's own arguments.
    one_line_failure("spiv-firmware-sim", &["--scene", "nope"]);
    one_line_failure(
        "spiv-firmware-sim",
        &["--scene", "uniform", "--encoding", "zip"],
    );
    one_line_failure(
        "spiv-firmware-sim",
        &["--scene", "uniform", "--fault", "drop=2"],
    );
    one_line_failure(
        "spiv-firmware-sim",
        &["--scene", "uniform", "--window", "0"],
    );
    one_line_failure("spiv-firmware-sim", &["--input", "/nonexistent.dat"]);
}

/// The summary line of a run from a recording states the real-time factor:
/// simulated ticks over wall time against the recording's tick rate
/// (20 kHz in the strip's scene.json), the same rate the pixel-tick figure
/// implies for its size.
#[test]
fn the_summary_states_the_real_time_factor() {
    let strip =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware-sim/cortex-m4/data/strip.dat");
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("strip.bin");
    let r = run(
        "spiv-firmware-sim",
        &[
            "--input",
            strip.to_str().expect("utf-8"),
            "--pairs",
            "1",
            "--out",
            out.to_str().expect("utf-8"),
        ],
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let line = String::from_utf8_lossy(&r.stderr).to_string();
    let field = |before: &str| -> f64 {
        let end = line
            .find(before)
            .unwrap_or_else(|| panic!("no {before:?} in {line}"));
        let start = line[..end].rfind(' ').map_or(0, |i| i + 1);
        line[start..end].parse().expect("a number")
    };
    let (rate, factor) = (field(" pixel-ticks/s"), field("x real time at 20 kHz"));
    assert!(line.trim_end().ends_with("real time at 20 kHz"), "{line}");
    // 128 x 64 px at 20 kHz: 1.6384e8 pixel-ticks per second of sensor.
    let implied = rate / (128.0 * 64.0 * 20_000.0);
    assert!(
        factor > 0.0 && (factor / implied - 1.0).abs() < 0.02,
        "{line}"
    );
}
