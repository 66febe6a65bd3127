//! The `spiv` binary as a user calls it: simulate, reconstruct, and one clear
//! line with a non-zero exit on every bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn spiv(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_spiv"))
        .args(args)
        .output()
        .expect("spawn spiv")
}

fn ok(args: &[&str]) -> String {
    let o = spiv(args);
    assert!(
        o.status.success(),
        "spiv {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs a command that must fail; returns its stderr, checked to be one line.
fn fails(args: &[&str]) -> String {
    let o = spiv(args);
    assert!(!o.status.success(), "spiv {args:?} should have failed");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(err.trim_end().lines().count(), 1, "one line, got: {err}");
    assert!(err.starts_with("spiv: "), "{err}");
    err
}

fn p(path: &Path) -> &str {
    path.to_str().expect("utf-8 temp path")
}

fn simulate_small(dir: &Path) -> PathBuf {
    let out = dir.join("sim");
    let msg = ok(&[
        "simulate",
        "--scene",
        "paper-linear",
        "--out",
        p(&out),
        "--width",
        "128",
        "--height",
        "96",
        "--seed",
        "3",
    ]);
    assert!(msg.contains("128x96"), "{msg}");
    out
}

#[test]
fn simulate_writes_every_file_and_reconstruct_reads_it_back() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let sim = simulate_small(tmp.path());
    for f in [
        "spikes.dat",
        "scene.json",
        "frame_a.png",
        "frame_b.png",
        "truth.csv",
        "profile.csv",
    ] {
        let len = std::fs::metadata(sim.join(f)).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "{f} missing or empty");
    }
    // The layout: the pair [64, 64 + dt] with 64 ticks on each side.
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sim.join("scene.json")).expect("json"))
            .expect("parse");
    let planes = meta["planes"].as_u64().expect("planes");
    let pair = &meta["pair"];
    let dt = pair[1].as_u64().expect("pair") - pair[0].as_u64().expect("pair");
    assert_eq!(pair[0].as_u64(), Some(64));
    assert_eq!(planes, dt + 2 * 64 + 1);
    let dat = std::fs::metadata(sim.join("spikes.dat"))
        .expect("dat")
        .len();
    assert_eq!(dat, planes * 128 * 96 / 8);

    for (method, bits) in [("adaptive", "8"), ("tfp", "16"), ("tfi", "8")] {
        let out = tmp.path().join(format!("{method}.png"));
        ok(&[
            "reconstruct",
            p(&sim.join("spikes.dat")),
            "--at",
            "64",
            "--method",
            method,
            "--bits",
            bits,
            "-o",
            p(&out),
        ]);
        let img = image::open(&out).expect("output image");
        assert_eq!((img.width(), img.height()), (128, 96), "{method}");
        // Not a blank frame: the scene has particles and a bright band.
        let g = img.to_luma16();
        let (lo, hi) = g
            .pixels()
            .fold((u16::MAX, 0), |(l, h), px| (l.min(px.0[0]), h.max(px.0[0])));
        assert!(hi > lo, "{method}: flat output");
    }
}

#[test]
fn bad_inputs_fail_with_one_line() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let d = tmp.path();
    let out = d.join("o.png");

    // Unknown scene, bad sizes.
    let e = fails(&["simulate", "--scene", "nope", "--out", p(&d.join("x"))]);
    assert!(e.contains("unknown scene"), "{e}");
    let e = fails(&[
        "simulate",
        "--out",
        p(&d.join("x")),
        "--width",
        "9",
        "--height",
        "9",
    ]);
    assert!(e.contains("multiple of 8"), "{e}");

    // Missing file.
    fails(&[
        "reconstruct",
        p(&d.join("missing.dat")),
        "--width",
        "8",
        "--height",
        "8",
        "--at",
        "0",
        "-o",
        p(&out),
    ]);
}

