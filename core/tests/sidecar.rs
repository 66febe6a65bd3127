//! The sidecar loop: each method's frames, at the scheduled ticks, equal the
//! core's own functions on the same planes, and the wire says which method
//! made them; bad configurations and planes are refused, never a panic.

//!
//! Needs the `std` feature (owned buffers); `cargo test --workspace` has it.
#![cfg(feature = "std")]

use spiv_core::buffers::{SidecarBuf, WorkspaceBuf};
use spiv_core::error::{ConfigError, Error, LinkError};
use spiv_core::sidecar::{Config, Probe, Sidecar};
use spiv_core::window::{tfi, tfp};
use spiv_core::wire::control::{
    control_header, encode_control, ControlHead, MAX_CONTROL_ENCODED, MAX_CONTROL_PAYLOAD,
};
use spiv_core::wire::sender::{Link, Slot};
use spiv_core::wire::{encode_message, Decoder, FrameEnd, Kind, WireError, MAX_ENCODED};
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
/// right in the top half, 0.1 in the bottom (1/4096 px per tick).
fn mc_velocity() -> Vec<i16> {
    (0..H).map(|r| if r < H / 2 { 1229 } else { 410 }).collect()
}

/// The control message telling the sidecar [`mc_velocity`] from pair 0,
/// one node per row.
fn mc_control() -> Vec<u8> {
    let zero = vec![0i16; usize::from(H)];
    control(0, 0, 0, (&mc_velocity(), &zero), &[], (W, H))
}

/// A framed control message `seq` for a `size` sensor from `from_pair`:
/// window limit `n_max` (0: the sidecar's), velocities per row, caps.
fn control(
    from_pair: u32,
    seq: u32,
    n_max: u16,
    (vx, vy): (&[i16], &[i16]),
    caps: &[u16],
    (w, h): (u16, u16),
) -> Vec<u8> {
    let head = ControlHead {
        from_pair,
        n_max,
        pitch: 1,
        cols: 1,
        tile: 64,
    };
    let mut payload = vec![0u8; MAX_CONTROL_PAYLOAD];
    let n = encode_control(&head, vx, vy, caps, &mut payload).unwrap();
    let mut out = vec![0u8; MAX_CONTROL_ENCODED];
    let m = encode_message(&control_header(seq, w, h), &payload[..n], &mut out).unwrap();
    out.truncate(m);
    out
}

fn run(cfg: Config, planes: &[Vec<u8>]) -> (Vec<(Slot, Vec<u16>)>, Vec<u8>) {
    let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
    let mut sc = Sidecar::new(W, H, cfg).unwrap();
    if cfg.method == Method::Mc {
        sc.hear(&mut buf.downlink(), &mc_control());
    }
    let mut mem = buf.memory(0).unwrap();
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
            let m = spiv_core::motion::Motion::rows(&v, &v[..]);
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
        Method::Ladder => panic!("the frame loop makes no ladder frames"),
    }
    out
}

#[test]
fn the_frame_loop_refuses_the_ladders_method() {
    for (method, bootstrap) in [(Method::Ladder, Method::Tfp), (Method::Mc, Method::Ladder)] {
        let mut cfg = Config::new(40, 9);
        cfg.method = method;
        cfg.bootstrap = bootstrap;
        let got = Sidecar::new(W, H, cfg).map(|_| ());
        assert_eq!(got, Err(Error::Config(ConfigError::Method(Method::Ladder))));
    }
}

#[test]
fn every_method_sends_the_cores_frames_at_the_scheduled_ticks() {
    let planes = planes(200);
    for method in Method::ALL.into_iter().filter(|&m| m != Method::Ladder) {
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
        Sidecar::new(W, H, cfg).unwrap_err(),
        Error::Config(ConfigError::Window(0))
    );
    let mut cfg = Config::new(10, 5);
    cfg.schedule.every = 4;
    assert!(matches!(
        Sidecar::new(W, H, cfg),
        Err(Error::Config(ConfigError::Schedule { every: 4, dt: 5 }))
    ));
    assert!(matches!(
        Sidecar::new(20_000, 8, Config::new(10, 5)),
        Err(Error::Config(ConfigError::RowTooWide(20_000)))
    ));
    let cfg = Config::new(10, 5);
    let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
    let mut mem = buf.memory(0).unwrap();
    let mut sc = Sidecar::new(W, H, cfg).unwrap();
    let short = vec![0u8; PX / 8 - 1];
    assert!(matches!(
        sc.push_plane(&mut mem, &short, &mut Bytes(Vec::new()), &mut ()),
        Err(LinkError::Core(Error::PlaneSize { .. }))
    ));
    assert_eq!(sc.sent().planes, 0, "a refused plane is not counted");
}

