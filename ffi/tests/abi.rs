//! The C ABI driven from Rust, as a C caller drives it: the loop over the
//! committed strip gives the Cortex-M4's parity lines, frames on demand
//! give the loop's frames and bytes, and every bad input comes back as a
//! status code (never a panic, never a write out of the block).

// Calling a C ABI from Rust takes raw pointers, as a C caller does.
#![allow(unsafe_code)]

use std::ffi::{c_void, CStr};
use std::path::{Path, PathBuf};
use std::ptr;

use proptest::prelude::*;
use spiv_ffi::*;

const W: u16 = 128;
const H: u16 = 64;
const PLANE: usize = W as usize * H as usize / 8;

fn m4() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware-sim/cortex-m4")
}

fn strip() -> Vec<u8> {
    std::fs::read(m4().join("data/strip.dat")).expect("committed strip")
}

fn defaults(w: u16, h: u16, dt: u32) -> SpivConfig {
    let mut c = std::mem::MaybeUninit::<SpivConfig>::uninit();
    // SAFETY: a writable config.
    assert_eq!(
        unsafe { spiv_config_default(w, h, dt, c.as_mut_ptr()) },
        SpivStatus::SpivOk
    );
    // SAFETY: filled above.
    unsafe { c.assume_init() }
}

/// A handle in an owned, 8-byte-aligned block.
struct Handle {
    _mem: Vec<u64>,
    sc: *mut SpivSidecar,
}

impl Handle {
    fn new(cfg: &SpivConfig) -> Result<Handle, SpivStatus> {
        let mut need = 0usize;
        // SAFETY: readable config, writable size.
        let s = unsafe { spiv_memory_size(cfg, &mut need) };
        if s != SpivStatus::SpivOk {
            return Err(s);
        }
        let mut mem = vec![0u64; need.div_ceil(8)];
        let mut sc = ptr::null_mut();
        // SAFETY: the block holds `need` bytes and lives as long as the handle.
        let s = unsafe { spiv_init(cfg, mem.as_mut_ptr().cast(), need, &mut sc) };
        if s != SpivStatus::SpivOk {
            return Err(s);
        }
        Ok(Handle { _mem: mem, sc })
    }
}

/// What the link saw.
#[derive(Default)]
struct Tap {
    stream: Vec<u8>,
    sent: SpivSent,
    frames: Vec<(SpivFrameInfo, Vec<u8>)>,
    refuse: bool,
}

unsafe extern "C" fn send(ctx: *mut c_void, bytes: *const u8, len: usize) -> i32 {
    // SAFETY: ctx is the test's Tap; bytes a message of len bytes.
    let t = unsafe { &mut *ctx.cast::<Tap>() };
    if t.refuse {
        return 7;
    }
    t.stream
        .extend_from_slice(unsafe { std::slice::from_raw_parts(bytes, len) });
    0
}

unsafe extern "C" fn frame(ctx: *mut c_void, info: *const SpivFrameInfo, samples: *const c_void) {
    // SAFETY: as the header documents.
    let (t, info) = unsafe { (&mut *ctx.cast::<Tap>(), *info) };
    let n = info.samples * usize::from(info.bytes_per_sample);
    let s = unsafe { std::slice::from_raw_parts(samples.cast::<u8>(), n) }.to_vec();
    t.frames.push((info, s));
}

fn link(tap: &mut Tap) -> SpivLink {
    SpivLink {
        send: Some(send),
        frame: Some(frame),
        ctx: ptr::from_mut(tap).cast(),
    }
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = (c >> 1) ^ (0xEDB8_8320 & 0u32.wrapping_sub(c & 1));
        }
    }
    !c
}

/// The loop over the strip: the parity line and what the link saw.
fn run_loop(cfg: &SpivConfig, control: Option<&[u8]>) -> (String, Tap) {
    let h = Handle::new(cfg).expect("handle");
    if let Some(c) = control {
        // SAFETY: a live handle, a readable buffer.
        assert_eq!(
            unsafe { spiv_hear(h.sc, c.as_ptr(), c.len()) },
            SpivStatus::SpivOk
        );
    }
    let mut tap = Tap::default();
    let l = link(&mut tap);
    let strip = strip();
    for plane in strip.chunks_exact(PLANE) {
        // SAFETY: a live handle.
        if unsafe { spiv_done(h.sc) } == 1 {
            break;
        }
        // SAFETY: a live handle, a whole plane, a valid link.
        let s = unsafe { spiv_push_plane(h.sc, plane.as_ptr(), plane.len(), &l) };
        assert_eq!(s, SpivStatus::SpivOk);
    }
    let mut sent = SpivSent::default();
    // SAFETY: as above.
    assert_eq!(
        unsafe { spiv_finish(h.sc, &l, &mut sent) },
        SpivStatus::SpivOk
    );
    tap.sent = sent;
    let crcs: Vec<String> = tap
        .frames
        .iter()
        .map(|(i, _)| format!("{:08x}", i.crc))
        .collect();
    let line = format!(
        "{}planes={} frames={} messages={} bytes={} stream_crc={:08x} frame_crcs={}\n",
        if control.is_some() { "mc " } else { "" },
        sent.planes,
        sent.frames,
        sent.messages,
        sent.bytes,
        crc32(&tap.stream),
        crcs.join(",")
    );
    (line, tap)
}

