//! `spiv flow` on recordings as a user has them — a simulated `.dat` with
//! `scene.json` beside it, a short 62-plane 256×256 recording, a 416-wide
//! capture with junk columns, the committed real `.npz` capture — held to
//! the simulator's ground truth where there is one.
//!
//! Bounds: the mean field's row-profile RMAE outside the glare rows (the
//! paper's metric, docs/spec.md §7), about 2× what each method measured on
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
    let rec = open(&dat);
    let dt = rec.meta_dt.expect("scene.json names the pair");
    let o = FlowOptions::new(&rec, dt);
    assert_eq!(o.method, spiv_core::Method::Ladder, "the default");
    // Every pair with the ladder's longest rung (128 ticks) on both sides.
    assert_eq!(
        o.pair_ticks(),
        [121, 173, 225, 277, 329, 381, 433],
        "{:?}",
        o.pair_ticks()
    );
    let mut seen = 0;
    let out = run_flow(&rec, &o, |i, n| {
        assert!(i <= n);
        seen = i;
    })
    .unwrap();
    assert_eq!((seen, out.pairs.len()), (7, 7));
    assert!(out
        .pairs
        .iter()
        .all(|p| p.method == spiv_core::Method::Ladder));
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
    let out = run_flow(&rec, &capped, |_, _| {}).unwrap();
    assert!(out.pairs[0].bootstrapped && !out.pairs[0].caps.is_empty());
    assert!(out.pairs.iter().skip(1).any(|p| !p.bootstrapped));
    let (cap, _) = rmae(dir.path(), &out.mean_field(), rec.height);
    assert!(cap < 0.07, "dwell cap: {cap:.3}");

    // The paper's algorithm, one n_max = 128: fast particles streak.
    let paper = FlowOptions {
        dwell_cap: None,
        ..capped
    };
    let out = run_flow(&rec, &paper, |_, _| {}).unwrap();
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
    let out = run_flow(&rec, &tfp, |_, _| {}).unwrap();
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
    let rec = open(&dir.path().join("spikes.dat"));
    assert_eq!((rec.planes, rec.meta_dt), (62, Some(21)));
    let o = FlowOptions::new(&rec, 21);
    assert_eq!(o.pair_ticks(), [20]);
    let out = run_flow(&rec, &o, |_, _| {}).unwrap();
    let (other, _) = rmae(dir.path(), &out.mean_field(), rec.height);
    eprintln!("short recording: other-row RMAE {other:.4}");
    assert!(other < 0.026, "short recording: other-row RMAE {other:.4}");
    // A pair that cannot fit is a clear error, not a panic.
    let late = FlowOptions { start: 50, ..o };
    assert!(run_flow(&rec, &late, |_, _| {}).is_err());
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
    let narrow = open(&dat);
    let dt = narrow.meta_dt.unwrap();
    let mut opts = FileOptions {
        width: Some(416),
        height: Some(250),
        dat: DatOptions {
            strip_head: 16,
            ..DatOptions::default()
        },
    };
    let stripped = Recording::open(&wide_dat, &opts).unwrap();
    assert_eq!((stripped.width, stripped.planes), (400, narrow.planes));
    let o = FlowOptions::new(&narrow, dt);
    let a = run_flow(&narrow, &o, |_, _| {}).unwrap();
    let b = run_flow(&stripped, &o, |_, _| {}).unwrap();
    assert!(!a.pairs.is_empty());
    for (x, y) in a.pairs.iter().zip(&b.pairs) {
        assert_eq!(x.vectors, y.vectors);
    }
    // Unstripped, the junk columns are seen (and the field differs).
    opts.dat.strip_head = 0;
    let raw = Recording::open(&wide_dat, &opts).unwrap();
    assert_eq!(raw.width, 416);
    let c = run_flow(&raw, &o, |_, _| {}).unwrap();
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
    let rec = Recording::open(&npz, &o).unwrap();
    assert_eq!((rec.crop_width, rec.height, rec.planes), (250, 250, 200));
    let opts = FlowOptions::new(&rec, 10);
    let out = run_flow(&rec, &opts, |_, _| {}).unwrap();
    // 200 planes: one pair at the centre.
    assert_eq!(out.pairs.len(), 1);
    assert_eq!(out.pairs[0].ticks, [95, 105]);
    assert_eq!(out.first_frames[0].len(), 250 * 250);
    // A real scene with no truth to hold it to: every vector finite, and
    // every measured one with a finite uncertainty.
    for p in &out.pairs {
        assert!(p.vectors.iter().all(|v| v.u.is_finite() && v.v.is_finite()));
        for (v, s) in p.vectors.iter().zip(&p.sigma) {
            assert_eq!(v.state.is_measured(), s.0.is_finite() && s.1.is_finite());
        }
    }
    // The plain adaptive frames of the same pairs do correlate somewhere.
    let adaptive = FlowOptions {
        method: spiv_core::Method::Adaptive,
        dwell_cap: None,
        ..opts
    };
    let out = run_flow(&rec, &adaptive, |_, _| {}).unwrap();
    assert!(out
        .pairs
        .iter()
        .all(|p| p.method == spiv_core::Method::Adaptive));
}