/// A recording that is empty, ragged, of an odd size or too short, and
/// bad option values: one line each, nothing written.
#[test]
fn bad_recordings_fail_with_one_line() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let d = tmp.path();
    let out = d.join("o.png");

    // Empty file.
    let empty = d.join("empty.dat");
    std::fs::write(&empty, b"").expect("write");
    let e = fails(&[
        "reconstruct",
        p(&empty),
        "--width",
        "16",
        "--height",
        "8",
        "--at",
        "0",
        "-o",
        p(&out),
    ]);
    assert!(e.to_lowercase().contains("empty"), "{e}");

    // Not a whole number of planes (16x8 -> 16 bytes a plane).
    let ragged = d.join("ragged.dat");
    std::fs::write(&ragged, vec![0u8; 16 * 3 + 5]).expect("write");
    let e = fails(&[
        "reconstruct",
        p(&ragged),
        "--width",
        "16",
        "--height",
        "8",
        "--at",
        "1",
        "-o",
        p(&out),
    ]);
    assert!(e.contains("plane"), "{e}");

    // W*H not divisible by 8.
    let odd = d.join("odd.dat");
    std::fs::write(&odd, vec![0u8; 64]).expect("write");
    fails(&[
        "reconstruct",
        p(&odd),
        "--width",
        "3",
        "--height",
        "3",
        "--at",
        "0",
        "-o",
        p(&out),
    ]);
}

/// A tick outside the recording, no size, bad option values: one line
/// each, nothing written.
#[test]
fn bad_ticks_and_options_fail_with_one_line() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let d = tmp.path();
    let out = d.join("o.png");

    // A tick outside the file.
    let whole = d.join("whole.dat");
    std::fs::write(&whole, vec![0xffu8; 16 * 4]).expect("write");
    fails(&[
        "reconstruct",
        p(&whole),
        "--width",
        "16",
        "--height",
        "8",
        "--at",
        "99",
        "-o",
        p(&out),
    ]);

    // No size and no scene.json beside the file.
    fails(&["reconstruct", p(&whole), "--at", "0", "-o", p(&out)]);

    // Bad option values.
    fails(&[
        "reconstruct",
        p(&whole),
        "--width",
        "16",
        "--height",
        "8",
        "--at",
        "0",
        "--bits",
        "12",
        "-o",
        p(&out),
    ]);
    fails(&[
        "reconstruct",
        p(&whole),
        "--width",
        "16",
        "--at",
        "0",
        "-o",
        p(&out),
    ]);
    assert!(!out.exists(), "no output written on failure");
}

#[test]
fn truncated_last_plane_is_refused_or_read_on_request() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let d = tmp.path();
    let f = d.join("t.dat");
    // 4 whole planes of 16x8 and half a fifth.
    std::fs::write(&f, vec![0x55u8; 16 * 4 + 8]).expect("write");
    let out = d.join("o.png");
    let e = fails(&[
        "reconstruct",
        p(&f),
        "--width",
        "16",
        "--height",
        "8",
        "--at",
        "2",
        "--method",
        "tfp",
        "--window",
        "3",
        "-o",
        p(&out),
    ]);
    assert!(e.contains("trunc"), "{e}");
    ok(&[
        "reconstruct",
        p(&f),
        "--width",
        "16",
        "--height",
        "8",
        "--at",
        "2",
        "--method",
        "tfp",
        "--window",
        "3",
        "--allow-truncated",
        "-o",
        p(&out),
    ]);
    let img = image::open(&out).expect("image").to_luma8();
    assert_eq!(img.dimensions(), (16, 8));
}

/// The reference captures (`SPIV_DATA`, else the repository's `data/`);
/// missing data fails the test.
fn reference_data() -> PathBuf {
    let dir = spiv_formats::reference_data_dir();
    assert!(dir.join("spike").is_dir(), "no spike/ in {}", dir.display());
    dir
}

