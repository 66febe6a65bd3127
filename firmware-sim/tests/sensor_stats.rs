//! Statistical tests of the simulated cameras against docs/spec.md §3.

use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::{FrameCamera, FrameCameraParams, Reset, SensorParams, SpikeSensor};

/// Mean spike rate of a `w × h` sensor under constant light `r` over `ticks`.
fn rate(params: SensorParams, r: f32, ticks: u32, seed: u64) -> (f64, u64) {
    let (w, h) = (64u16, 64u16);
    let mut s = SpikeSensor::new(params, w, h, seed);
    let light = vec![r; 64 * 64];
    let mut plane = vec![0u8; 64 * 64 / 8];
    let mut spikes = 0;
    for _ in 0..ticks {
        spikes += s.tick(&light, true, &mut plane);
    }
    let n = 64 * 64 * u64::from(ticks);
    (spikes as f64 / n as f64, n)
}

#[test]
fn subtract_reset_fires_at_the_light_rate_within_a_binomial_interval() {
    // Subtract keeps the excess, so the long-run rate is (r + dark) exactly.
    let p = SensorParams {
        reset: Reset::Subtract,
        sigma_fpn: 0.0,
        ..SensorParams::default()
    };
    for r in [0.02f32, 0.1, 0.3, 0.7] {
        let (got, n) = rate(p, r, 1500, 3);
        let want = f64::from(r) + p.dark;
        // 4.5 binomial standard errors, plus the start-up phase of one spike per pixel.
        let tol = 4.5 * (want * (1.0 - want) / n as f64).sqrt() + 1.0 / 1500.0;
        assert!(
            (got - want).abs() < tol,
            "r={r}: rate {got}, want {want} ± {tol}"
        );
    }
}

#[test]
fn zero_reset_loses_the_excess_charge() {
    // Reset to zero: a pixel needs ceil(phi / electrons per tick) ticks.
    let p = SensorParams {
        sigma_fpn: 0.0,
        ..SensorParams::default()
    };
    let (got, _) = rate(p, 0.3 - 0.005, 1000, 4);
    // 300 e-/tick: 4 ticks to 1000 e- (3 with lucky noise): rate in (1/4, 1/3).
    assert!(got > 0.25 && got < 0.27, "{got}");
}

#[test]
fn the_rate_limit_is_one_spike_per_tick() {
    for reset in [Reset::Zero, Reset::Subtract] {
        let p = SensorParams {
            reset,
            ..SensorParams::default()
        };
        let (got, _) = rate(p, 5.0, 50, 5);
        assert_eq!(got, 1.0, "{reset:?}");
    }
    let (dark, _) = rate(SensorParams::default(), 0.0, 3000, 6);
    assert!((dark - 0.005).abs() < 0.0006, "dark rate {dark}");
}

#[test]
fn threshold_fixed_pattern_spread() {
    let p = SensorParams::default();
    let s = SpikeSensor::new(p, 128, 128, 7);
    let v: Vec<f64> = (0..128)
        .flat_map(|i| (0..128).map(move |j| (i, j)))
        .map(|(i, j)| f64::from(s.threshold(i, j).unwrap()) / p.phi0)
        .collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!((mean - 1.0).abs() < 0.002, "{mean}");
    assert!((sd - 0.03).abs() < 0.002, "{sd}");
    assert!(v.iter().all(|&x| x >= 0.5));
}

#[test]
fn spikes_depend_on_the_seed_only_not_on_the_thread_count() {
    let p = SceneParams {
        width: 96,
        height: 64,
        ..SceneParams::new(SceneKind::PaperLinear)
    };
    let scene = Scene::new(p, 9, 30);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            spiv_firmware_sim::sensor::simulate(&scene, SensorParams::default(), 9, 0, 30)
        })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
    assert_ne!(
        one,
        spiv_firmware_sim::sensor::simulate(&scene, SensorParams::default(), 10, 0, 30)
    );
}

#[test]
fn the_frame_camera_clips_the_glare_and_sees_particles_in_the_dark() {
    let p = SceneParams::new(SceneKind::PaperLinear);
    let scene = Scene::new(p.clone(), 2, 100);
    let cam = FrameCamera {
        params: FrameCameraParams::default(),
    };
    let f = cam.capture(&scene, 64, 2);
    let w = usize::from(p.width);
    let max = cam.params.max_dn();
    // The bottom rows (glare 0.65 thr/tick > full scale 0.28) are clipped.
    let bottom = &f[249 * w..250 * w];
    assert!(bottom.iter().all(|&d| d == max));
    // The dark top: background 0.01/0.28 of full scale, particles well above it.
    let top = &f[..40 * w];
    let mut sorted = top.to_vec();
    sorted.sort_unstable();
    let median = f64::from(sorted[sorted.len() / 2]) / f64::from(max);
    assert!((median - 0.01 / 0.28).abs() < 0.01, "background {median}");
    assert!(sorted[sorted.len() - 1] > max / 2, "particles are imaged");
    let eight = FrameCamera {
        params: FrameCameraParams {
            bits: 8,
            ..FrameCameraParams::default()
        },
    };
    assert!(eight.capture(&scene, 64, 2).iter().all(|&d| d <= 255));
}
