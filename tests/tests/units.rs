//! `spiv flow` in physical units and as one netCDF file: the calibration in
//! `scene.json` beside a recording turns px per pair into m/s, held to the
//! simulator's truth in its own units; `flow.nc` holds every pair's field
//! and the mean as the run measured them.

use std::path::Path;

use spiv_firmware_sim::scene::{SceneKind, SceneParams, PIXEL_MM, TICK_HZ};
use spiv_firmware_sim::simulation::{simulate_to_dir, Request};
use spiv_formats::dat::DatOptions;
use spiv_formats::vectors::read_vectors;
use spiv_host::flow::{run_flow, FlowOutcome, FlowRequest, Recording};
use spiv_host::reconstruct::FileOptions;
use spiv_host::report::flow::{write_flow, RunInfo};

/// Simulates paper-linear (400 planes) into `dir`, runs the flow job with
/// `req` and writes its files into `dir/out`.
fn flow(dir: &Path, req: FlowRequest) -> (FlowOutcome, spiv_host::flow::FlowOptions) {
    let mut r = Request::new(SceneParams::new(SceneKind::PaperLinear), 7);
    r.ticks = Some(400);
    simulate_to_dir(&r, dir, |_, _| {}).expect("simulates");
    let dat = dir.join("spikes.dat");
    let fo = FileOptions {
        width: None,
        height: None,
        dat: DatOptions::default(),
    };
    let rec = Recording::open(&dat, &fo).expect("opens");
    let o = req.options(&rec, &dat).expect("options");
    let out = run_flow(&rec, &o, |_, _| {}).expect("runs");
    let info = RunInfo {
        input: &dat,
        planes: rec.planes,
        seconds: 0.0,
        command: "spiv flow spikes.dat",
    };
    std::fs::create_dir_all(dir.join("out")).unwrap();
    write_flow(&dir.join("out"), &out, &o, info).expect("writes");
    (out, o)
}

#[test]
fn velocities_in_m_per_s_meet_the_simulators_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = flow(dir.path(), FlowRequest::default());
    let c = o.calibration.expect("scene.json calibrates the recording");
    assert_eq!((c.pixel_mm, c.tick_hz), (PIXEL_MM, TICK_HZ));
    let mut nc = netcdf3::FileReader::open(dir.path().join("out/flow.nc")).expect("flow.nc");
    let mean_u = nc.read_var_f64("mean_u_m_s").unwrap();
    let mean_v = nc.read_var_f64("mean_v_m_s").unwrap();
    // The truth at the nodes, px per pair, in m/s by the simulator's own
    // constants.
    let truth = read_vectors(&dir.path().join("truth.csv")).unwrap();
    let per_pair = PIXEL_MM * 1e-3 * TICK_HZ / f64::from(o.dt);
    let (mut err, mut sum, mut n) = (0.0, 0.0, 0);
    for ((t, (&u, &v)), m) in truth
        .iter()
        .zip(mean_u.iter().zip(&mean_v))
        .zip(&out.mean().vectors)
    {
        // Outside the glare band (50 px above the wall, bottom rows).
        if t.y > f64::from(out.size.1) - 50.0 || !m.state.is_measured() {
            continue;
        }
        err += (u - t.u * per_pair).abs() + (v - t.v * per_pair).abs();
        sum += t.u.abs() * per_pair;
        n += 1;
    }
    assert!(n > 200, "{n} nodes measured");
    let rel = err / sum;
    eprintln!(
        "m/s error outside the glare: {:.3} % of the speed over {n} nodes",
        100.0 * rel
    );
    assert!(
        rel < 0.01,
        "m/s off the truth by {:.2} % of its speed",
        100.0 * rel
    );
    // The top speed of paper-linear is about 0.47 m/s at these constants.
    let top = mean_u
        .iter()
        .cloned()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    assert!((0.40..0.50).contains(&top), "{top} m/s");
}

#[test]
fn flow_nc_holds_every_pair_and_the_mean_as_measured() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = flow(dir.path(), FlowRequest::default());
    let mut nc = netcdf3::FileReader::open(dir.path().join("out/flow.nc")).expect("flow.nc");
    let (g, p) = (&out.grid, out.pairs.len());
    {
        let ds = nc.data_set();
        assert_eq!(ds.dim_size("t"), Some(p));
        assert_eq!(ds.dim_size("y"), Some(g.ny));
        assert_eq!(ds.dim_size("x"), Some(g.nx));
        // UDUNITS units: pixels are counts; the flag and uncertainty named.
        assert_eq!(
            ds.get_var_attr_as_string("u", "units").as_deref(),
            Some("1")
        );
        assert_eq!(
            ds.get_var_attr_as_string("u_m_s", "units").as_deref(),
            Some("m s-1")
        );
        assert_eq!(
            ds.get_var_attr_as_string("u_m_s", "ancillary_variables")
                .as_deref(),
            Some("flag sigma_u")
        );
        assert_eq!(
            ds.get_var_attr_as_string("x", "units").as_deref(),
            Some("m")
        );
        assert_eq!(
            ds.get_global_attr_as_string("Conventions").as_deref(),
            Some("CF-1.8")
        );
        assert_eq!(
            ds.get_global_attr_f64("dt_ticks"),
            Some(&[f64::from(o.dt)][..])
        );
    }
    let u = nc.read_var_f64("u").unwrap();
    let flag = nc.read_var_i32("flag").unwrap();
    let sigma_u = nc.read_var_f64("sigma_u").unwrap();
    let time = nc.read_var_f64("t").unwrap();
    // Calibrated: node centres in m, and in px beside them.
    let (x, x_px) = (
        nc.read_var_f64("x").unwrap(),
        nc.read_var_f64("x_px").unwrap(),
    );
    for (c, (&m, &px)) in x.iter().zip(&x_px).enumerate() {
        assert_eq!(px, g.centre(0, c).0);
        assert!((m - px * PIXEL_MM * 1e-3).abs() < 1e-15, "{m} {px}");
    }
    let nodes = g.nx * g.ny;
    for (i, pr) in out.pairs.iter().enumerate() {
        let mid = (pr.ticks[0] + pr.ticks[1]) as f64 / 2.0;
        assert!((time[i] - mid / TICK_HZ).abs() < 1e-12, "time {i}");
        for (j, v) in pr.vectors.iter().enumerate() {
            let k = i * nodes + j;
            assert_eq!(flag[k], i32::from(v.state.flag()));
            if v.state.is_measured() {
                assert_eq!(u[k], v.u, "pair {i} node {j}");
            } else {
                assert!(u[k].is_nan());
            }
            let s = pr.sigma[j].0;
            assert!(s.is_finite() && sigma_u[k] == s || !s.is_finite() && sigma_u[k].is_nan());
        }
    }
    let mean = out.mean();
    let mean_u = nc.read_var_f64("mean_u").unwrap();
    let pairs = nc.read_var_i32("mean_pairs").unwrap();
    for (j, v) in mean.vectors.iter().enumerate() {
        if v.state.is_measured() {
            assert_eq!(mean_u[j], v.u);
        }
        assert_eq!(i64::from(pairs[j]), i64::from(mean.pairs[j]));
    }
}