fn one_pair() -> SpivConfig {
    let mut c = defaults(W, H, 13);
    c.pairs = 1;
    c
}

#[test]
fn the_loop_prints_the_cortex_m4_parity_lines() {
    let (line, tap) = run_loop(&one_pair(), None);
    let expected = std::fs::read_to_string(m4().join("expected.txt")).unwrap();
    assert_eq!(line, expected);
    assert_eq!(tap.frames.len(), 2);
    assert_eq!(
        (tap.frames[0].0.tick, tap.frames[1].0.tick),
        (64, 77),
        "frames at first and first + dt"
    );

    let mut mc = one_pair();
    mc.method = SPIV_METHOD_MC;
    mc.bootstrap = SPIV_METHOD_ADAPTIVE;
    mc.refine = 1;
    let control = std::fs::read(m4().join("data/control.bin")).unwrap();
    let (line, tap) = run_loop(&mc, Some(&control));
    let expected = std::fs::read_to_string(m4().join("expected-mc.txt")).unwrap();
    assert_eq!(format!("mc {expected}"), line);
    assert!(tap.frames.iter().all(|(i, _)| i.method == SPIV_METHOD_MC));
}

/// Frames on demand at the loop's ticks: the same samples and, sent as
/// the loop sends them, the same bytes on the wire.
fn on_demand_matches_loop(cfg: &SpivConfig) {
    let (_, looped) = run_loop(cfg, None);
    assert_eq!(looped.frames.len(), 2);
    let h = Handle::new(cfg).unwrap();
    let mut tap = Tap::default();
    let l = link(&mut tap);
    let strip = strip();
    let window = if cfg.method == SPIV_METHOD_TFP {
        cfg.tfp_window
    } else {
        cfg.n_max
    };
    let ahead = u32::from(window - window / 2) - 1;
    // The planes the loop ingested (it stops once its pair was sent).
    let planes = looped.sent.planes as usize;
    for (k, plane) in strip.chunks_exact(PLANE).take(planes).enumerate() {
        let mut tick = u32::MAX;
        // SAFETY: a live handle, a whole plane.
        let s = unsafe { spiv_ingest(h.sc, plane.as_ptr(), plane.len(), &mut tick) };
        assert_eq!((s, tick), (SpivStatus::SpivOk, k as u32));
        // Each frame when its window's last plane has arrived.
        for (member, (want, samples)) in looped.frames.iter().enumerate() {
            if want.tick + ahead != tick {
                continue;
            }
            let mut info = SpivFrameInfo::default();
            let mut out: *const c_void = ptr::null();
            // SAFETY: a live handle, writable outputs.
            let s = unsafe { spiv_make_frame(h.sc, want.tick, ptr::null(), &mut info, &mut out) };
            assert_eq!(s, SpivStatus::SpivOk);
            assert_eq!((info.method, info.samples), (want.method, want.samples));
            // SAFETY: the handle's frame, `samples` bytes (8-bit frames).
            let made = unsafe { std::slice::from_raw_parts(out.cast::<u8>(), info.samples) };
            if cfg.encoding != SPIV_ENCODING_SPARSE && cfg.encoding != SPIV_ENCODING_SPARSE_CONTEXT
            {
                // Lossless: the frame made is the frame sent.
                assert_eq!(info.crc, want.crc);
                assert_eq!(made, &samples[..]);
            }
            // SAFETY: as above.
            let s = unsafe { spiv_send_frame(h.sc, 0, member as u8, &l) };
            assert_eq!(s, SpivStatus::SpivOk);
        }
    }
    // What the link saw of each frame (lossy: as the receiver decodes it).
    assert_eq!(tap.frames.len(), 2);
    for ((got, g), (want, w)) in tap.frames.iter().zip(&looped.frames) {
        assert_eq!(
            (got.crc, got.tick, got.member, g),
            (want.crc, want.tick, want.member, w)
        );
    }
    let mut sent = SpivSent::default();
    // SAFETY: as above.
    assert_eq!(
        unsafe { spiv_finish(h.sc, &l, &mut sent) },
        SpivStatus::SpivOk
    );
    assert_eq!(sent, looped.sent);
    assert!(
        tap.stream == looped.stream,
        "the same messages, byte for byte"
    );
}