#[test]
fn reconstructs_the_real_reference_capture() {
    let data = reference_data();
    let tmp = tempfile::tempdir().expect("tempdir");
    let out = tmp.path().join("tfp.png");
    let dat = data.join("spike/spikezoo_base_reds_400x250_301f.dat");
    ok(&[
        "reconstruct",
        p(&dat),
        "--width",
        "400",
        "--height",
        "250",
        "--at",
        "150",
        "--method",
        "tfp",
        "--window",
        "41",
        "-o",
        p(&out),
    ]);
    let got = image::open(&out).expect("out").to_luma8();
    let gt = image::open(data.join("spike/spikezoo_base_reds_400x250_gt.png"))
        .expect("gt")
        .to_luma8();
    assert_eq!(got.dimensions(), gt.dimensions());
    let (a, b): (Vec<f64>, Vec<f64>) = got
        .pixels()
        .zip(gt.pixels())
        .map(|(x, y)| (f64::from(x.0[0]), f64::from(y.0[0])))
        .unzip();
    let r = pearson(&a, &b);
    assert!(r > 0.98, "correlation with ground truth {r}");

    let npz = data.join("spike/spikezoo_uhsr_real_250x250_200f.npz");
    let out = tmp.path().join("npz.png");
    ok(&[
        "reconstruct",
        p(&npz),
        "--at",
        "100",
        "--method",
        "adaptive",
        "-o",
        p(&out),
    ]);
    let adaptive = image::open(&out).expect("npz out").to_luma8();
    assert_eq!(adaptive.dimensions(), (250, 250));
    // The capture's scene, upright: the spike count of all 200 planes.
    let s = spiv_formats::npz::read_npz_spikes(&npz).expect("npz");
    let counts = spiv_formats::dat::count_upright(&s.planes, s.packed_width, s.height, false);
    let counts: Vec<f64> = counts.iter().map(|&c| f64::from(c)).collect();
    let a: Vec<f64> = adaptive.pixels().map(|x| f64::from(x.0[0])).collect();
    let flipped: Vec<f64> = adaptive
        .rows()
        .rev()
        .flat_map(|r| r.map(|x| f64::from(x.0[0])))
        .collect();
    let bg = |img: &[f64]| -> (Vec<f64>, Vec<f64>) {
        img.iter()
            .zip(&counts)
            .filter(|(&g, _)| g < 25.0)
            .map(|(&g, &c)| (g, c))
            .unzip()
    };
    let (ga, ca) = bg(&a);
    let (gf, cf) = bg(&flipped);
    let (r, r_flip) = (pearson(&ga, &ca), pearson(&gf, &cf));
    // Dim real data: the suppressed background (below FS/β = 25.5) keeps
    // the scene's brightness, the right way up (r = 0.52, flipped −0.15
    // today), and particle regions are a few percent of the frame.
    assert!(
        ga.len() > 90 * 250 * 250 / 100,
        "{} background px",
        ga.len()
    );
    assert!(r > 0.4 && r_flip < 0.1, "r {r}, flipped {r_flip}");
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

#[test]
fn piv_on_a_simulated_pair_and_its_errors() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let sim = simulate_small(tmp.path());
    let out = tmp.path().join("v.csv");
    let msg = ok(&[
        "piv",
        p(&sim.join("frame_a.png")),
        p(&sim.join("frame_b.png")),
        "-o",
        p(&out),
        "--windows",
        "32,32",
    ]);
    assert!(msg.contains("vectors"), "{msg}");
    let v = spiv_formats::vectors::read_vectors(&out).expect("csv");
    // 128x96 with 32-px windows every 16 px: 7 x 5.
    assert_eq!(v.len(), 35);
    assert!(v.iter().all(|x| x.u.is_finite() && x.v.is_finite()));
    // --repeat times several runs and writes the same vectors once.
    let out3 = tmp.path().join("v3.csv");
    let args = |o: &Path| {
        vec![
            "piv".to_string(),
            p(&sim.join("frame_a.png")).to_string(),
            p(&sim.join("frame_b.png")).to_string(),
            "-o".into(),
            p(o).to_string(),
            "--windows".into(),
            "32,32".into(),
        ]
    };
    let mut a3 = args(&out3);
    a3.extend(["--repeat".into(), "3".into()]);
    let msg = ok(&a3.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(msg.contains("(median of 3)"), "{msg}");
    assert_eq!(
        std::fs::read(&out).expect("v"),
        std::fs::read(&out3).expect("v3")
    );
    // The same field as netCDF: u where measured, the flags, the grid.
    let nc = tmp.path().join("v.nc");
    ok(&args(&nc).iter().map(String::as_str).collect::<Vec<_>>());
    let mut r = netcdf3::FileReader::open(&nc).expect("v.nc");
    let (u, flag) = (
        r.read_var_f64("u").unwrap(),
        r.read_var_i32("flag").unwrap(),
    );
    assert_eq!((u.len(), r.read_var_f64("x").unwrap().len()), (35, 7));
    for ((a, b), f) in u.iter().zip(&v).zip(&flag) {
        assert_eq!(*f, i32::from(b.state.flag()));
        assert!(if b.state.is_measured() {
            (a - b.u).abs() < 5.1e-7
        } else {
            a.is_nan()
        });
    }
    let mut a0 = args(&out3);
    a0.extend(["--repeat".into(), "0".into()]);
    let e = fails(&a0.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(e.contains("--repeat"), "{e}");

    // A pair of different sizes, a missing image, an image smaller than the
    // window, a bad window list.
    let small = tmp.path().join("small.png");
    spiv_formats::image::write_gray8(&small, 16, 16, &[0u8; 256]).expect("png");
    let a = sim.join("frame_a.png");
    let e = fails(&["piv", p(&a), p(&small), "-o", p(&out)]);
    assert!(e.contains("differ in size"), "{e}");
    fails(&["piv", p(&a), p(&tmp.path().join("none.png")), "-o", p(&out)]);
    let e = fails(&["piv", p(&small), p(&small), "-o", p(&out)]);
    assert!(e.contains("smaller than"), "{e}");
    fails(&["piv", p(&a), p(&a), "-o", p(&out), "--windows", "2"]);
    fails(&["piv", p(&a), p(&a), "-o", p(&out), "--overlap", "1.5"]);
    let garbage = tmp.path().join("garbage.png");
    std::fs::write(&garbage, b"not a png").expect("write");
    fails(&["piv", p(&garbage), p(&a), "-o", p(&out)]);
}

#[test]
fn run_writes_the_table_images_vectors_plots_and_summary() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let out = tmp.path().join("run");
    let table = ok(&["run", "--out", p(&out)]);
    for line in [
        "frame camera",
        "spike, TFP n=8",
        "spike, adaptive",
        "frame / adaptive",
    ] {
        assert!(table.contains(line), "{line} missing in:\n{table}");
    }
    for f in [
        "frame_a.png",
        "frame_b.png",
        "tfp_a.png",
        "tfp_b.png",
        "adaptive_a.png",
        "adaptive_b.png",
        "vectors_frame.csv",
        "vectors_tfp.csv",
        "vectors_adaptive.csv",
        "mc_a.png",
        "mc_b.png",
        "vectors_mc.csv",
        "mc_wide_a.png",
        "mc_wide_b.png",
        "vectors_mc_wide.csv",
        "profile.png",
        "vectors.png",
        "summary.json",
    ] {
        let len = std::fs::metadata(out.join(f)).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "{f} missing or empty");
    }
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("json"))
            .expect("parse");
    assert_eq!(s["scene"], "paper-linear");
    let results = s["results"].as_array().expect("results");
    assert_eq!(results.len(), 5);
    let rmae = |i: usize, region: &str| results[i][region]["rmae"].as_f64().expect("number");
    // Against the simulator's truth (seed 1; today frame camera 0.543 /
    // 0.003, adaptive 0.130 / 0.027): the spike camera sees the flow in
    // the glare where the saturated frame camera does not.
    assert!(
        rmae(2, "glare") < 0.2,
        "adaptive glare {}",
        rmae(2, "glare")
    );
    assert!(rmae(2, "rest") < 0.05, "adaptive rest {}", rmae(2, "rest"));
    assert!(rmae(0, "glare") > 2.0 * rmae(2, "glare"));
    assert!(rmae(0, "rest") < 0.01);
    // Motion-compensated (seed 1: 0.157 / 0.009): the other rows within
    // about 3x the frame camera, a third of the adaptive frames' error.
    assert!(rmae(3, "rest") < 0.02, "mc rest {}", rmae(3, "rest"));
    assert!(rmae(3, "rest") < 0.5 * rmae(2, "rest"));
    assert!(table.contains("spike, motion-comp."), "{table}");
    // The wide baseline (seed 1: glare 0.004 against the pair's 0.011,
    // other rows 0.001 against 0.002).
    assert!(
        rmae(4, "rest") <= rmae(3, "rest"),
        "mc wide rest {}",
        rmae(4, "rest")
    );
    assert!(
        rmae(4, "glare") < 0.01,
        "mc wide glare {}",
        rmae(4, "glare")
    );
    assert!(table.contains("spike, m.-c. wide"), "{table}");
    assert!(s["wire"]["mc_wide_pair_bytes"].as_u64().unwrap_or(0) > 0);
    // The table is the one in summary.json: the frame camera's error in the
    // glare rows is printed as it is stored.
    let fg = results[0]["glare"]["rmae"].as_f64().expect("number");
    assert!(table.contains(&format!("{fg:.3}")), "{table}");

    fails(&["run", "--scene", "nope", "--out", p(&out)]);
    fails(&["run", "--dwell-cap", "-1", "--out", p(&out)]);
}

