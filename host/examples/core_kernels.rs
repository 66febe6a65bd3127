//! Runs the core's kernels on the default scene for instruction counting
//! (`valgrind --tool=callgrind`, see README): ingest of 160 planes of
//! 400×250 px, then one adaptive frame at n_max = 128 — or, with `mc`,
//! one motion-compensated frame (refine on, the scene's true velocity
//! predicted; `mc_once`).
//!
//! `cargo run --release -p spiv-host --example core_kernels [frames] [mc]`

use spiv_core::buffers::WorkspaceBuf;
use spiv_core::motion::{refine, Motion, Refine};
use spiv_core::region::Region;
use spiv_core::state::Buffers;
use spiv_core::{
    reconstruct_adaptive, reconstruct_compensated, History, Params, PlaneView, Workspace,
    WorkspaceSizes,
};
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::{simulate, SensorParams};

const W: u16 = 400;
const H: u16 = 250;

#[inline(never)]
fn ingest_all(hist: &mut History<'_>, packed: &[u8]) -> u32 {
    let plane = usize::from(W) * usize::from(H) / 8;
    let mut last = 0;
    for bytes in packed.chunks_exact(plane) {
        if let Ok(view) = PlaneView::new(bytes, W, H) {
            last = hist.push(&view).unwrap_or(last);
        }
    }
    last
}

#[inline(never)]
fn frame_once(
    hist: &History<'_>,
    k: u32,
    ws: &mut Workspace<'_>,
    out: &mut [u8],
) -> spiv_core::FrameStats {
    reconstruct_adaptive(hist, k, &Params::default(), ws, out).unwrap()
}

#[inline(never)]
fn mc_once(hist: &History<'_>, k: u32, ws: &mut Workspace<'_>, out: &mut [u8]) -> u32 {
    // u = U·y/H, U = 1.25 px/tick, stored rows bottom-up (y = r + 0.5), 1/4096 px per tick.
    let vx: Vec<i16> = (0..H)
        .map(|r| {
            (1.25 * (f64::from(r) + 0.5) / f64::from(H) * f64::from(spiv_core::motion::Q)).round()
                as i16
        })
        .collect();
    let vy = vec![0i16; usize::from(H)];
    let (mut rvx, mut rvy) = (vy.clone(), vy.clone());
    let m = Motion::rows(&vx, &vy);
    refine(hist, k, &m, &Refine::default(), &mut rvx, &mut rvy).unwrap();
    let m = Motion::rows(&rvx, &rvy);
    reconstruct_compensated(hist, k, &Params::default(), ws, (0, H), &m, out)
        .unwrap()
        .regions_out
}

fn main() {
    let mc = std::env::args().any(|a| a == "mc");
    if mc {
        return main_mc();
    }
    let frames: u32 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1);
    let scene = Scene::new(SceneParams::new(SceneKind::PaperLinear), 1, 160);
    let packed = simulate(&scene, SensorParams::default(), 1, 0, 160);
    let mut hb = vec![0u64; History::words_needed(W, H, 160).unwrap()];
    let mut hist = History::new(&mut hb, W, H, 0, H, 160).unwrap();
    let last = ingest_all(&mut hist, &packed);
    let sizes = WorkspaceSizes::for_strip(W, H);
    let n = sizes.pixels();
    let (mut a, mut b, mut c) = (vec![0u64; sizes.count_words()], vec![0u8; n], vec![0u8; n]);
    let mut labels = vec![0u16; n];
    let mut masks = vec![0u64; sizes.mask_words()];
    let mut tiles = vec![0u8; sizes.tiles()];
    let mut parents = vec![0u16; sizes.parents()];
    let mut regions = vec![Region::default(); usize::from(sizes.max_regions)];
    let mut ws = Workspace::new(
        sizes,
        Buffers {
            counts: &mut a,
            c_t: &mut b,
            class: &mut c,
            labels: &mut labels,
            masks: &mut masks,
            tiles: &mut tiles,
            parents: &mut parents,
            regions: &mut regions,
        },
    )
    .unwrap();
    let mut out = vec![0u8; usize::from(W) * usize::from(H)];
    let mut checksum = 0u64;
    for f in 0..frames {
        let stats = frame_once(&hist, 80 - f % 8, &mut ws, &mut out);
        checksum = out.iter().fold(checksum, |h, &g| {
            h.wrapping_mul(31).wrapping_add(u64::from(g))
        });
        checksum ^= u64::from(stats.regions_out);
    }
    println!("planes {} regions-frame checksum {checksum:016x}", last + 1);
}

fn main_mc() {
    let scene = Scene::new(SceneParams::new(SceneKind::PaperLinear), 1, 160);
    let packed = simulate(&scene, SensorParams::default(), 1, 0, 160);
    let mut hb = vec![0u64; History::words_needed(W, H, 160).unwrap()];
    let mut hist = History::new(&mut hb, W, H, 0, H, 160).unwrap();
    ingest_all(&mut hist, &packed);
    let mut buf = WorkspaceBuf::new(WorkspaceSizes::for_motion(W, H));
    let mut ws = buf.workspace().unwrap();
    let mut out = vec![0u8; usize::from(W) * usize::from(H)];
    let regions = mc_once(&hist, 80, &mut ws, &mut out);
    let checksum = out
        .iter()
        .fold(0u64, |h, &g| h.wrapping_mul(31).wrapping_add(u64::from(g)));
    println!("motion-compensated frame: {regions} regions, checksum {checksum:016x}");
}