#[test]
fn frames_on_demand_are_the_loops_frames_and_bytes() {
    on_demand_matches_loop(&one_pair());
    let mut tfp = one_pair();
    tfp.method = SPIV_METHOD_TFP;
    tfp.encoding = SPIV_ENCODING_SPARSE;
    on_demand_matches_loop(&tfp);
}

#[test]
fn motion_on_demand_compensates_and_short_rows_are_refused() {
    let mut cfg = one_pair();
    cfg.method = SPIV_METHOD_MC;
    let h = Handle::new(&cfg).unwrap();
    for plane in strip().chunks_exact(PLANE).take(141) {
        // SAFETY: a live handle, a whole plane.
        let s = unsafe { spiv_ingest(h.sc, plane.as_ptr(), plane.len(), ptr::null_mut()) };
        assert_eq!(s, SpivStatus::SpivOk);
    }
    let make = |guide: *const SpivGuide| {
        let mut info = SpivFrameInfo::default();
        let mut out = ptr::null();
        // SAFETY: a live handle, writable outputs, a guide or null.
        let s = unsafe { spiv_make_frame(h.sc, 64, guide, &mut info, &mut out) };
        (s, info)
    };
    // No motion: the bootstrap (TFP) frame.
    let (s, info) = make(ptr::null());
    assert_eq!((s, info.method), (SpivStatus::SpivOk, SPIV_METHOD_TFP));
    // The strip flows along x (scene.json: linear profile); 0.1 px/tick.
    let vx = vec![26i16; usize::from(H)];
    let vy = vec![0i16; usize::from(H)];
    let mut g = SpivGuide {
        n_max: 0,
        caps: ptr::null(),
        n_caps: 0,
        vx: vx.as_ptr(),
        vy: vy.as_ptr(),
        rows: vx.len(),
        cols: 1,
        tile: 0,
    };
    let (s, info) = make(&g);
    assert_eq!((s, info.method), (SpivStatus::SpivOk, SPIV_METHOD_MC));
    g.rows = usize::from(H) - 1;
    assert_eq!(make(&g).0, SpivStatus::SpivErrBuffer);
    // A grid of two 64-px columns needs two velocities per row; a tile off
    // the word grid is refused.
    let (gx, gy) = (
        vec![26i16; 2 * usize::from(H)],
        vec![0i16; 2 * usize::from(H)],
    );
    let mut grid = SpivGuide {
        vx: gx.as_ptr(),
        vy: gy.as_ptr(),
        rows: gx.len(),
        cols: 2,
        tile: 64,
        ..g
    };
    let (s, info) = make(&grid);
    assert_eq!((s, info.method), (SpivStatus::SpivOk, SPIV_METHOD_MC));
    grid.rows = gx.len() - 1;
    assert_eq!(make(&grid).0, SpivStatus::SpivErrBuffer);
    grid.rows = gx.len();
    grid.tile = 96;
    assert_eq!(make(&grid).0, SpivStatus::SpivErrConfig);
    // Caps with a null pointer and a count are refused, not read.
    g.rows = 0;
    g.n_caps = 2;
    assert_eq!(make(&g).0, SpivStatus::SpivErrNull);
    // A tick the history no longer (or not yet) holds.
    let mut info = SpivFrameInfo::default();
    let mut out = ptr::null();
    // SAFETY: as above.
    let s = unsafe { spiv_make_frame(h.sc, 5, ptr::null(), &mut info, &mut out) };
    assert_eq!(s, SpivStatus::SpivErrTick);
}