#[test]
fn bench_paper_with_one_seed() {
    let out = ok(&["bench", "paper", "--seeds", "1"]);
    for s in [
        "paper-linear",
        "paper-quadratic",
        "paper-log",
        "frame/adaptive RMAE",
    ] {
        assert!(out.contains(s), "{s} missing");
    }
    fails(&["bench", "paper", "--seeds", "0"]);
}

#[test]
fn receive_counts_crafted_frames_as_corrupt_and_never_allocates_them() {
    // A tile and a frame end claiming a 65535 x 65535 frame: valid COBS,
    // CRC, magic and version, 92 bytes (it once aborted the receiver on an
    // 8.6 GB allocation). The receiver's unit tests build the same bytes.
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/frame_65535x65535.bin");
    assert_eq!(std::fs::metadata(&file).expect("fixture").len(), 92);
    let out = ok(&["receive", "--file", p(&file)]);
    assert!(
        out.contains("received 0 frames")
            && out.contains("lost 1 frames")
            && out.contains("corrupted 2"),
        "{out}"
    );
    // The limit is the caller's; a bad one is one line.
    let out = ok(&["receive", "--file", p(&file), "--max-frame", "1024x1024"]);
    assert!(out.contains("corrupted 2"), "{out}");
    let e = fails(&["receive", "--file", p(&file), "--max-frame", "0x8"]);
    assert!(e.contains("frame limit"), "{e}");
}