#[test]
fn an_mc_sidecar_that_heard_no_motion_sends_its_bootstrap_frames() {
    let planes = planes(120);
    for bootstrap in [Method::Tfp, Method::Adaptive] {
        let mut cfg = Config::new(40, 9);
        cfg.method = Method::Mc;
        cfg.bootstrap = bootstrap;
        cfg.params.n_max = 48;
        cfg.schedule.pairs = Some(2);
        let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
        let mut mem = buf.memory(0).unwrap();
        let mut sc = Sidecar::new(W, H, cfg).unwrap();
        let (mut link, mut kept) = (Bytes(Vec::new()), Kept::default());
        for p in &planes {
            sc.push_plane(&mut mem, p, &mut link, &mut kept).unwrap();
        }
        assert_eq!(kept.0.len(), 4);
        for (slot, frame) in &kept.0 {
            assert!(frame == &direct(bootstrap, &cfg, &planes, slot.tick));
        }
        let (methods, _) = methods_and_status(&link.0);
        assert_eq!(methods, [bootstrap; 4]);
    }
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
    b[5] = 5;
    assert_eq!(FrameEnd::parse(&b), Err(WireError::Payload.into()));
}

/// The frame ends' methods and the last status of a message stream.
fn methods_and_status(bytes: &[u8]) -> (Vec<Method>, Option<spiv_core::wire::Status>) {
    let mut rx = vec![0u8; MAX_ENCODED];
    let mut dec = Decoder::new(&mut rx);
    let mut input = bytes;
    let (mut methods, mut status) = (Vec::new(), None);
    while let Some(m) = dec.feed(&mut input) {
        let m = m.unwrap();
        match m.header.kind {
            Kind::FrameEnd => methods.push(FrameEnd::parse(m.payload).unwrap().method),
            Kind::Status => status = Some(spiv_core::wire::Status::parse(m.payload).unwrap()),
            _ => {}
        }
    }
    (methods, status)
}

/// What [`run_heard`] returns: the configuration, the frames as sent, the
/// wire bytes and the downlink's counts.
type Heard = (
    Config,
    Vec<(Slot, Vec<u16>)>,
    Vec<u8>,
    spiv_core::downlink::DownlinkStats,
);

/// An Mc sidecar over `planes`, 4 pairs; `talk(plane index, pair due)`
/// returns downlink bytes to hear before that plane.
fn run_heard(planes: &[Vec<u8>], mut talk: impl FnMut(usize, Option<u32>) -> Vec<u8>) -> Heard {
    let mut cfg = Config::new(40, 9);
    cfg.method = Method::Mc;
    cfg.params.n_max = 48;
    cfg.schedule.every = 30;
    cfg.schedule.pairs = Some(4);
    let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
    let mut sc = Sidecar::new(W, H, cfg).unwrap();
    let (mut link, mut kept) = (Bytes(Vec::new()), Kept::default());
    for (i, p) in planes.iter().enumerate() {
        if sc.done() {
            break;
        }
        let bytes = talk(i, sc.pair_due());
        sc.hear(&mut buf.downlink(), &bytes);
        let mut mem = buf.memory(sc.next_tick()).unwrap();
        sc.push_plane(&mut mem, p, &mut link, &mut kept).unwrap();
    }
    let mut mem = buf.memory(sc.next_tick()).unwrap();
    sc.finish(&mut mem.send, &mut link).unwrap();
    (cfg, kept.0, link.0, sc.downlink())
}

#[test]
fn a_control_applies_from_its_pair_and_both_frames_of_a_pair_share_it() {
    let planes = planes(200);
    let zero = vec![0i16; usize::from(H)];
    // Heard at plane 0 for pair 2, and again (newer) between the frames of
    // pair 2 (made when planes 123 and 132 arrive): that one waits for
    // pair 3.
    let (cfg, sent, bytes, dl) = run_heard(&planes, |i, _| match i {
        0 => control(2, 0, 0, (&mc_velocity(), &zero), &[], (W, H)),
        128 => control(2, 1, 0, (&zero, &zero), &[], (W, H)),
        _ => Vec::new(),
    });
    let (methods, status) = methods_and_status(&bytes);
    use Method::{Mc, Tfp as T};
    assert_eq!(methods, [T, T, T, T, Mc, Mc, Mc, Mc]);
    for (slot, frame) in &sent {
        let method = if slot.pair >= 2 { Mc } else { T };
        let want = if slot.pair == 3 {
            // Pair 3 uses the second control: zero motion.
            let mut words = vec![0u64; History::words_needed(W, H, 255).unwrap()];
            let mut hist = History::new(&mut words, W, H, 0, H, 255).unwrap();
            for p in &planes[..=(slot.tick as usize + 24)] {
                hist.push(&PlaneView::new(p, W, H).unwrap()).unwrap();
            }
            let mut ws = WorkspaceBuf::new(spiv_core::WorkspaceSizes::for_motion(W, H));
            let m = spiv_core::motion::Motion::rows(&zero, &zero);
            let mut out = vec![0u16; PX];
            spiv_core::reconstruct_compensated(
                &hist,
                slot.tick,
                &cfg.params,
                &mut ws.workspace().unwrap(),
                (0, H),
                &m,
                &mut out,
            )
            .unwrap();
            out
        } else {
            direct(method, &cfg, &planes, slot.tick)
        };
        assert!(frame == &want, "pair {} member {}", slot.pair, slot.member);
    }
    assert_eq!((dl.heard, dl.applied, dl.refused), (2, 2, 0));
    let status = status.unwrap();
    assert_eq!((status.controls_applied, status.controls_refused), (2, 0));
}