#[test]
fn bad_input_comes_back_as_status_codes() {
    let cfg = one_pair();
    let mut need = 0usize;
    let mut sc = ptr::null_mut();
    // SAFETY (each call below): pointers are valid or deliberately null.
    unsafe {
        assert_eq!(
            spiv_memory_size(ptr::null(), &mut need),
            SpivStatus::SpivErrNull
        );
        assert_eq!(spiv_memory_size(&cfg, &mut need), SpivStatus::SpivOk);
        let mut mem = vec![0u64; need / 8 + 2];
        let base = mem.as_mut_ptr().cast::<u8>();
        assert_eq!(
            spiv_init(&cfg, base.cast(), need - 1, &mut sc),
            SpivStatus::SpivErrMemory
        );
        assert_eq!(
            spiv_init(&cfg, base.add(4).cast(), need, &mut sc),
            SpivStatus::SpivErrMemory,
            "misaligned"
        );
        assert_eq!(
            spiv_init(&cfg, ptr::null_mut(), need, &mut sc),
            SpivStatus::SpivErrNull
        );
        for bad in [
            SpivConfig { method: 9, ..cfg },
            SpivConfig {
                bootstrap: 7,
                ..cfg
            },
            SpivConfig { encoding: 0, ..cfg },
            SpivConfig { encoding: 7, ..cfg },
            SpivConfig { refine: 2, ..cfg },
            SpivConfig { dt: 0, ..cfg },
            SpivConfig { every: 5, ..cfg },
            SpivConfig { n_max: 0, ..cfg },
            SpivConfig { n_max: 300, ..cfg },
            SpivConfig {
                full_scale: 0,
                ..cfg
            },
            SpivConfig { width: 0, ..cfg },
            SpivConfig {
                width: 3,
                height: 3,
                ..cfg
            },
            SpivConfig {
                lossy_block: 1,
                ..cfg
            },
            SpivConfig {
                method: SPIV_METHOD_TFP,
                tfp_window: 0,
                ..cfg
            },
        ] {
            assert_eq!(
                spiv_memory_size(&bad, &mut need),
                SpivStatus::SpivErrConfig,
                "{bad:?}"
            );
            assert_eq!(
                spiv_init(&bad, base.cast(), mem.len() * 8, &mut sc),
                SpivStatus::SpivErrConfig
            );
        }
        // A block that was never initialised is not a handle.
        let garbage = base.cast::<SpivSidecar>();
        assert_eq!(
            spiv_hear(garbage, ptr::null(), 0),
            SpivStatus::SpivErrHandle
        );
        assert_eq!(spiv_done(ptr::null_mut()), 0);
    }
}

/// A handle's calls with a bad plane, null pointers, the wrong mode or a
/// link that refuses: each a status code; every code has a message.
#[test]
fn bad_calls_on_a_handle_come_back_as_status_codes() {
    let cfg = one_pair();
    // SAFETY (each call below): pointers are valid or deliberately null.
    unsafe {
        let h = Handle::new(&cfg).unwrap();
        let mut tap = Tap::default();
        let l = link(&mut tap);
        let plane = vec![0u8; PLANE + 1];
        assert_eq!(
            spiv_push_plane(h.sc, plane.as_ptr(), PLANE + 1, &l),
            SpivStatus::SpivErrPlane
        );
        assert_eq!(
            spiv_push_plane(h.sc, ptr::null(), PLANE, &l),
            SpivStatus::SpivErrNull
        );
        assert_eq!(
            spiv_push_plane(h.sc, plane.as_ptr(), PLANE, ptr::null()),
            SpivStatus::SpivErrNull
        );
        // The loop owns this handle now: frames on demand are refused.
        assert_eq!(
            spiv_ingest(h.sc, plane.as_ptr(), PLANE, ptr::null_mut()),
            SpivStatus::SpivErrMode
        );
        // A link that refuses the bytes.
        tap.refuse = true;
        assert_eq!(
            spiv_finish(h.sc, &l, ptr::null_mut()),
            SpivStatus::SpivErrLink
        );

        let h = Handle::new(&cfg).unwrap();
        assert_eq!(
            spiv_send_frame(h.sc, 0, 0, &l),
            SpivStatus::SpivErrMode,
            "nothing made"
        );
        for code in -12..=1 {
            let m = CStr::from_ptr(spiv_status_message(code)).to_str().unwrap();
            assert!(!m.is_empty() && !m.contains('\n'));
        }
    }
}

/// Configurations that run, and some with one field broken.
fn arb_config() -> impl Strategy<Value = SpivConfig> {
    (
        (1u16..=24, 1u16..=24, 0u8..4, 0u8..2, 1u8..=6, 0u8..2),
        (1u16..=40, 1u16..=160, 1u16..=1023),
        (0u32..200, 1u32..40, 0u32..100, 0u32..4, 0u32..3),
        (2u8..=64, any::<u16>(), 0u16..10),
        (0u8..24, any::<u16>()),
    )
        .prop_map(
            |(
                (w8, h, method, bootstrap, encoding, refine),
                (tfp_window, n_max, full_scale),
                (first, dt, extra, pairs, status_every),
                (lossy_block, lossy_tolerance, lossy_contrast),
                (broken, junk),
            )| {
                let mut c = SpivConfig {
                    width: w8 * 8,
                    height: h,
                    method,
                    bootstrap,
                    encoding,
                    refine,
                    tfp_window,
                    n_max,
                    full_scale,
                    first,
                    dt,
                    every: dt + extra,
                    pairs,
                    status_every,
                    lossy_block,
                    lossy_tolerance,
                    lossy_contrast,
                    lossy_contrast_mc: lossy_contrast / 2,
                };
                // One field out of its range now and then.
                match broken {
                    0 => c.width = junk,
                    1 => c.height = junk,
                    2 => c.method = junk as u8,
                    3 => c.encoding = junk as u8,
                    4 => c.n_max = junk,
                    5 => c.tfp_window = junk,
                    6 => c.every = u32::from(junk),
                    7 => c.lossy_block = junk as u8,
                    8 => c.full_scale = junk,
                    _ => {}
                }
                c
            },
        )
}

