//! Speed against error of the PIV engine: vectors per second for a 400×250
//! and a 1024×1024 frame-camera pair with 3 passes (64→32→32, 50 %
//! overlap), each row with its RMS error against the truth. Medians from
//! criterion; run with `cargo bench -p spiv-host --bench piv`. The side-by-
//! side comparison with OpenPIV is `bench/openpiv_compare.sh`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ndarray::Array2;
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::{FrameCamera, FrameCameraParams};
use spiv_host::piv::{piv, Interp, Settings};
use std::hint::black_box;

/// The allocator of the `spiv` binary, so that the numbers are the CLI's.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

struct Case {
    name: &'static str,
    a: Array2<f32>,
    b: Array2<f32>,
    scene: Scene,
    dt: u32,
}

fn case(name: &'static str, w: u16, h: u16) -> Case {
    let p = SceneParams {
        width: w,
        height: h,
        shift: (2.6, 1.4),
        ..SceneParams::new(SceneKind::Uniform)
    };
    let dt = p.pair_dt;
    let scene = Scene::new(p, 5, 64 + dt + 1);
    let cam = FrameCamera {
        params: FrameCameraParams::default(),
    };
    let (wu, hu) = (usize::from(w), usize::from(h));
    let to = |v: Vec<u16>| Array2::from_shape_fn((hu, wu), |(i, j)| f32::from(v[i * wu + j]));
    Case {
        name,
        a: to(cam.capture(&scene, 64, 1)),
        b: to(cam.capture(&scene, 64 + dt, 2)),
        scene,
        dt,
    }
}

fn rms(c: &Case, s: &Settings) -> f64 {
    let f = piv(&c.a, &c.b, None, s).expect("piv");
    let vs = f.vectors();
    let pts: Vec<(f64, f64)> = vs.iter().map(|v| (v.x, v.y)).collect();
    let truth = c.scene.truth(&pts, f64::from(c.dt));
    let e: Vec<f64> = vs
        .iter()
        .zip(&truth)
        .filter(|(v, _)| v.state.is_measured())
        .map(|(v, t)| (v.u - t.2).powi(2) + (v.v - t.3).powi(2))
        .collect();
    (e.iter().sum::<f64>() / e.len().max(1) as f64).sqrt()
}

fn bench(c: &mut Criterion) {
    let cases = [case("400x250", 400, 250), case("1024x1024", 1024, 1024)];
    let configs = [
        ("64,32,32 bspline", Settings::default()),
        (
            "64,32,32 bilinear",
            Settings {
                interp: Interp::Bilinear,
                ..Settings::default()
            },
        ),
        (
            "64,32 bspline",
            Settings {
                windows: vec![64, 32],
                ..Settings::default()
            },
        ),
    ];
    let mut g = c.benchmark_group("piv");
    g.sample_size(20);
    for cs in &cases {
        for (name, s) in &configs {
            let f = piv(&cs.a, &cs.b, None, s).expect("piv");
            eprintln!(
                "piv {} {name}: {} vectors, rms error {:.4} px",
                cs.name,
                f.grid.len(),
                rms(cs, s)
            );
            g.throughput(Throughput::Elements(f.grid.len() as u64));
            g.bench_function(format!("{} {name}", cs.name), |b| {
                b.iter(|| black_box(piv(&cs.a, &cs.b, None, s).expect("piv")))
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
