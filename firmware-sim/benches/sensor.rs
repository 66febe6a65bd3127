//! Pixel-ticks per second of the simulated camera on the default scene
//! (400×250, paper-linear): scene rendering plus the spike sensor, rows in
//! parallel. `cargo bench -p spiv-firmware-sim --bench sensor`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::{SensorParams, SpikeSensor};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let p = SceneParams::new(SceneKind::PaperLinear);
    let scene = Scene::new(p.clone(), 1, 141);
    let (w, h) = (p.width, p.height);
    let mut sensor = SpikeSensor::new(SensorParams::default(), w, h, 1);
    let mut light = vec![0f32; usize::from(w) * usize::from(h)];
    let mut plane = vec![0u8; usize::from(w) * usize::from(h) / 8];
    scene.render(7.5, &mut light);
    let mut g = c.benchmark_group("camera");
    g.throughput(Throughput::Elements(u64::from(w) * u64::from(h)));
    let mut t = 0.0;
    g.bench_function("render + spike tick 400x250", |b| {
        b.iter(|| {
            t += 1.0;
            scene.render(t, &mut light);
            black_box(sensor.tick(&light, true, &mut plane))
        })
    });
    g.bench_function("spike tick only 400x250", |b| {
        b.iter(|| black_box(sensor.tick(&light, true, &mut plane)))
    });
    g.bench_function("render only 400x250", |b| {
        b.iter(|| scene.render(black_box(7.5), &mut light))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