proptest! {
    // Case counts from PROPTEST_CASES (CI sets 256).

    /// Any configuration is refused or runs: any planes (of any length),
    /// any downlink bytes, frames at any tick — only status codes come
    /// back, and nothing is written past the block (a guard word after it
    /// stays untouched).
    #[test]
    fn any_config_and_bytes_give_status_codes(
        cfg in arb_config(),
        planes in proptest::collection::vec((any::<u8>(), 0usize..3), 0..40),
        downlink in proptest::collection::vec(any::<u8>(), 0..600),
        ticks in proptest::collection::vec(0u32..80, 0..3),
    ) {
        let mut need = 0usize;
        // SAFETY: valid pointers throughout; the block holds `need` bytes.
        unsafe {
            let s = spiv_memory_size(&cfg, &mut need);
            prop_assert!(s == SpivStatus::SpivOk || s == SpivStatus::SpivErrConfig);
            if s != SpivStatus::SpivOk {
                return Ok(());
            }
            const GUARD: u64 = 0xDEAD_BEEF_F00D_CAFE;
            let words = need.div_ceil(8);
            let mut mem = vec![GUARD; words + 1];
            let mut sc = ptr::null_mut();
            prop_assert_eq!(spiv_init(&cfg, mem.as_mut_ptr().cast(), need, &mut sc), SpivStatus::SpivOk);
            let mut tap = Tap::default();
            let l = link(&mut tap);
            let bytes = usize::from(cfg.width) * usize::from(cfg.height) / 8;
            let manual = !ticks.is_empty();
            if !manual {
                let _ = spiv_hear(sc, downlink.as_ptr(), downlink.len());
            }
            for (fill, len_kind) in planes {
                let len = [bytes, bytes.saturating_sub(1), bytes + 1][len_kind];
                let plane = vec![fill; len];
                let s = if manual {
                    spiv_ingest(sc, plane.as_ptr(), len, ptr::null_mut())
                } else {
                    spiv_push_plane(sc, plane.as_ptr(), len, &l)
                };
                prop_assert!(s == SpivStatus::SpivOk || (len != bytes && s == SpivStatus::SpivErrPlane), "{:?}", s);
            }
            for t in ticks {
                let mut info = SpivFrameInfo::default();
                let mut out = ptr::null();
                let s = spiv_make_frame(sc, t, ptr::null(), &mut info, &mut out);
                prop_assert!(s == SpivStatus::SpivOk || s == SpivStatus::SpivErrTick, "{:?}", s);
                if s == SpivStatus::SpivOk {
                    prop_assert_eq!(spiv_send_frame(sc, 0, 0, &l), SpivStatus::SpivOk);
                }
            }
            prop_assert_eq!(spiv_finish(sc, &l, ptr::null_mut()), SpivStatus::SpivOk);
            prop_assert_eq!(mem[words], GUARD);
        }
    }
}

/// The light model's arrays, owned.
#[derive(Debug, PartialEq)]
struct LightArrays {
    last: Vec<u16>,
    period: Vec<u16>,
    rate: Vec<u32>,
    short_run: Vec<u16>,
    lead: Vec<i8>,
    flags: Vec<u8>,
}

impl LightArrays {
    fn new(px: usize) -> LightArrays {
        LightArrays {
            last: vec![0; px],
            period: vec![0; px],
            rate: vec![0; px],
            short_run: vec![0; px],
            lead: vec![0; px],
            flags: vec![0; px],
        }
    }

    /// The core's view of the arrays.
    fn state(&mut self) -> spiv_core::light::LightState<'_> {
        spiv_core::light::LightState {
            last: &mut self.last,
            period: &mut self.period,
            rate: &mut self.rate,
            short: &mut self.short_run,
            lead: &mut self.lead,
            flags: &mut self.flags,
        }
    }

    fn handle(&mut self) -> SpivLight {
        SpivLight {
            last: self.last.as_mut_ptr(),
            period: self.period.as_mut_ptr(),
            rate: self.rate.as_mut_ptr(),
            short_run: self.short_run.as_mut_ptr(),
            lead: self.lead.as_mut_ptr(),
            flags: self.flags.as_mut_ptr(),
            len: self.last.len(),
            next: 0,
            seen: 0,
        }
    }
}