#[test]
fn flow_writes_vectors_per_pair_the_mean_field_and_plots() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let sim = simulate_small(tmp.path());
    let out = tmp.path().join("flow");
    let dat = sim.join("spikes.dat");
    let msg = ok(&["flow", p(&dat), "--out", p(&out)]);
    assert!(
        msg.contains("128x96 px") && msg.contains("(ladder)"),
        "{msg}"
    );
    for f in [
        "vectors_00000.csv",
        "mean.csv",
        "mean_field.png",
        "pair_vectors.png",
        "pair_a.png",
        "pair_b.png",
        "summary.json",
        "flow.nc",
        "mean_speed.png",
        "mean_vorticity.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing: {msg}");
    }
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["method"], "ladder");
    // The time ladder: its rungs, the first two uncompensated.
    let rungs = s["pairs"][0]["rungs"].as_array().expect("rungs");
    assert_eq!(rungs[0]["separation"], 4);
    let mean = std::fs::read_to_string(out.join("mean.csv")).unwrap();
    assert!(
        mean.starts_with("x,y,u,v,flag,sigma_u,sigma_v,u_m_s,v_m_s,pairs\n"),
        "{mean}"
    );
    let pair = std::fs::read_to_string(out.join("vectors_00000.csv")).unwrap();
    assert!(
        pair.starts_with("x,y,u,v,flag,sigma_u,sigma_v,u_m_s,v_m_s\n"),
        "{pair}"
    );
    // The calibration from scene.json, in summary.json.
    assert_eq!(s["calibration"]["pixel_mm"], 0.02);
    let msg = ok(&["flow", p(&dat), "--out", p(&out), "--method", "adaptive"]);
    assert!(msg.contains("dwell cap 8 px"), "{msg}");
    // TFP, another schedule, with the movie: one frame per pair, the map
    // at twice the frame's size under its caption, looping.
    ok(&[
        "flow",
        p(&dat),
        "--out",
        p(&out),
        "--method",
        "tfp",
        "--every",
        "20",
        "--movie",
    ]);
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let pairs = s["pairs"].as_array().expect("pairs").len();
    assert!(pairs > 2, "{pairs}");
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    let mut gif = opts
        .read_info(std::fs::File::open(out.join("flow.gif")).unwrap())
        .unwrap();
    let size = spiv_host::report::plot::node_map_size((128, 96));
    assert_eq!((u32::from(gif.width()), u32::from(gif.height())), size);
    let mut frames = Vec::new();
    while let Some(f) = gif.read_next_frame().unwrap() {
        assert_eq!(f.delay, 10);
        frames.push(f.buffer.to_vec());
    }
    assert_eq!(frames.len(), pairs);
    // The pairs differ, so the frames do (their captions at least).
    assert!(frames.windows(2).all(|w| w[0] != w[1]));
}