/// The glare band: the paper's 50 px above the wall, nothing in the top
/// half; and the colour maps of the mean field with it marked.
#[test]
fn the_glare_band_and_the_mean_fields_maps() {
    let dir = tempfile::tempdir().unwrap();
    let (out, _) = flow(dir.path(), FlowRequest::default());
    let (w, h) = (usize::from(out.size.0), usize::from(out.size.1));
    let row_glare = |r: usize| out.glare[r * w..(r + 1) * w].iter().filter(|&&g| g).count();
    assert!(row_glare(h - 5) > w * 9 / 10, "{} of {w}", row_glare(h - 5));
    assert!((0..h / 2).all(|r| row_glare(r) == 0));
    let band = (0..h).filter(|&r| row_glare(r) > w / 2).count();
    assert!((35..=65).contains(&band), "glare band {band} rows");
    for png in ["mean_speed.png", "mean_vorticity.png"] {
        let img = image::open(dir.path().join("out").join(png)).expect(png);
        assert_eq!(
            (img.width(), img.height()),
            spiv_host::report::plot::node_map_size((w as u32, h as u32)),
            "{png}"
        );
        // A colour bar right of the map: a column of many colours.
        let rgb = img.to_rgb8();
        let x = 2 * w as u32 + 58 + 20;
        let mut colours: Vec<_> = (40..2 * h as u32).map(|y| *rgb.get_pixel(x, y)).collect();
        colours.dedup();
        assert!(
            colours.len() > 20,
            "{png}: {} colours in the bar",
            colours.len()
        );
    }
}

#[test]
fn without_a_calibration_there_are_no_m_per_s_and_time_is_in_ticks() {
    let dir = tempfile::tempdir().unwrap();
    // The command line's pixel size alone, with scene.json moved away: half
    // a calibration is none.
    let mut r = Request::new(SceneParams::new(SceneKind::PaperLinear), 7);
    r.ticks = Some(300);
    simulate_to_dir(&r, dir.path(), |_, _| {}).unwrap();
    let dat = dir.path().join("spikes.dat");
    std::fs::remove_file(dir.path().join("scene.json")).unwrap();
    let fo = FileOptions {
        width: Some(400),
        height: Some(250),
        dat: DatOptions::default(),
    };
    let rec = Recording::open(&dat, &fo).unwrap();
    // Half a calibration is refused, naming the missing half.
    let half = FlowRequest {
        dt: Some(13),
        pixel_mm: Some(0.02),
        ..FlowRequest::default()
    };
    let e = half.options(&rec, &dat).unwrap_err();
    assert!(
        e.to_string().contains("the tick rate (Hz) is missing"),
        "{e}"
    );
    let req = FlowRequest {
        dt: Some(13),
        ..FlowRequest::default()
    };
    let o = req.options(&rec, &dat).unwrap();
    assert!(o.calibration.is_none());
    let out = run_flow(&rec, &o, |_, _| {}).unwrap();
    let info = RunInfo {
        input: &dat,
        planes: rec.planes,
        seconds: 0.0,
        command: "spiv flow",
    };
    write_flow(dir.path(), &out, &o, info).unwrap();
    let nc = netcdf3::FileReader::open(dir.path().join("flow.nc")).unwrap();
    let ds = nc.data_set();
    assert!(!ds.has_var("u_m_s") && ds.has_var("u"));
    assert_eq!(
        ds.get_var_attr_as_string("t", "units").as_deref(),
        Some("1")
    );
    assert_eq!(
        ds.get_var_attr_as_string("x", "units").as_deref(),
        Some("1")
    );
    assert!(!ds.has_var("x_px"));
    let header = std::fs::read_to_string(dir.path().join("mean.csv")).unwrap();
    assert!(!header.lines().next().unwrap().contains("u_m_s"));
    // A calibration out of range is refused, not written.
    let bad = FlowRequest {
        dt: Some(13),
        pixel_mm: Some(-1.0),
        tick_hz: Some(20_000.0),
        ..FlowRequest::default()
    };
    let e = bad.options(&rec, &dat).unwrap_err();
    assert!(e.to_string().contains("pixel size -1"), "{e}");
}
