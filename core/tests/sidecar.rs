//! The sidecar loop: each method's frames, at the scheduled ticks, equal the
//! core's own functions on the same planes, and the wire says which method
//! made them; bad configurations and planes are refused, never a panic.

//!
//! Needs the `std` feature (owned buffers); `cargo test --workspace` has it.
#![cfg(feature = "std")]

use spiv_core::buffers::{SidecarBuf, WorkspaceBuf};
use spiv_core::sidecar::{Config, ConfigError, Probe, Sidecar, SidecarError};
use spiv_core::window::{tfi, tfp};
use spiv_core::wire::sender::{Link, Slot};
use spiv_core::wire::{Decoder, FrameEnd, Kind, WireError, MAX_ENCODED};
use spiv_core::{reconstruct_adaptive, History, Method, PlaneView};

const W: u16 = 64;
const H: u16 = 32;
const PX: usize = W as usize * H as usize;

/// Planes of a few bright static blobs on a dim, noisy background
/// (deterministic LCG), so adaptive frames segment something.
fn planes(n: usize) -> Vec<Vec<u8>> {
    let mut seed = 12345u64;
    let mut charge = vec![0u32; PX];
    (0..n)
        .map(|_| {
            let mut p = vec![0u8; PX / 8];
            for (i, c) in charge.iter_mut().enumerate() {
                let (x, y) = (i % W as usize, i / W as usize);
                let blob = [(10, 8), (40, 20), (55, 5)]
                    .iter()
                    .any(|&(bx, by)| x.abs_diff(bx) <= 1 && y.abs_diff(by) <= 1);
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
                *c += if blob {
                    60
                } else {
                    8 + ((seed >> 33) % 9) as u32
                };
                if *c >= 100 {
                    *c -= 100;
                    p[i / 8] |= 1 << (i % 8);
                }
            }
            p
        })
        .collect()
}

struct Bytes(Vec<u8>);
impl Link for Bytes {
    type Error = ();
    fn send(&mut self, m: &[u8]) -> Result<(), ()> {
        self.0.extend_from_slice(m);
        Ok(())
    }
}

#[derive(Default)]
struct Kept(Vec<(Slot, Vec<u16>)>);
impl Probe<u16> for Kept {
    fn sent(&mut self, _id: u32, slot: Slot, frame: &[u16]) {
        self.0.push((slot, frame.to_vec()));
    }
}

/// Runs the loop over `planes` with `cfg`; returns the frames as sent and
/// the wire bytes.
/// The velocity the sidecar is given for `Mc` frames: 0.3 px/tick to the
/// right in the top half, 0.1 in the bottom (1/256 px per tick).
fn mc_velocity() -> Vec<i16> {
    (0..H).map(|r| if r < H / 2 { 77 } else { 26 }).collect()
}

fn run(cfg: Config, planes: &[Vec<u8>]) -> (Vec<(Slot, Vec<u16>)>, Vec<u8>) {
    let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
    if cfg.method == Method::Mc {
        buf.motion = (mc_velocity(), vec![0; usize::from(H)]);
    }
    let mut mem = buf.memory(0).unwrap();
    let mut sc = Sidecar::new::<()>(W, H, cfg).unwrap();
    let (mut link, mut kept) = (Bytes(Vec::new()), Kept::default());
    for p in planes {
        if sc.done() {
            break;
        }
        sc.push_plane(&mut mem, p, &mut link, &mut kept).unwrap();
    }
    sc.finish(&mut mem.send, &mut link).unwrap();
    (kept.0, link.0)
}

/// The frame the core's own function makes at `k` from the same planes.
fn direct(method: Method, cfg: &Config, planes: &[Vec<u8>], k: u32) -> Vec<u16> {
    let mut words = vec![0u64; History::words_needed(W, H, 255).unwrap()];
    let mut hist = History::new(&mut words, W, H, 0, H, 255).unwrap();
    for p in &planes[..=(k as usize + usize::from(cfg.window() / 2)).min(planes.len() - 1)] {
        hist.push(&PlaneView::new(p, W, H).unwrap()).unwrap();
    }
    let mut out = vec![0u16; PX];
    let p = &cfg.params;
    match method {
        Method::Tfp => {
            let mut counts = vec![0u8; PX];
            tfp(
                &hist,
                k,
                cfg.tfp_window,
                p.full_scale,
                &mut counts,
                &mut out,
            )
            .unwrap();
        }
        Method::Tfi => tfi(&hist, k, p.n_max, p.full_scale, &mut out).unwrap(),
        Method::Mc => {
            let mut ws = WorkspaceBuf::new(spiv_core::WorkspaceSizes::for_motion(W, H));
            let v = mc_velocity();
            let m = spiv_core::motion::Motion { vx: &v, vy: &v[..] };
            let zero = vec![0i16; usize::from(H)];
            let m = spiv_core::motion::Motion { vy: &zero, ..m };
            spiv_core::reconstruct_compensated(
                &hist,
                k,
                p,
                &mut ws.workspace().unwrap(),
                (0, H),
                &m,
                &mut out,
            )
            .unwrap();
        }
        Method::Adaptive => {
            let mut ws = WorkspaceBuf::whole(W, H);
            reconstruct_adaptive(&hist, k, p, &mut ws.workspace().unwrap(), &mut out).unwrap();
        }
    }
    out
}

