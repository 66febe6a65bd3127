//! `spiv flow` on recordings as a user has them — a simulated `.dat` with
//! `scene.json` beside it, a short 62-plane 256×256 recording, a 416-wide
//! capture with junk columns, the committed real `.npz` capture — held to
//! the simulator's ground truth where there is one.
//!
//! Bounds: the mean field's row-profile RMAE outside the glare rows (the
//! paper's metric, SPEC 7), about 2× what each method measured on
//! paper-linear seed 1, 600 planes (motion-compensated, the default, 0.008
//! — 0.0035 since compensated counts have their own noise model; TFP n = 8
//! 0.027; dwell-capped adaptive 0.029) and on the short recording (mc
//! 0.018, now 0.013); the paper's algorithm with one n_max = 128 must be
//! far worse on the same recording (it streaks: ~1.0), and compensation must
//! beat both baselines, so switching it off fails the test.

use std::path::Path;

use spiv_firmware_sim::scene::{SceneKind, SceneParams};
use spiv_firmware_sim::simulation::{simulate_to_dir, Request};
use spiv_formats::dat::DatOptions;
use spiv_formats::vectors::read_vectors;
use spiv_formats::{State, Vector};
use spiv_host::flow::{run_flow, FlowOptions, Recording};
use spiv_host::metrics::{region_error, row_profile};
use spiv_host::reconstruct::FileOptions;

/// Simulates `scene` (`size`, `ticks`, `dt`) into `dir`.
fn simulate(dir: &Path, size: Option<(u16, u16)>, ticks: u32, dt: Option<u32>) {
    simulate_seed(dir, size, ticks, dt, 1);
}

/// [`simulate`] with particles and noise from `seed`.
fn simulate_seed(dir: &Path, size: Option<(u16, u16)>, ticks: u32, dt: Option<u32>, seed: u64) {
    let mut p = SceneParams::new(SceneKind::PaperLinear);
    if let Some((w, h)) = size {
        (p.width, p.height) = (w, h);
    }
    if let Some(dt) = dt {
        p.pair_dt = dt;
    }
    let mut req = Request::new(p, seed);
    req.ticks = Some(ticks);
    simulate_to_dir(&req, dir, |_, _| {}).expect("simulates");
}

/// Other-row (y ≥ 50 px from the wall) and glare-row RMAE of a field
/// against the truth written beside the recording.
fn rmae(dir: &Path, field: &[Vector], height: u16) -> (f64, f64) {
    let truth = read_vectors(&dir.join("truth.csv")).expect("truth.csv");
    let rows = row_profile(field, &truth, f64::from(height));
    (
        region_error(&rows, |y| y >= 50.0).rmae,
        region_error(&rows, |y| y < 50.0).rmae,
    )
}

fn open(dat: &Path) -> Recording {
    let o = FileOptions {
        width: None,
        height: None,
        dat: DatOptions::default(),
    };
    Recording::open(dat, &o).expect("opens with scene.json beside it")
}