#[test]
fn corrupted_malformed_foreign_and_stale_controls_are_counted_never_applied() {
    let planes = planes(200);
    let zero = vec![0i16; usize::from(H)];
    let good = control(1, 0, 0, (&mc_velocity(), &zero), &[], (W, H));
    let mut flipped = good.clone();
    flipped[20] ^= 0x10;
    let foreign = control(0, 1, 0, (&mc_velocity(), &zero), &[], (W + 8, H));
    let too_long = control(0, 2, 200, (&mc_velocity(), &zero), &[], (W, H));
    let too_many_caps = control(0, 3, 0, (&[], &[]), &[8; 5], (W, H));
    let stale = control(0, 4, 0, (&mc_velocity(), &zero), &[], (W, H));
    let (_, _, bytes, dl) = run_heard(&planes, |i, _| match i {
        0 => [
            flipped.clone(),
            foreign.clone(),
            too_long.clone(),
            too_many_caps.clone(),
        ]
        .concat(),
        1 => vec![0x55; 40], // noise, then its delimiter
        2 => vec![0],
        3 => good.clone(),
        4 => stale.clone(),
        _ => Vec::new(),
    });
    let (methods, status) = methods_and_status(&bytes);
    use Method::{Mc, Tfp as T};
    assert_eq!(methods, [T, T, Mc, Mc, Mc, Mc, Mc, Mc]);
    assert_eq!((dl.heard, dl.applied, dl.refused), (1, 1, 6));
    assert_eq!(status.unwrap().controls_refused, 6);
}

#[test]
fn caps_and_a_lower_n_max_from_the_host_make_the_adaptive_frame() {
    let planes = planes(200);
    let mut cfg = Config::new(40, 9);
    cfg.params.n_max = 48;
    cfg.schedule.pairs = Some(1);
    for (n_max, caps) in [(0u16, vec![8u16]), (20, vec![])] {
        let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
        let mut sc = Sidecar::new(W, H, cfg).unwrap();
        sc.hear(
            &mut buf.downlink(),
            &control(0, 0, n_max, (&[], &[]), &caps, (W, H)),
        );
        let mut mem = buf.memory(0).unwrap();
        let (mut link, mut kept) = (Bytes(Vec::new()), Kept::default());
        for p in &planes {
            if sc.done() {
                break;
            }
            sc.push_plane(&mut mem, p, &mut link, &mut kept).unwrap();
        }
        let mut q = cfg.params;
        if n_max > 0 {
            q.n_max = n_max;
            q.n0 = q.n0.min(n_max);
        }
        for (slot, frame) in &kept.0 {
            let mut words = vec![0u64; History::words_needed(W, H, 255).unwrap()];
            let mut hist = History::new(&mut words, W, H, 0, H, 255).unwrap();
            for p in &planes[..=(slot.tick as usize + 24)] {
                hist.push(&PlaneView::new(p, W, H).unwrap()).unwrap();
            }
            let mut ws = WorkspaceBuf::whole(W, H);
            let mut want = vec![0u16; PX];
            spiv_core::sidecar::capped_frame(
                &hist,
                slot.tick,
                &q,
                &caps,
                &mut ws.workspace().unwrap(),
                &mut want,
            )
            .unwrap();
            assert!(frame == &want, "n_max {n_max} caps {caps:?}");
            let plain = direct(Method::Adaptive, &cfg, &planes, slot.tick);
            assert!(frame != &plain, "the control changed nothing");
        }
    }
}

proptest::proptest! {
    /// Any bytes on the downlink, in any chunking: never a panic, and a
    /// valid control after them is still heard.
    #[test]
    fn the_downlink_takes_any_bytes(
        junk in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..600),
        cut in 1usize..64,
    ) {
        let cfg = Config::new(40, 9);
        let mut buf = SidecarBuf::<u16>::new(W, H, &cfg).unwrap();
        let mut sc = Sidecar::new(W, H, cfg).unwrap();
        let zero = vec![0i16; usize::from(H)];
        let good = control(0, 9, 0, (&mc_velocity(), &zero), &[4], (W, H));
        let mut stream = junk.clone();
        stream.push(0);
        stream.extend_from_slice(&good);
        for part in stream.chunks(cut) {
            sc.hear(&mut buf.downlink(), part);
        }
        proptest::prop_assert!(sc.downlink().heard >= 1);
    }
}