#[test]
fn every_method_sends_the_cores_frames_at_the_scheduled_ticks() {
    let planes = planes(200);
    for method in Method::ALL {
        let mut cfg = Config::new(40, 9);
        cfg.method = method;
        cfg.params.n_max = 48;
        cfg.tfp_window = 8;
        cfg.schedule.every = 30;
        cfg.schedule.pairs = Some(3);
        let (sent, bytes) = run(cfg, &planes);
        let ticks: Vec<u32> = sent.iter().map(|(s, _)| s.tick).collect();
        assert_eq!(ticks, [40, 49, 70, 79, 100, 109], "{method:?}");
        for (slot, frame) in &sent {
            let want = direct(method, &cfg, &planes, slot.tick);
            assert!(frame == &want, "{method:?} at {}", slot.tick);
            assert!(frame.iter().any(|&g| g > 0), "{method:?}: an empty frame");
        }
        // The frame ends carry the method; the stream ends with a status.
        let mut rx = vec![0u8; MAX_ENCODED];
        let mut dec = Decoder::new(&mut rx);
        let mut input = &bytes[..];
        let (mut ends, mut last) = (0, None);
        while let Some(m) = dec.feed(&mut input) {
            let m = m.unwrap();
            if m.header.kind == Kind::FrameEnd {
                assert_eq!(FrameEnd::parse(m.payload).unwrap().method, method);
                ends += 1;
            }
            last = Some(m.header.kind);
        }
        assert_eq!((ends, last), (6, Some(Kind::Status)));
    }
}

#[test]
fn bad_configurations_and_planes_are_refused() {
    let mut cfg = Config::new(10, 5);
    cfg.method = Method::Tfp;
    cfg.tfp_window = 0;
    assert_eq!(
        Sidecar::new::<()>(W, H, cfg).unwrap_err(),
        SidecarError::Config(ConfigError::Window(0))
    );
    let mut cfg = Config::new(10, 5);
    cfg.schedule.every = 4;
    assert!(matches!(
        Sidecar::new::<()>(W, H, cfg),
        Err(SidecarError::Config(ConfigError::Schedule {
            every: 4,
            dt: 5
        }))
    ));
    assert!(matches!(
        Sidecar::new::<()>(20_000, 8, Config::new(10, 5)),
        Err(SidecarError::Config(ConfigError::RowTooWide(20_000)))
    ));
    let cfg = Config::new(10, 5);
    let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
    let mut mem = buf.memory(0).unwrap();
    let mut sc = Sidecar::new::<()>(W, H, cfg).unwrap();
    let short = vec![0u8; PX / 8 - 1];
    assert!(matches!(
        sc.push_plane(&mut mem, &short, &mut Bytes(Vec::new()), &mut ()),
        Err(SidecarError::Core(spiv_core::Error::PlaneSize { .. }))
    ));
    assert_eq!(sc.sent().planes, 0, "a refused plane is not counted");
    // An Mc frame without a predicted motion is refused when it is due.
    let mut cfg = Config::new(4, 2);
    cfg.method = Method::Mc;
    cfg.params.n_max = 8;
    let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
    let mut mem = buf.memory(0).unwrap();
    let mut sc = Sidecar::new::<()>(W, H, cfg).unwrap();
    let refused = planes(10).iter().find_map(|p| {
        sc.push_plane(&mut mem, p, &mut Bytes(Vec::new()), &mut ())
            .err()
    });
    assert!(
        matches!(
            refused,
            Some(SidecarError::Core(spiv_core::Error::BufferTooSmall { .. }))
        ),
        "{refused:?}"
    );
}

#[test]
fn an_unknown_method_code_is_a_malformed_frame_end() {
    let end = FrameEnd {
        pair: 1,
        member: 0,
        method: Method::Tfi,
        full_scale: 255,
        dt: 13,
        tiles: 2,
        lossy: 0,
        frame_crc: 7,
    };
    let mut b = end.to_bytes();
    assert_eq!(FrameEnd::parse(&b), Ok(end));
    b[5] = 4;
    assert_eq!(FrameEnd::parse(&b), Err(WireError::Payload));
}