#[test]
fn motion_compensation_measures_the_flow_best_and_one_n_max_does_not() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), None, 600, None);
    let dat = dir.path().join("spikes.dat");
    let mut rec = open(&dat);
    let dt = rec.meta_dt.expect("scene.json names the pair");
    let o = FlowOptions::new(&rec, dt);
    assert_eq!(o.method, spiv_core::Method::Mc, "the default");
    assert_eq!(o.pair_ticks().len(), 11, "{:?}", o.pair_ticks());
    let mut seen = 0;
    let out = run_flow(&mut rec, &o, |i, n| {
        assert!(i <= n);
        seen = i;
    })
    .unwrap();
    assert_eq!((seen, out.pairs.len()), (11, 11));
    assert!(out.pairs.iter().all(|p| p.method == spiv_core::Method::Mc));
    let (mc, _) = rmae(dir.path(), &out.mean_field(), rec.height);
    assert!(mc < 0.008, "motion-compensated: other-row RMAE {mc:.4}");
    let (_, _, invalid) = out.pairs[3].counts();
    assert!(
        invalid * 10 < out.pairs[3].vectors.len(),
        "{invalid} invalid"
    );

    // The dwell-capped loop: time-resolved, bootstrapped once from TFP.
    let capped = FlowOptions {
        method: spiv_core::Method::Adaptive,
        ..o.clone()
    };
    let out = run_flow(&mut rec, &capped, |_, _| {}).unwrap();
    assert!(out.pairs[0].bootstrapped && !out.pairs[0].caps.is_empty());
    assert!(out.pairs.iter().skip(1).any(|p| !p.bootstrapped));
    let (cap, _) = rmae(dir.path(), &out.mean_field(), rec.height);
    assert!(cap < 0.07, "dwell cap: {cap:.3}");

    // The paper's algorithm, one n_max = 128: fast particles streak.
    let paper = FlowOptions {
        dwell_cap: None,
        ..capped
    };
    let out = run_flow(&mut rec, &paper, |_, _| {}).unwrap();
    let (one, _) = rmae(dir.path(), &out.mean_field(), rec.height);
    assert!(
        one > 5.0 * cap,
        "one n_max = 128: {one:.3} against {cap:.3}"
    );

    let tfp = FlowOptions {
        method: spiv_core::Method::Tfp,
        window: 8,
        ..o
    };
    let out = run_flow(&mut rec, &tfp, |_, _| {}).unwrap();
    let (t, _) = rmae(dir.path(), &out.mean_field(), rec.height);
    assert!(t < 0.06, "TFP: {t:.3}");
    eprintln!("other-row RMAE: mc {mc:.4}, TFP {t:.4}, dwell cap {cap:.4}, one n_max {one:.4}");
    // The point of compensation: it beats both baselines outside the glare.
    assert!(
        mc < 0.6 * t && mc < 0.6 * cap,
        "mc {mc:.3}, TFP {t:.3}, cap {cap:.3}"
    );
}

#[test]
fn a_short_recording_gets_one_central_pair() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), Some((256, 256)), 62, Some(21));
    let mut rec = open(&dir.path().join("spikes.dat"));
    assert_eq!((rec.planes, rec.meta_dt), (62, Some(21)));
    let o = FlowOptions::new(&rec, 21);
    assert_eq!(o.pair_ticks(), [20]);
    let out = run_flow(&mut rec, &o, |_, _| {}).unwrap();
    let (other, _) = rmae(dir.path(), &out.mean_field(), rec.height);
    eprintln!("short recording: other-row RMAE {other:.4}");
    assert!(other < 0.026, "short recording: other-row RMAE {other:.4}");
    // A pair that cannot fit is a clear error, not a panic.
    let late = FlowOptions { start: 50, ..o };
    assert!(run_flow(&mut rec, &late, |_, _| {}).is_err());
}

#[test]
fn junk_columns_are_stripped_and_change_nothing() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), None, 200, None);
    let dat = dir.path().join("spikes.dat");
    // The same planes 416 wide: 16 always-firing columns at the right.
    let bytes = std::fs::read(&dat).unwrap();
    let wide: Vec<u8> = bytes
        .chunks_exact(50)
        .flat_map(|row| row.iter().copied().chain([0xff, 0xff]))
        .collect();
    let wide_dat = dir.path().join("wide/spikes.dat");
    std::fs::create_dir_all(wide_dat.parent().unwrap()).unwrap();
    std::fs::write(&wide_dat, wide).unwrap();
    let mut narrow = open(&dat);
    let dt = narrow.meta_dt.unwrap();
    let mut opts = FileOptions {
        width: Some(416),
        height: Some(250),
        dat: DatOptions {
            strip_head: 16,
            ..DatOptions::default()
        },
    };
    let mut stripped = Recording::open(&wide_dat, &opts).unwrap();
    assert_eq!((stripped.width, stripped.planes), (400, narrow.planes));
    let o = FlowOptions::new(&narrow, dt);
    let a = run_flow(&mut narrow, &o, |_, _| {}).unwrap();
    let b = run_flow(&mut stripped, &o, |_, _| {}).unwrap();
    assert!(!a.pairs.is_empty());
    for (x, y) in a.pairs.iter().zip(&b.pairs) {
        assert_eq!(x.vectors, y.vectors);
    }
    // Unstripped, the junk columns are seen (and the field differs).
    opts.dat.strip_head = 0;
    let mut raw = Recording::open(&wide_dat, &opts).unwrap();
    assert_eq!(raw.width, 416);
    let c = run_flow(&mut raw, &o, |_, _| {}).unwrap();
    assert_ne!(c.pairs[0].vectors.len(), a.pairs[0].vectors.len());
}