/// One plane (`plane.len()` bytes) through `spiv_light_push` into
/// `events`, with room said to be `cap` (at most `events.len()`): the
/// status and the events written.
fn light_push(
    l: &mut SpivLight,
    plane: &[u8],
    events: &mut [SpivEvent],
    cap: usize,
) -> (SpivStatus, usize) {
    assert!(cap <= events.len());
    let mut n = usize::MAX;
    // SAFETY: `plane.len()` readable bytes, `cap` writable event slots,
    // and the arrays `l` was made over (the caller's).
    let s = unsafe {
        spiv_light_push(
            l,
            W,
            H,
            plane.as_ptr(),
            plane.len(),
            events.as_mut_ptr(),
            cap,
            &mut n,
        )
    };
    (s, n)
}

/// The static-light model through the C ABI settles the events the
/// core's model settles on the same planes (the strip, from a tick near
/// the 16-bit wrap), with the same state after every plane; a short
/// event buffer, a short array or a plane of the wrong size is refused
/// before anything changes.
#[test]
fn light_model_through_the_abi() {
    use spiv_core::light::Light;
    let px = usize::from(W) * usize::from(H);
    let mut c = LightArrays::new(px);
    let mut l = c.handle();
    // SAFETY: six arrays of `px` entries each.
    assert_eq!(
        unsafe { spiv_light_init(&mut l, W, H, 65_500) },
        SpivStatus::SpivOk
    );
    let mut r = LightArrays::new(px);
    let state = r.state();
    let mut core = Light::new(W, H, 65_500, state).expect("model");
    let data = strip();
    let mut events = vec![SpivEvent::default(); px];
    let mut total = 0usize;
    for plane in data.chunks_exact(PLANE) {
        let (s, n) = light_push(&mut l, plane, &mut events, px);
        assert_eq!(s, SpivStatus::SpivOk);
        let mut want = Vec::new();
        let view = spiv_core::PlaneView::new(plane, W, H).expect("plane");
        core.push(&view, |e| want.push((e.index, e.tick, e.sign)))
            .expect("push");
        let got: Vec<_> = events[..n]
            .iter()
            .map(|e| (e.index, e.tick, e.sign))
            .collect();
        assert_eq!(got, want);
        assert_eq!(l.next, core.next_tick());
        total += n;
    }
    assert!(total > 10_000, "{total} events");
    assert_eq!(c, r);

    let mut c = LightArrays::new(px);
    let mut l = c.handle();
    // SAFETY: as above.
    assert_eq!(
        unsafe { spiv_light_init(&mut l, W, H, 0) },
        SpivStatus::SpivOk
    );
    let plane = &data[..PLANE];
    // A buffer one event short of a plane's worst case; half a plane.
    let (s, n) = light_push(&mut l, plane, &mut events, px - 1);
    assert_eq!((s, n, l.next), (SpivStatus::SpivErrBuffer, usize::MAX, 0));
    let (s, _) = light_push(&mut l, &plane[..PLANE / 2], &mut events, px);
    assert_eq!((s, l.next), (SpivStatus::SpivErrPlane, 0));
    let mut short = LightArrays::new(px - 1);
    let mut l = short.handle();
    // SAFETY: arrays one entry short: refused, nothing written.
    assert_eq!(
        unsafe { spiv_light_init(&mut l, W, H, 0) },
        SpivStatus::SpivErrBuffer
    );
    l.flags = ptr::null_mut();
    // SAFETY: a null array.
    assert_eq!(
        unsafe { spiv_light_init(&mut l, W, H, 0) },
        SpivStatus::SpivErrNull
    );
}