/// `spiv flow`'s inputs checked against what they claim, and its bad
/// values: each named on one line.
#[test]
fn flow_refuses_bad_inputs_with_one_line() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let sim = simulate_small(tmp.path());
    let out = tmp.path().join("flow");
    let dat = sim.join("spikes.dat");
    // Without scene.json the pair separation must be given; bad values fail.
    let lone = tmp.path().join("lone.dat");
    std::fs::copy(&dat, &lone).unwrap();
    let e = fails(&["flow", p(&lone), "--width", "128", "--height", "96"]);
    assert!(e.contains("--dt"), "{e}");
    let e = fails(&["flow", p(&dat), "--dt", "100000"]);
    assert!(e.contains("--dt 100000"), "{e}");
    let e = fails(&["flow", p(&dat), "--start", "100000", "--out", p(&out)]);
    assert!(e.contains("no pair fits"), "{e}");
    let e = fails(&["flow", p(&dat), "--window", "0", "--out", p(&out)]);
    assert!(e.contains("window 0"), "{e}");
    let e = fails(&["flow", p(&dat), "--pixel-size", "0", "--out", p(&out)]);
    assert!(e.contains("pixel size 0"), "{e}");
    let e = fails(&["flow", p(&dat), "--tick-hz", "NaN", "--out", p(&out)]);
    assert!(e.contains("tick rate NaN"), "{e}");
    // Inputs checked against what they claim, each named on one line.
    let e = fails(&["flow", p(&tmp.path().join("missing.dat"))]);
    assert!(
        e.contains("missing.dat") && e.contains("No such file"),
        "{e}"
    );
    for name in ["notes.txt", "frame.png"] {
        let f = tmp.path().join(name);
        std::fs::write(&f, b"not spikes").unwrap();
        let e = fails(&["flow", p(&f), "--width", "128", "--height", "96"]);
        assert!(
            e.contains(name) && e.contains("not a spike recording"),
            "{e}"
        );
    }
    let png = tmp.path().join("frame.dat");
    std::fs::write(&png, b"\x89PNG\r\n\x1a\nmore").unwrap();
    let e = fails(&["flow", p(&png), "--width", "128", "--height", "96"]);
    assert!(e.contains("not a spike recording"), "{e}");
    let e = fails(&["flow", p(&dat), "--width", "64", "--height", "192"]);
    assert!(e.contains("64x192 px given") && e.contains("128x96"), "{e}");
    let e = fails(&[
        "flow",
        p(&lone),
        "--width",
        "128",
        "--height",
        "96",
        "--dt",
        "13",
        "--pixel-size",
        "0.02",
        "--out",
        p(&out),
    ]);
    assert!(
        e.contains("half a calibration: the tick rate (Hz) is missing"),
        "{e}"
    );
    let e = fails(&["flow"]);
    assert!(e.contains("<INPUT>"), "{e}");
    let e = fails(&["piv", p(&dat), p(&dat)]);
    assert!(e.contains("--out <OUT>"), "{e}");
}

