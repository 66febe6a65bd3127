//! Wide frames keep every particle: a compensated frame of the paper's
//! 6400-px canvas overflows the labeller's 32,766 provisional labels when
//! made in one strip, and the sizes the sidecar and the host ship
//! (`spiv_core::state::strip_rows`) cut it into strips that do not.

use spiv_core::buffers::WorkspaceBuf;
use spiv_core::motion::Motion;
use spiv_core::sidecar::Config;
use spiv_core::state::{strip_rows, MAX_STRIP_PIXELS};
use spiv_core::{reconstruct_compensated, History, Method, Params, PlaneView, WorkspaceSizes};
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams};
use spiv_firmware_sim::sensor::{simulate, SensorParams};

#[test]
fn a_wide_compensated_frame_loses_no_particle_pixels_in_the_shipped_strips() {
    let (w, h, ticks) = (6400u16, 250u16, 160u32);
    let mut sp = SceneParams::new(SceneKind::PaperQuadratic);
    sp.width = w;
    let scene = Scene::new(sp, 1, ticks);
    let packed = simulate(&scene, SensorParams::default(), 1, 0, ticks);
    let depth = ticks as u16;
    let mut hb = vec![0u64; History::words_needed(w, h, depth).unwrap()];
    let mut hist = History::new(&mut hb, w, h, 0, h, depth).unwrap();
    let plane = usize::from(w) * usize::from(h) / 8;
    for b in packed.chunks_exact(plane) {
        hist.push(&PlaneView::new(b, w, h).unwrap()).unwrap();
    }
    // The scene's velocity, u = U·(y/H)², U = 1.25 px/tick, stored rows
    // bottom-up (y = r + 0.5), 1/4096 px per tick.
    let vx: Vec<i16> = (0..h)
        .map(|r| {
            (1.25 * ((f64::from(r) + 0.5) / f64::from(h)).powi(2) * f64::from(spiv_core::motion::Q))
                .round() as i16
        })
        .collect();
    let vy = vec![0i16; usize::from(h)];
    let m = Motion::rows(&vx, &vy);
    let p = Params::default();
    let mut out = vec![0u8; usize::from(w) * usize::from(h)];
    let mut frame = |sizes: WorkspaceSizes| {
        let mut buf = WorkspaceBuf::new(sizes);
        let mut ws = buf.workspace().unwrap();
        reconstruct_compensated(&hist, 80, &p, &mut ws, (0, h), &m, &mut out).unwrap()
    };
    // One strip: the table fills and particle pixels become background.
    let whole = frame(WorkspaceSizes::for_motion(w, h));
    assert!(whole.labels.dropped_pixels > 1000, "{:?}", whole.labels);
    // The sidecar's sizes for this sensor, and the host's.
    let mut cfg = Config::new(0, 13);
    cfg.method = Method::Mc;
    let sizes = cfg.memory_sizes(w, h).unwrap().workspace;
    assert_eq!(
        sizes,
        WorkspaceSizes::for_motion(w, strip_rows(w, h, p.margin))
    );
    assert!(sizes.pixels() <= MAX_STRIP_PIXELS && sizes.rows < h);
    let strips = frame(sizes);
    assert!(strips.strips > 1);
    assert_eq!(strips.labels.dropped_pixels, 0, "{:?}", strips.labels);
    assert_eq!(strips.labels.overflow_regions, 0, "{:?}", strips.labels);
    // Every region the one-strip frame kept is still found.
    assert!(strips.labels.regions >= whole.labels.regions);
}

#[test]
fn strips_cover_wide_frames_only() {
    assert_eq!(strip_rows(400, 250, 16), 250);
    assert_eq!(strip_rows(2048, 256, 16), 256);
    assert_eq!(strip_rows(6400, 250, 16), 81);
    assert_eq!(strip_rows(1000, 1000, 16), 524);
    // Never fewer than two margins and 16 inner rows, never more than the band.
    assert_eq!(strip_rows(65535, 1000, 16), 48);
    assert_eq!(strip_rows(65535, 20, 16), 20);
    assert_eq!(strip_rows(0, 10, 16), 10);
}