/// Pairs near a recording's ends are measured from fewer planes (the
/// ladder's longer rungs do not fit): their vectors are less certain, and
/// their errors stay within what their uncertainty says, so the robust
/// mean weighs nothing they cannot support.
#[test]
fn pairs_at_the_recording_ends_say_they_are_less_certain() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), None, 400, None);
    let rec = open(&dir.path().join("spikes.dat"));
    let dt = rec.meta_dt.expect("scene.json names the pair");
    let mut o = FlowOptions::new(&rec, dt);
    // Every pair from the first tick to the last: the ends are clipped.
    o.start = 0;
    o.last_start = None;
    o.every = 6 * dt;
    let out = run_flow(&rec, &o, |_, _| {}).unwrap();
    let truth = read_vectors(&dir.path().join("truth.csv")).expect("truth.csv");
    let median_sigma = |p: &spiv_host::flow::PairResult| {
        let mut s: Vec<f64> = p
            .sigma
            .iter()
            .zip(&p.vectors)
            .filter(|(_, v)| v.state == State::Valid)
            .map(|(s, _)| s.0.hypot(s.1))
            .collect();
        s.sort_by(f64::total_cmp);
        s.get(s.len() / 2).copied().unwrap_or(f64::INFINITY)
    };
    let first = &out.pairs[0];
    let middle = &out.pairs[out.pairs.len() / 2];
    let (sf, sm) = (median_sigma(first), median_sigma(middle));
    eprintln!("median σ: first pair {sf:.4}, middle pair {sm:.4}");
    assert!(
        sf > 2.0 * sm,
        "the clipped pair must be less certain: {sf} vs {sm}"
    );
    // Its errors are within its uncertainty as often as the middle pair's.
    let within = |p: &spiv_host::flow::PairResult| {
        let (mut n, mut k) = (0, 0);
        for ((v, t), s) in p.vectors.iter().zip(&truth).zip(&p.sigma) {
            if v.state == State::Valid {
                n += 1;
                k += usize::from((v.u - t.u).hypot(v.v - t.v) <= 2.0 * s.0.hypot(s.1));
            }
        }
        k as f64 / n.max(1) as f64
    };
    let (wf, wm) = (within(first), within(middle));
    eprintln!("errors within 2σ: first pair {wf:.2}, middle pair {wm:.2}");
    assert!(wf > 0.7 && wm > 0.7, "{wf} {wm}");
}

/// `spiv flow` on every core gives what it gives on one: its loop of
/// pairs runs in order and each pair's PIV is the same on any number of
/// threads. Split into segments (`FlowOptions::segment`, as `spiv.dask`
/// spreads them over workers), each segment starts from nothing with its
/// own warm-up pairs, and a run of one segment's pairs gives exactly that
/// segment's vectors.
#[test]
fn all_cores_give_the_same_output_as_one() {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), Some((128, 96)), 800, None);
    let rec = open(&dir.path().join("spikes.dat"));
    let o = FlowOptions::new(&rec, rec.meta_dt.unwrap());
    let seg = 4;
    assert!(o.pair_ticks().len() > seg, "{:?}", o.pair_ticks());
    let on = |threads: usize, o: &FlowOptions| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| run_flow(&rec, o, |_, _| {}).unwrap())
    };
    let (one, two) = (on(1, &o), on(2, &o));
    assert_eq!(one.pairs.len(), two.pairs.len());
    for (a, b) in one.pairs.iter().zip(&two.pairs) {
        assert_eq!(a.ticks, b.ticks);
        assert_eq!(a.vectors, b.vectors, "pair at {:?}", a.ticks);
        assert_eq!(a.sigma, b.sigma);
    }
    assert_eq!(one.mean().vectors, two.mean().vectors);
    // Segments: on any number of threads the same; runs of whole
    // segments give exactly their pairs; their robust mean is the mean.
    let segmented = FlowOptions {
        segment: Some(seg),
        ..o.clone()
    };
    let whole = on(2, &segmented);
    assert_eq!(whole.pairs.len(), one.pairs.len());
    let n = whole.pairs.len();
    let mut joined = Vec::new();
    for a in (0..n).step_by(seg) {
        let part = FlowOptions {
            pairs: Some(a..(a + seg).min(n)),
            ..segmented.clone()
        };
        joined.extend(on(1, &part).pairs);
    }
    assert_eq!(joined.len(), n);
    for (a, b) in whole.pairs.iter().zip(&joined) {
        assert_eq!(
            (a.ticks, &a.vectors, &a.sigma),
            (b.ticks, &b.vectors, &b.sigma)
        );
    }
    let fields: Vec<_> = joined
        .iter()
        .map(|p| (p.vectors.as_slice(), p.sigma.as_slice()))
        .collect();
    let mean = spiv_host::flow::MeanField::of(&fields);
    assert_eq!(mean.vectors, whole.mean().vectors);
    assert_eq!(mean.pairs, whole.mean().pairs);
    // A range outside the schedule is refused in one line.
    let past = FlowOptions {
        pairs: Some(n..n + 1),
        ..o.clone()
    };
    let e = run_flow(&rec, &past, |_, _| {}).unwrap_err().to_string();
    assert_eq!(
        e,
        format!("pairs {n}..{}: the schedule has pairs 0..{n}", n + 1)
    );
}