/// Ctrl-C (SIGINT) stops `spiv flow` between pairs: exit status 130, one
/// line saying how many pairs were measured, and those pairs written.
#[test]
fn ctrl_c_stops_flow_and_keeps_the_pairs_done() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let sim = tmp.path().join("long");
    ok(&[
        "simulate",
        "--scene",
        "uniform",
        "--out",
        p(&sim),
        "--width",
        "128",
        "--height",
        "96",
        "--ticks",
        "8000",
        "--seed",
        "4",
    ]);
    let out = tmp.path().join("flow");
    let dat = sim.join("spikes.dat");
    let child = Command::new(env!("CARGO_BIN_EXE_spiv"))
        .args(["flow", p(&dat), "--out", p(&out)])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn spiv");
    // Past opening the recording (the handler is set before the first pair).
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(kill.success());
    let o = child.wait_with_output().expect("wait");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(!err.contains("panicked"), "{err}");
    if err.contains("nothing written") {
        assert!(
            err.starts_with("spiv: interrupted before the first of"),
            "{err}"
        );
        return;
    }
    // "spiv: interrupted: N of M pairs measured, written to DIR"
    let words: Vec<&str> = err.split_whitespace().collect();
    assert_eq!(&words[..2], ["spiv:", "interrupted:"], "{err}");
    let (n, m): (usize, usize) = (words[2].parse().unwrap(), words[4].parse().unwrap());
    assert!(n >= 1 && n < m, "{err}");
    let csvs = std::fs::read_dir(&out)
        .unwrap()
        .filter(|e| {
            let name = e.as_ref().unwrap().file_name();
            name.to_string_lossy().starts_with("vectors_")
        })
        .count();
    assert_eq!(csvs, n, "{err}");
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["pairs"].as_array().expect("pairs").len(), n);
}

