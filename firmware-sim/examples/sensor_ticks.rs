//! Runs the spike sensor on the default scene for profiling:
//! `cargo run --release -p spiv-firmware-sim --example sensor_ticks [ticks]`.
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::{SensorParams, SpikeSensor};

fn main() {
    let ticks: u32 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(200);
    let p = SceneParams::new(SceneKind::PaperLinear);
    let scene = Scene::new(p.clone(), 1, ticks);
    let mut sensor = SpikeSensor::new(SensorParams::default(), p.width, p.height, 1);
    let mut light = vec![0f32; usize::from(p.width) * usize::from(p.height)];
    let mut plane = vec![0u8; light.len() / 8];
    let t0 = std::time::Instant::now();
    let mut spikes = 0;
    for t in 0..ticks {
        scene.render(f64::from(t) + 0.5, &mut light);
        spikes += sensor.tick(&light, true, &mut plane);
    }
    let s = t0.elapsed().as_secs_f64();
    println!(
        "{spikes} spikes, {:.3e} pixel-ticks/s",
        light.len() as f64 * f64::from(ticks) / s
    );
}