/// The event ring and the rung frames through the C ABI: the ring keeps
/// and gives back the events the core's ring keeps (in its order), and the
/// frames are the core's `rung_frames` on the same state, along a flow; a
/// short buffer, too many separations, a pair past the ring's ticks and a
/// null flow are refused.
#[test]
fn rung_frames_through_the_abi() {
    use spiv_core::light::Light;
    use spiv_core::rungs::{rung_frames, EventRing, Rungs};
    let px = usize::from(W) * usize::from(H);
    let depth = 160usize;
    let first = 70_000u32;
    let mut c = LightArrays::new(px);
    let mut l = c.handle();
    let (mut entries, mut starts) = (vec![0u32; px * 40], vec![0u32; depth + 1]);
    let mut ring = SpivRing {
        entries: entries.as_mut_ptr(),
        capacity: entries.len(),
        starts: starts.as_mut_ptr(),
        depth,
        first: 0,
        next: 0,
        stored: 0,
        lost: 0,
        evicted: 0,
    };
    // SAFETY: the arrays above, as long as said.
    unsafe {
        assert_eq!(spiv_light_init(&mut l, W, H, first), SpivStatus::SpivOk);
        assert_eq!(spiv_ring_init(&mut ring, first), SpivStatus::SpivOk);
    }
    let mut r = LightArrays::new(px);
    let state = r.state();
    let mut light = Light::new(W, H, first, state).expect("model");
    let (mut e2, mut s2) = (vec![0u32; px * 40], vec![0u32; depth + 1]);
    let mut core_ring = EventRing::new(&mut e2, &mut s2, first).expect("ring");
    for plane in strip().chunks_exact(PLANE) {
        // SAFETY: a whole plane; the arrays above.
        let s = unsafe { spiv_ring_push(&mut ring, &mut l, W, H, plane.as_ptr(), plane.len()) };
        assert_eq!(s, SpivStatus::SpivOk);
        let view = spiv_core::PlaneView::new(plane, W, H).expect("plane");
        core_ring.push(&mut light, &view).expect("push");
    }
    assert_eq!(
        (ring.first, ring.next),
        (core_ring.ticks().start, core_ring.ticks().end)
    );
    assert_eq!((ring.lost, ring.evicted), (0, 0));

    // The events of 60 ticks, in the ring's order.
    let (a, b) = (ring.next - 80, ring.next - 20);
    let mut want = Vec::new();
    core_ring.each(a, b, |e| want.push((e.index, e.tick, e.sign)));
    assert!(want.len() > 1000, "{} events", want.len());
    let mut events = vec![SpivEvent::default(); want.len()];
    let mut n = 0usize;
    // SAFETY: `events.len()` writable entries.
    let s = unsafe {
        spiv_ring_events(
            &mut ring,
            a,
            b,
            events.as_mut_ptr(),
            events.len() - 1,
            &mut n,
        )
    };
    assert_eq!((s, n), (SpivStatus::SpivErrBuffer, want.len()));
    // SAFETY: as above.
    let s = unsafe { spiv_ring_events(&mut ring, a, b, events.as_mut_ptr(), events.len(), &mut n) };
    assert_eq!((s, n), (SpivStatus::SpivOk, want.len()));
    let got: Vec<_> = events.iter().map(|e| (e.index, e.tick, e.sign)).collect();
    assert_eq!(got, want);

    // Rung frames of 8 and 32 ticks along a shear on 16-px nodes.
    let (nx, ny) = (8usize, 4usize);
    let vx: Vec<i16> = (0..nx * ny).map(|k| (k / nx) as i16 * 600 - 900).collect();
    let vy: Vec<i16> = (0..nx * ny).map(|k| (k % nx) as i16 * -150).collect();
    let ax: Vec<i16> = (0..nx * ny).map(|k| (k as i16 % 5) * 40).collect();
    let ay = vec![-30i16; nx * ny];
    let flow = SpivFlow {
        nx: nx as u16,
        ny: ny as u16,
        x0: 128,
        y0: 128,
        pitch: 256,
        vx: vx.as_ptr(),
        vy: vy.as_ptr(),
        ax: ax.as_ptr(),
        ay: ay.as_ptr(),
    };
    let seps = [8u16, 32];
    let mid = ring.next - 32 - 16;
    let mut got = vec![0i16; 4 * px];
    // SAFETY: the flow's arrays hold nx·ny entries; `got` 4·px.
    let s = unsafe {
        spiv_rung_frames(
            &mut ring,
            &mut l,
            W,
            H,
            &flow,
            mid,
            seps.as_ptr(),
            2,
            got.as_mut_ptr(),
            got.len(),
        )
    };
    assert_eq!(s, SpivStatus::SpivOk);
    let mut rungs = Rungs::events(0);
    rungs.separations[..2].copy_from_slice(&seps);
    rungs.count = 2;
    let core_flow = spiv_core::warp::Flow {
        nx: nx as u16,
        ny: ny as u16,
        x0: 128,
        y0: 128,
        pitch: 256,
        vx: &vx,
        vy: &vy,
        ax: &ax,
        ay: &ay,
    };
    let mut want = vec![0i16; 4 * px];
    rung_frames(&core_ring, &light, &core_flow, mid, &rungs, &mut want).expect("frames");
    assert_eq!(got, want);
    assert!(want.iter().filter(|&&v| v != 0).count() > 1000);

    // Refused: a frame buffer one sample short, nine separations, a pair
    // whose B frames reach past the ring, a null flow.
    let call = |flow: *const SpivFlow,
                mid: u32,
                seps: &[u16],
                len: usize,
                ring: &mut SpivRing,
                l: &mut SpivLight| {
        let mut out = vec![0i16; len];
        // SAFETY: `len` writable samples; the flow's arrays as above.
        unsafe {
            spiv_rung_frames(
                ring,
                l,
                W,
                H,
                flow,
                mid,
                seps.as_ptr(),
                seps.len(),
                out.as_mut_ptr(),
                len,
            )
        }
    };
    assert_eq!(
        call(&flow, mid, &seps, 4 * px - 1, &mut ring, &mut l),
        SpivStatus::SpivErrBuffer
    );
    assert_eq!(
        call(&flow, mid, &[4; 9], 18 * px, &mut ring, &mut l),
        SpivStatus::SpivErrConfig
    );
    assert_eq!(
        call(&flow, mid + 1, &seps, 4 * px, &mut ring, &mut l),
        SpivStatus::SpivErrTick
    );
    assert_eq!(
        call(ptr::null(), mid, &seps, 4 * px, &mut ring, &mut l),
        SpivStatus::SpivErrNull
    );
}

