//! Speed against error of the sidecar core on the paper's window (400×250 px):
//! ingest throughput (pixel-samples per second), the time of one adaptive
//! frame at n_max = 128, one motion-compensated frame (refine on, true
//! velocity predicted) and refine alone, TFP for comparison, and the same
//! adaptive frame by the f64
//! reference with the error between them. Medians from criterion; run with
//! `cargo bench -p spiv-host --bench core`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use spiv_core::buffers::WorkspaceBuf;
use spiv_core::motion::{refine, Motion, Refine};
use spiv_core::window::tfp;
use spiv_core::{
    reconstruct_adaptive, reconstruct_compensated, History, Params, PlaneView, WorkspaceSizes,
};
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::{simulate, SensorParams};
use spiv_host::reference::{adaptive_frame, SpikeVolume};
use std::hint::black_box;

const W: u16 = 400;
const H: u16 = 250;
const TICKS: u32 = 160;
/// Pixels of a frame.
const PX: usize = W as usize * H as usize;
/// The frames' centre tick.
const K: u32 = 80;

fn stream() -> Vec<u8> {
    let scene = Scene::new(SceneParams::new(SceneKind::PaperLinear), 1, 160);
    simulate(&scene, SensorParams::default(), 1, 0, TICKS)
}

/// Every plane of `packed` pushed into a history over `words`, `depth`
/// planes deep.
fn history<'a>(words: &'a mut [u64], packed: &[u8], depth: u16) -> History<'a> {
    let mut hist = History::new(words, W, H, 0, H, depth).unwrap();
    for bytes in packed.chunks_exact(PX / 8) {
        hist.push(&PlaneView::new(bytes, W, H).unwrap()).unwrap();
    }
    hist
}

fn bench_ingest(c: &mut Criterion) {
    let packed = stream();
    let mut g = c.benchmark_group("ingest");
    g.throughput(Throughput::Elements(PX as u64 * u64::from(TICKS)));
    g.bench_function("400x250 x160 planes", |b| {
        let mut hb = vec![0u64; History::words_needed(W, H, 128).unwrap()];
        b.iter(|| black_box(history(&mut hb, &packed, 128).newest()))
    });
    g.finish();
}

fn bench_frames(c: &mut Criterion) {
    let packed = stream();
    let mut hb = vec![0u64; History::words_needed(W, H, TICKS as u16).unwrap()];
    let hist = history(&mut hb, &packed, TICKS as u16);
    let p = Params::default();
    let mut g = c.benchmark_group("frame");
    g.sample_size(30);
    for strip in [H, 64] {
        let mut buf = WorkspaceBuf::new(WorkspaceSizes::for_strip(W, strip));
        let mut ws = buf.workspace().unwrap();
        let mut out = vec![0u8; PX];
        g.bench_with_input(
            BenchmarkId::new("adaptive n_max=128, strip rows", strip),
            &strip,
            |b, _| {
                b.iter(|| black_box(reconstruct_adaptive(&hist, K, &p, &mut ws, &mut out).unwrap()))
            },
        );
    }
    // The motion-compensated frame as the sidecar makes it (refine on),
    // predicted by the scene's true velocity: u = U·y/H, U = 1.25 px/tick,
    // stored rows bottom-up (y = r + 0.5), 1/4096 px per tick.
    let vx: Vec<i16> = (0..H)
        .map(|r| {
            (1.25 * (f64::from(r) + 0.5) / f64::from(H) * f64::from(spiv_core::motion::Q)).round()
                as i16
        })
        .collect();
    let vy = vec![0i16; usize::from(H)];
    let (mut rvx, mut rvy) = (vy.clone(), vy.clone());
    let mut mws = WorkspaceBuf::new(WorkspaceSizes::for_motion(W, H));
    let mut out = vec![0u8; PX];
    g.bench_function("motion-compensated n_max=128, refine on", |b| {
        b.iter(|| {
            let m = Motion::rows(&vx, &vy);
            refine(&hist, K, &m, &Refine::default(), &mut rvx, &mut rvy).unwrap();
            let m = Motion::rows(&rvx, &rvy);
            let mut ws = mws.workspace().unwrap();
            black_box(reconstruct_compensated(&hist, K, &p, &mut ws, (0, H), &m, &mut out).unwrap())
        })
    });
    g.bench_function("refine alone", |b| {
        b.iter(|| {
            let m = Motion::rows(&vx, &vy);
            refine(&hist, K, &m, &Refine::default(), &mut rvx, &mut rvy).unwrap();
            black_box(rvx[0])
        })
    });
    let mut counts = vec![0u8; PX];
    g.bench_function("tfp n=8", |b| {
        b.iter(|| black_box(tfp(&hist, K, 8, 255, &mut counts, &mut out).unwrap()))
    });
    let vol = SpikeVolume::from_packed(&packed, usize::from(W), usize::from(H), 0);
    g.sample_size(10);
    g.bench_function("f64 reference adaptive", |b| {
        b.iter(|| black_box(adaptive_frame(&vol, K, &p, 255.0)))
    });
    g.finish();
    print_error(&hist, &vol, &p);
}

/// The error of the fixed-point core's adaptive frame against the f64
/// reference, printed beside the times.
fn print_error(hist: &History<'_>, vol: &SpikeVolume, p: &Params) {
    let mut buf = WorkspaceBuf::new(WorkspaceSizes::for_strip(W, H));
    let mut ws = buf.workspace().unwrap();
    let mut out = vec![0u8; PX];
    let stats = reconstruct_adaptive(hist, K, p, &mut ws, &mut out).unwrap();
    let r = adaptive_frame(vol, K, p, 255.0);
    let diffs: Vec<f64> = out
        .iter()
        .zip(&r.gray)
        .map(|(&a, &b)| (f64::from(a) - b).abs())
        .collect();
    let max = diffs.iter().cloned().fold(0.0, f64::max);
    let rms = (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len() as f64).sqrt();
    println!(
        "error of the core against the f64 reference: max {max:.3} gray, rms {rms:.3} gray; regions {}, mean n* {:.1} ticks",
        stats.regions_out,
        stats.n_star_sum as f64 / f64::from(stats.regions_out.max(1))
    );
}

criterion_group!(benches, bench_ingest, bench_frames);
criterion_main!(benches);