#[test]
fn the_real_capture_runs_end_to_end() {
    let npz = spiv_formats::reference_data_dir().join("spike/spikezoo_uhsr_real_250x250_200f.npz");
    let o = FileOptions {
        width: None,
        height: None,
        dat: DatOptions::default(),
    };
    let mut rec = Recording::open(&npz, &o).unwrap();
    assert_eq!((rec.crop_width, rec.height, rec.planes), (250, 250, 200));
    let opts = FlowOptions::new(&rec, 10);
    let out = run_flow(&mut rec, &opts, |_, _| {}).unwrap();
    assert_eq!(out.pairs.len(), 4);
    // No particles: the TFP pair gives PIV nothing to predict from, so the
    // default falls back to the plain adaptive frames.
    assert!(out
        .pairs
        .iter()
        .all(|p| p.method == spiv_core::Method::Adaptive));
    assert_eq!(out.first_frames[0].len(), 250 * 250);
    for p in &out.pairs {
        assert!(p.vectors.iter().all(|v| v.u.is_finite() && v.v.is_finite()));
        assert!(p.vectors.iter().any(|v| v.state == State::Valid));
    }
}

#[test]
fn the_wide_baseline_measures_the_recording_better_where_it_fits() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), None, 600, None);
    let mut rec = open(&dir.path().join("spikes.dat"));
    let dt = rec.meta_dt.expect("scene.json names the pair");
    let o = FlowOptions::new(&rec, dt);
    assert_eq!(o.wide, Some(spiv_host::baseline::SEPARATION), "the default");
    let wide = run_flow(&mut rec, &o, |_, _| {}).unwrap();
    // The first pair (ticks 64/77) has no room for frames 19 ticks earlier
    // with their 64 ticks of history, nor the last two (from tick 584)
    // for frames 33 ticks after their second one with 64 ticks ahead of
    // them in 600 planes; the others have.
    let has: Vec<bool> = wide.pairs.iter().map(|p| p.wide.is_some()).collect();
    assert_eq!(
        has,
        [false, true, true, true, true, true, true, true, true, false, false]
    );
    assert_eq!(wide.pairs[1].wide, Some([97, 149]));
    let pair = FlowOptions {
        wide: None,
        ..o.clone()
    };
    let alone = run_flow(&mut rec, &pair, |_, _| {}).unwrap();
    assert!(alone.pairs.iter().all(|p| p.wide.is_none()));
    // The mean fields, over four recordings (one recording's 11 pairs
    // share their particles, so one seed can go either way: seed 1's
    // glare rows read 0.0054 wide against 0.0034 alone, seed 3's 0.0071
    // against 0.0112).
    let (wo, wg) = rmae(dir.path(), &wide.mean_field(), rec.height);
    let (ao, ag) = rmae(dir.path(), &alone.mean_field(), rec.height);
    let (mut w_sum, mut a_sum) = ((wo, wg), (ao, ag));
    for seed in 2..=4u64 {
        let d = tempfile::tempdir().unwrap();
        simulate_seed(d.path(), None, 600, None, seed);
        let mut r = open(&d.path().join("spikes.dat"));
        let w = run_flow(&mut r, &o, |_, _| {}).unwrap().mean_field();
        let a = run_flow(&mut r, &pair, |_, _| {}).unwrap().mean_field();
        let (wo, wg) = rmae(d.path(), &w, r.height);
        let (ao, ag) = rmae(d.path(), &a, r.height);
        eprintln!("seed {seed}: wide {wo:.4} / {wg:.4}, pair alone {ao:.4} / {ag:.4}");
        w_sum = (w_sum.0 + wo, w_sum.1 + wg);
        a_sum = (a_sum.0 + ao, a_sum.1 + ag);
    }
    let ((wo, wg), (ao, ag)) = (
        (w_sum.0 / 4.0, w_sum.1 / 4.0),
        (a_sum.0 / 4.0, a_sum.1 / 4.0),
    );
    eprintln!(
        "mean field, other / glare rows, mean of 4: wide {wo:.4} / {wg:.4}, pair alone {ao:.4} / {ag:.4}"
    );
    assert!(
        wg < 0.85 * ag && wo <= 1.05 * ao,
        "wide {wo:.4} / {wg:.4}, alone {ao:.4} / {ag:.4}"
    );
}