/// A recording with more particles than the core's region table holds
/// (456 blobs of 2×2 px in 128×96 px, a table of 192): `spiv flow
/// --method adaptive` says so on stderr and in `summary.json`, with and
/// without the dwell cap.
#[test]
fn full_label_tables_are_reported() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let (w, h, planes) = (128usize, 96usize, 300usize);
    let mut data = Vec::with_capacity(planes * w * h / 8);
    for t in 0..planes {
        let mut plane = vec![0u8; w * h / 8];
        if t % 2 == 0 {
            for y in (1..h - 2).step_by(6) {
                for x in (1..w - 2).step_by(6) {
                    for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                        // Stored bottom-up, bits least significant first.
                        let p = (h - 1 - (y + dy)) * w + x + dx;
                        plane[p / 8] |= 1 << (p % 8);
                    }
                }
            }
        }
        data.extend(plane);
    }
    let dat = tmp.path().join("blobs.dat");
    std::fs::write(&dat, data).unwrap();
    for cap in ["8", "off"] {
        let out = tmp.path().join(format!("out-{cap}"));
        let o = spiv(&[
            "flow",
            p(&dat),
            "--width",
            "128",
            "--height",
            "96",
            "--dt",
            "13",
            "--method",
            "adaptive",
            "--dwell-cap",
            cap,
            "--out",
            p(&out),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(
            err.contains("warning: the core's tables were full"),
            "{cap}: {err}"
        );
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        let lost: u64 = s["pairs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["lost_to_full_tables"]["regions"].as_u64().unwrap())
            .sum();
        assert!(lost > 0, "{cap}: {s}");
    }
}

/// docs/cli.md names every option each subcommand's `--help` lists, in
/// that subcommand's row, so the page cannot fall behind the code.
#[test]
fn docs_cli_names_every_option() {
    let page = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/cli.md"))
        .expect("docs/cli.md");
    let options = |args: &[&str]| -> Vec<String> {
        let help = ok(&[args, &["--help"]].concat());
        let mut found: Vec<String> = help
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
            .filter(|w| w.starts_with("--") && w.len() > 2 && w != &"--help" && w != &"--version")
            .map(str::to_string)
            .collect();
        found.sort();
        found.dedup();
        found
    };
    let row = |start: &str| -> &str {
        page.lines()
            .find(|l| l.starts_with(start))
            .unwrap_or_else(|| panic!("docs/cli.md has no row starting {start}"))
    };
    for cmd in ["run", "simulate", "flow", "reconstruct", "piv", "receive"] {
        let line = row(&format!("| `spiv {cmd}"));
        for o in options(&[cmd]) {
            assert!(line.contains(&o), "docs/cli.md: spiv {cmd} lacks {o}");
        }
    }
    let bench = row("| `spiv bench");
    for sub in [
        "paper",
        "blasius",
        "link",
        "speed",
        "turbulence",
        "flows",
        "live",
    ] {
        for o in options(&["bench", sub]) {
            let at = bench
                .find(&format!("`spiv bench {sub}"))
                .unwrap_or_else(|| panic!("docs/cli.md: no spiv bench {sub}"));
            let own = &bench[at..];
            let own = &own[..own[1..].find("`spiv bench").map_or(own.len(), |e| e + 1)];
            assert!(own.contains(&o), "docs/cli.md: spiv bench {sub} lacks {o}");
        }
    }
}

/// `spiv bench live` on one family and seed: a row per delivery mode, the
/// JSON rows with their bytes against the raw spikes, and one clear line
/// for a pair count out of range.
#[test]
fn bench_live_reports_every_mode() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("live.json");
    let out = ok(&[
        "bench",
        "live",
        "--seeds",
        "1",
        "--families",
        "uniform",
        "--pairs",
        "1",
        "--json",
        p(&json),
    ]);
    for mode in [
        "spiv flow",
        "1 pair late",
        "3 pairs late",
        "1 late, 10 % lost",
        "1 late, 5 % lost, 5 % corrupted",
    ] {
        assert!(
            out.lines()
                .any(|l| l.starts_with("uniform") && l.contains(mode)),
            "{out}"
        );
    }
    let rows: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(rows.len(), 5);
    for r in &rows {
        let (b, raw) = (
            r["bytes_per_pair"].as_f64().unwrap(),
            r["raw_per_pair"].as_f64().unwrap(),
        );
        assert!(b > 0.0 && b < raw, "{r}");
        // Uniform 0.56 px per pair: measured to a few hundredths.
        assert!(r["other"].as_f64().unwrap() < 0.05, "{r}");
    }
    let err = fails(&["bench", "live", "--pairs", "0"]);
    assert!(err.contains("--pairs 0"), "{err}");
}