/// One tile through `spiv_encode_tile`: (status, encoding used, payload).
fn encode_tile(encoding: u8, samples: &[u16], width: u16, rows: u16) -> (SpivStatus, u8, Vec<u8>) {
    let mut out = vec![0u8; 4 * samples.len() + 64];
    let (mut used, mut len) = (0u8, 0usize);
    // SAFETY: the arrays are as long as the call reads and writes.
    let st = unsafe {
        spiv_encode_tile(
            encoding,
            samples.as_ptr(),
            width,
            rows,
            out.as_mut_ptr(),
            out.len(),
            &mut used,
            &mut len,
        )
    };
    out.truncate(len);
    (st, used, out)
}

/// The tile coder through the ABI: what it codes decodes to the samples
/// (Rice and Context; raw where coding would not pay: noise, and 16-bit
/// noise as two bytes per sample), and it refuses the lossy encodings,
/// empty tiles and null pointers.
#[test]
fn tiles_through_the_abi_decode_to_their_samples() {
    use spiv_core::wire::codec::decode_tile;
    use spiv_core::wire::Encoding;
    let (w, rows) = (40u16, 6u16);
    let n = usize::from(w) * usize::from(rows);
    let mut seed = 5u32;
    let mut rnd = move || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        seed >> 8
    };
    // A dark frame with a few particles; 8-bit noise; 16-bit noise.
    let particles: Vec<u16> = (0..n)
        .map(|i| {
            if i % 37 < 3 {
                200 + (i % 7) as u16
            } else {
                (i % 3) as u16
            }
        })
        .collect();
    let noise: Vec<u16> = (0..n).map(|_| (rnd() % 256) as u16).collect();
    let wide: Vec<u16> = (0..n).map(|_| (rnd() % 65_536) as u16).collect();
    for (name, samples, raw) in [
        ("particles", &particles, None),
        ("noise", &noise, Some(Encoding::Raw8)),
        ("wide", &wide, Some(Encoding::Raw16)),
    ] {
        for enc in [Encoding::Rice, Encoding::Context] {
            let (st, used, payload) = encode_tile(enc as u8, samples, w, rows);
            assert_eq!(st, SpivStatus::SpivOk, "{name}");
            let used = Encoding::from_u8(used).expect("an encoding");
            assert_eq!(used, raw.unwrap_or(enc), "{name} {enc:?}");
            if raw.is_none() {
                assert!(payload.len() < n, "{name}: {} bytes", payload.len());
            }
            let mut back = vec![0u16; n];
            decode_tile(used, &payload, w, rows, &mut [], &mut back).expect("decodes");
            assert_eq!(&back, samples, "{name} {enc:?}");
        }
    }
    for refused in [Encoding::Sparse, Encoding::SparseContext, Encoding::Raw8] {
        let (st, _, _) = encode_tile(refused as u8, &particles, w, rows);
        assert_eq!(st, SpivStatus::SpivErrConfig, "{refused:?}");
    }
    assert_eq!(
        encode_tile(3, &particles, 0, rows).0,
        SpivStatus::SpivErrConfig
    );
    let (mut used, mut len) = (0u8, 0usize);
    let mut out = [0u8; 8];
    // SAFETY: null samples are refused before anything is read.
    let st = unsafe {
        spiv_encode_tile(
            3,
            ptr::null(),
            w,
            rows,
            out.as_mut_ptr(),
            8,
            &mut used,
            &mut len,
        )
    };
    assert_eq!(st, SpivStatus::SpivErrNull);
}
