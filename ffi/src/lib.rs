//! The C ABI of `spiv-core`, for sidecar firmware written in C.
//!
//! Everything runs in one block of memory the caller supplies (a static
//! array on a device), 8-byte aligned, of the size [`spiv_memory_size`]
//! gives for a configuration: the loop state at its head, then the spike
//! history, the adaptive workspace, one frame and the sender's buffers. The
//! library never allocates and never panics; every function returns a
//! [`SpivStatus`] (0 on success, negative on refusal, named by
//! [`spiv_status_message`]).
//!
//! Two ways to drive it, one per handle:
//!
//! - **The loop** (what `spiv-firmware-sim` and the Cortex-M4 firmware run):
//!   [`spiv_push_plane`] for each spike plane; the core makes and sends every
//!   frame of the schedule ([`SpivConfig::first`], `dt`, `every`, `pairs`)
//!   through the caller's [`SpivLink`]; [`spiv_hear`] takes the host's
//!   control messages (predicted motion, window caps) from the downlink;
//!   [`spiv_finish`] sends the final status.
//! - **Frames on demand**, for firmware with its own scheduler:
//!   [`spiv_ingest`] a plane, [`spiv_make_frame`] at a tick with the caller's
//!   predictions or caps ([`SpivGuide`]), [`spiv_send_frame`] to code and
//!   frame it into wire messages.
//!
//! And, apart from any handle, the live loop's **static-light model**
//! ([`spiv_light_init`], [`spiv_light_push`]: per plane, the innovation
//! events each pixel settles) over six arrays the caller owns
//! ([`SpivLight`]): what `fpga/tb/tb_light.cpp` holds the RTL to.
//!
//! Units: ticks (one spike plane each), pixels, velocities in 1/4096 px per
//! tick, gray levels `0..=full_scale`. Planes are Vidar bit planes in stored
//! row order, `width·height/8` bytes (docs/protocol.md, docs/formats.md).
//!
//! The header `include/spiv_core.h` is generated from this file by cbindgen
//! (`SPIV_BLESS=1 cargo test -p spiv-ffi --test header`; the same test
//! fails when the committed header is stale).

// No std on the device (the crate then brings its own panic handler); the
// host build links std so the static library stands alone for `cc`.
#![cfg_attr(target_os = "none", no_std)]
// A C ABI takes raw pointers: every `unsafe` block here turns one into a
// reference or slice and says why that holds.
#![allow(unsafe_code)]

use core::ffi::{c_char, c_void};
use core::mem::{align_of, size_of};

use spiv_core::downlink::DownlinkBuffers;
use spiv_core::error::LinkError;
use spiv_core::motion::{Motion, Refine};
use spiv_core::region::Region;
use spiv_core::sidecar::{
    make_frame, Config, FrameBuffers, Guide, Memory, Probe, RefineBuffers, Sidecar,
};
use spiv_core::state::Buffers;
use spiv_core::wire::codec::Lossy;
use spiv_core::wire::control::MAX_CONTROL_ENCODED;
use spiv_core::wire::sender::{tile_rows, FrameInfo, Link, SendBuffers, Sender, Sent, Slot};
use spiv_core::wire::{frame_crc, Encoding, MAX_ENCODED, MAX_PAYLOAD};
use spiv_core::{Gray, History, Method, Params, Workspace, WorkspaceSizes};

#[cfg(target_os = "none")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    // The core returns every refusal as an error and never panics; this is
    // only the handler a no_std static library must carry.
    loop {
        core::hint::spin_loop();
    }
}

/// What a function returns: 0 on success, a negative code on refusal.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpivStatus {
    /// Success.
    SpivOk = 0,
    /// A pointer the function needs is null.
    SpivErrNull = -1,
    /// The handle is not one [`spiv_init`] made.
    SpivErrHandle = -2,
    /// The configuration is refused (size, method, encoding, window,
    /// schedule or parameter out of range).
    SpivErrConfig = -3,
    /// The memory block is too small or not 8-byte aligned.
    SpivErrMemory = -4,
    /// A plane of the wrong size.
    SpivErrPlane = -5,
    /// The tick is not in the spike history (or the tick counter would
    /// wrap).
    SpivErrTick = -6,
    /// A caller's array is shorter than the frame needs (motion rows).
    SpivErrBuffer = -7,
    /// Coding or framing a message failed.
    SpivErrWire = -8,
    /// The link's `send` returned non-zero.
    SpivErrLink = -9,
    /// The loop and frames on demand mixed on one handle, or
    /// [`spiv_send_frame`] without a frame made.
    SpivErrMode = -10,
}

/// A one-line message for a status code (a static C string).
#[no_mangle]
pub extern "C" fn spiv_status_message(status: i32) -> *const c_char {
    let s: &'static core::ffi::CStr = match status {
        0 => c"ok",
        -1 => c"a required pointer is null",
        -2 => c"not a handle made by spiv_init",
        -3 => c"configuration refused (size, method, encoding, window, schedule or parameter out of range)",
        -4 => c"memory block too small or not 8-byte aligned (see spiv_memory_size)",
        -5 => c"plane size differs from width*height/8 bytes",
        -6 => c"tick not in the spike history",
        -7 => c"an array is shorter than the frame needs",
        -8 => c"coding or framing a message failed",
        -9 => c"the link refused the bytes",
        -10 => c"loop and frames on demand mixed, or no frame to send",
        _ => c"unknown status",
    };
    s.as_ptr()
}

/// How frames are made: [`SpivConfig::method`] and
/// [`SpivConfig::bootstrap`] (the wire's method codes).
pub const SPIV_METHOD_ADAPTIVE: u8 = 0;
/// Spike count over a fixed window (TFP).
pub const SPIV_METHOD_TFP: u8 = 1;
/// Inverse inter-spike interval (TFI).
pub const SPIV_METHOD_TFI: u8 = 2;
/// Adaptive integration on motion-compensated counts.
pub const SPIV_METHOD_MC: u8 = 3;
/// Tile coding [`SpivConfig::encoding`]: one byte per sample.
pub const SPIV_ENCODING_RAW8: u8 = 1;
/// Two bytes per sample.
pub const SPIV_ENCODING_RAW16: u8 = 2;
/// Adaptive Rice code (lossless, the default).
pub const SPIV_ENCODING_RICE: u8 = 3;
/// Background at low resolution, particles exact (lossy).
pub const SPIV_ENCODING_SPARSE: u8 = 4;
/// Context-modelled range coder (lossless; about half of Rice's bytes).
pub const SPIV_ENCODING_CONTEXT: u8 = 5;
/// Sparse's frames, context-modelled range coder (lossy).
pub const SPIV_ENCODING_SPARSE_CONTEXT: u8 = 6;

/// What the sidecar does (`spiv_config_default` fills the defaults).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SpivConfig {
    /// Sensor width, pixels (`width·height` a multiple of 8).
    pub width: u16,
    /// Sensor height, pixels.
    pub height: u16,
    /// `SPIV_METHOD_*`.
    pub method: u8,
    /// Motion-compensated frames: how frames are made while no motion was
    /// heard (`SPIV_METHOD_TFP`, the default, or `SPIV_METHOD_ADAPTIVE`).
    pub bootstrap: u8,
    /// `SPIV_ENCODING_*` (lossless fallbacks apply).
    pub encoding: u8,
    /// Motion-compensated frames: 1 refines the predicted motion from the
    /// spikes before each frame (16-row bands, the core's defaults), 0 not.
    pub refine: u8,
    /// TFP window, ticks (`1..=255`).
    pub tfp_window: u16,
    /// Adaptive window limit `n_max`, ticks (`1..=255`, default 128).
    pub n_max: u16,
    /// Full-scale gray level (`1..=65535`, default 255; above 255 frames
    /// are 16-bit).
    pub full_scale: u16,
    /// Tick of the first pair's first frame.
    pub first: u32,
    /// Ticks between the frames of a pair (≥ 1).
    pub dt: u32,
    /// Ticks between pairs (≥ `dt`).
    pub every: u32,
    /// Pairs to send; 0: until the input ends.
    pub pairs: u32,
    /// A status message every this many pairs (0: only at the end).
    pub status_every: u32,
    /// Lossy coding: background block edge, px (`2..=64`).
    pub lossy_block: u8,
    /// Lossy coding: largest error of a background sample, gray levels.
    pub lossy_tolerance: u16,
    /// Lossy coding: contrast rule (0: the tolerance everywhere).
    pub lossy_contrast: u16,
    /// Lossy coding: contrast rule of motion-compensated frames.
    pub lossy_contrast_mc: u16,
}

/// Fills `out` with the defaults of `spiv-firmware-sim` for a
/// `width × height` sensor and pairs `dt` ticks apart: adaptive frames,
/// `n_max` 128, the first frame at tick 64, a pair every `4·dt`, until the
/// input ends, lossless Rice coding, a status every 16 pairs.
/// # Safety
/// `out` is writable or null.
#[no_mangle]
pub unsafe extern "C" fn spiv_config_default(
    width: u16,
    height: u16,
    dt: u32,
    out: *mut SpivConfig,
) -> SpivStatus {
    // SAFETY: the caller passes a writable SpivConfig or null.
    let Some(out) = (unsafe { out.as_mut() }) else {
        return SpivStatus::SpivErrNull;
    };
    let p = Params::default();
    let c = Config::new(u32::from(p.n_max / 2), dt);
    *out = SpivConfig {
        width,
        height,
        method: c.method.code(),
        bootstrap: c.bootstrap.code(),
        encoding: c.encoding as u8,
        refine: u8::from(c.refine.is_some()),
        tfp_window: c.tfp_window,
        n_max: p.n_max,
        full_scale: p.full_scale,
        first: c.schedule.first,
        dt: c.schedule.dt,
        every: c.schedule.every,
        pairs: c.schedule.pairs.unwrap_or(0),
        status_every: c.status_every,
        lossy_block: c.lossy.block,
        lossy_tolerance: c.lossy.tolerance,
        lossy_contrast: c.lossy.contrast,
        lossy_contrast_mc: c.lossy.contrast_mc,
    };
    SpivStatus::SpivOk
}

/// The core's configuration of a C one, checked as the loop checks it.
fn config(c: &SpivConfig) -> Result<Config, SpivStatus> {
    let bad = SpivStatus::SpivErrConfig;
    let method = Method::from_code(c.method).ok_or(bad)?;
    let bootstrap = Method::from_code(c.bootstrap).ok_or(bad)?;
    let encoding = match Encoding::from_u8(c.encoding) {
        Some(Encoding::None) | None => return Err(bad),
        Some(e) => e,
    };
    let refine = match c.refine {
        0 => None,
        1 => Some(Refine::default()),
        _ => return Err(bad),
    };
    let mut cfg = Config::new(c.first, c.dt);
    cfg.params.n_max = c.n_max;
    cfg.params.n0 = cfg.params.n0.min(c.n_max);
    cfg.params.full_scale = c.full_scale;
    cfg.method = method;
    cfg.bootstrap = bootstrap;
    cfg.encoding = encoding;
    cfg.refine = refine;
    cfg.tfp_window = c.tfp_window;
    cfg.schedule.every = c.every;
    cfg.schedule.pairs = (c.pairs > 0).then_some(c.pairs);
    cfg.status_every = c.status_every;
    cfg.lossy = Lossy {
        block: c.lossy_block,
        tolerance: c.lossy_tolerance,
        contrast: c.lossy_contrast,
        contrast_mc: c.lossy_contrast_mc,
    };
    if !(2..=64).contains(&c.lossy_block) {
        return Err(bad);
    }
    // Whole-byte planes, then the loop's own checks (window, schedule,
    // parameters, tile width).
    spiv_core::plane::plane_bytes(c.width, c.height).ok_or(bad)?;
    Sidecar::new(c.width, c.height, cfg).map_err(|_| bad)?;
    Ok(cfg)
}

/// Where one buffer sits in the block: byte offset and element count.
#[derive(Debug, Clone, Copy, Default)]
struct Span {
    off: usize,
    len: usize,
}

/// Lays buffers out one after the other, each at its type's alignment.
struct Cursor(usize);

impl Cursor {
    fn take<T>(&mut self, n: usize) -> Option<Span> {
        let off = self.0.checked_next_multiple_of(align_of::<T>())?;
        self.0 = off.checked_add(n.checked_mul(size_of::<T>())?)?;
        Some(Span { off, len: n })
    }
}

/// The block's layout for one configuration: every buffer
/// [`Config::memory_sizes`] names (as `spiv_core::buffers::SidecarBuf`
/// owns them), at its type's alignment.
#[derive(Debug, Clone, Copy)]
struct Layout {
    sizes: WorkspaceSizes,
    depth: u16,
    wide: bool,
    history: Span,
    counts: Span,
    c_t: Span,
    class: Span,
    labels: Span,
    masks: Span,
    tiles: Span,
    parents: Span,
    regions: Span,
    mc: Span,
    frame: Span,
    tfp: Span,
    payload: Span,
    wire: Span,
    scratch: Span,
    rx: Span,
    rows: [Span; 4],
    caps: [Span; 2],
    refined: [Span; 2],
    total: usize,
}

impl Layout {
    fn new(w: u16, h: u16, cfg: &Config) -> Option<Layout> {
        let m = cfg.memory_sizes(w, h)?;
        let sizes = m.workspace;
        let sp = sizes.pixels();
        let mut c = Cursor(size_of::<State>());
        Some(Layout {
            sizes,
            depth: m.depth,
            wide: m.wide,
            history: c.take::<u64>(m.history_words)?,
            masks: c.take::<u64>(sizes.mask_words())?,
            counts: c.take::<u64>(sizes.count_words())?,
            regions: c.take::<Region>(sizes.regions())?,
            labels: c.take::<u16>(sp)?,
            parents: c.take::<u16>(sizes.parents())?,
            scratch: c.take::<u16>(m.codec_scratch)?,
            frame: if m.wide {
                c.take::<u16>(m.frame)?
            } else {
                c.take::<u8>(m.frame)?
            },
            rows: [
                c.take::<i16>(m.motion_entries)?,
                c.take::<i16>(m.motion_entries)?,
                c.take::<i16>(m.motion_entries)?,
                c.take::<i16>(m.motion_entries)?,
            ],
            caps: [c.take::<u16>(m.cap_bands)?, c.take::<u16>(m.cap_bands)?],
            refined: [c.take::<i16>(m.refined)?, c.take::<i16>(m.refined)?],
            c_t: c.take::<u8>(sp)?,
            class: c.take::<u8>(sp)?,
            tiles: c.take::<u8>(sizes.tiles())?,
            mc: c.take::<u8>(m.motion_counts)?,
            tfp: c.take::<u8>(m.tfp_counts)?,
            payload: c.take::<u8>(MAX_PAYLOAD)?,
            wire: c.take::<u8>(MAX_ENCODED)?,
            rx: c.take::<u8>(MAX_CONTROL_ENCODED)?,
            total: c.0,
        })
    }
}

/// Element types a buffer of the block holds: plain integers (and the
/// region table, a struct of integers), valid for any bit pattern.
trait Plain {}
impl Plain for u8 {}
impl Plain for u16 {}
impl Plain for i16 {}
impl Plain for u64 {}
impl Plain for Region {}

/// Which of the two drivers a handle runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Fresh,
    Loop,
    Manual,
}

/// A made frame waiting for [`spiv_send_frame`].
#[derive(Debug, Clone, Copy)]
struct Made {
    tick: u32,
    method: Method,
}

/// The head of the caller's block.
#[derive(Debug)]
struct State {
    magic: u64,
    sidecar: Sidecar,
    cfg: Config,
    layout: Layout,
    width: u16,
    height: u16,
    mode: Mode,
    /// Frames on demand: the tick the next plane gets, the sender, the
    /// frame made last.
    next_tick: u32,
    sender: Sender,
    made: Option<Made>,
}

const MAGIC: u64 = 0x7370_6976_6666_6931; // "spivffi1"

/// The block's alignment, bytes.
pub const SPIV_MEMORY_ALIGN: usize = 8;

const _: () = assert!(align_of::<State>() <= SPIV_MEMORY_ALIGN);
const _: () = assert!(align_of::<Region>() <= SPIV_MEMORY_ALIGN);

/// Opaque handle: the head of the caller's memory block.
#[derive(Debug)]
pub struct SpivSidecar {
    _private: [u8; 0],
}

/// Bytes of memory a handle for `cfg` needs (8-byte aligned), into
/// `bytes`. Refuses a configuration the loop cannot run.
/// # Safety
/// `cfg` is readable and `bytes` writable (or null).
#[no_mangle]
pub unsafe extern "C" fn spiv_memory_size(cfg: *const SpivConfig, bytes: *mut usize) -> SpivStatus {
    // SAFETY: the caller passes a readable SpivConfig and a writable size,
    // or nulls.
    let (Some(c), Some(bytes)) = (unsafe { cfg.as_ref() }, unsafe { bytes.as_mut() }) else {
        return SpivStatus::SpivErrNull;
    };
    match config(c)
        .and_then(|cfg| Layout::new(c.width, c.height, &cfg).ok_or(SpivStatus::SpivErrConfig))
    {
        Ok(l) => {
            *bytes = l.total;
            SpivStatus::SpivOk
        }
        Err(e) => e,
    }
}

/// Makes a handle in `memory` (`len` bytes, 8-byte aligned, at least
/// [`spiv_memory_size`]; the block is zeroed) and writes it to `out`. The
/// block belongs to the handle until the caller stops using it; there is
/// nothing to free.
/// # Safety
/// `cfg` is readable, `out` writable (or null); `memory` holds `len`
/// writable bytes that nothing else uses while the handle lives.
#[no_mangle]
pub unsafe extern "C" fn spiv_init(
    cfg: *const SpivConfig,
    memory: *mut c_void,
    len: usize,
    out: *mut *mut SpivSidecar,
) -> SpivStatus {
    // SAFETY: readable config and writable out, or nulls.
    let (Some(c), Some(out)) = (unsafe { cfg.as_ref() }, unsafe { out.as_mut() }) else {
        return SpivStatus::SpivErrNull;
    };
    if memory.is_null() {
        return SpivStatus::SpivErrNull;
    }
    let cfg = match config(c) {
        Ok(cfg) => cfg,
        Err(e) => return e,
    };
    let Some(layout) = Layout::new(c.width, c.height, &cfg) else {
        return SpivStatus::SpivErrConfig;
    };
    if len < layout.total || !(memory as usize).is_multiple_of(SPIV_MEMORY_ALIGN) {
        return SpivStatus::SpivErrMemory;
    }
    let (Ok(sidecar), Ok(sender)) = (
        Sidecar::new(c.width, c.height, cfg),
        Sender::new(
            c.width,
            c.height,
            tile_rows(c.width, c.height, layout.wide, cfg.lossy.block),
        ),
    ) else {
        return SpivStatus::SpivErrConfig;
    };
    let base = memory.cast::<u8>();
    // SAFETY: `memory` holds `len ≥ layout.total` writable bytes (the
    // caller's promise), aligned for State (checked above); zeroing makes
    // every buffer a valid array of plain integers.
    unsafe {
        core::ptr::write_bytes(base, 0, layout.total);
        base.cast::<State>().write(State {
            magic: MAGIC,
            sidecar,
            cfg,
            layout,
            width: c.width,
            height: c.height,
            mode: Mode::Fresh,
            next_tick: 0,
            sender,
            made: None,
        });
    }
    *out = memory.cast::<SpivSidecar>();
    SpivStatus::SpivOk
}

/// The state at the head of a handle's block, and the block's base.
fn state<'h>(sc: *mut SpivSidecar) -> Result<(&'h mut State, *mut u8), SpivStatus> {
    if sc.is_null() || !(sc as usize).is_multiple_of(SPIV_MEMORY_ALIGN) {
        return Err(SpivStatus::SpivErrNull);
    }
    let base = sc.cast::<u8>();
    // SAFETY: a non-null, aligned handle points at a block spiv_init
    // wrote (the caller's promise, checked by the magic below as far as
    // that can be checked); the State occupies the block's head, apart
    // from every buffer.
    let st = unsafe { &mut *base.cast::<State>() };
    if st.magic != MAGIC {
        return Err(SpivStatus::SpivErrHandle);
    }
    Ok((st, base))
}

/// One buffer of the block as a slice.
///
/// # Safety
/// `base` is a block laid out by `layout`, `span` one of its buffers of
/// element type `T`, and no other live reference covers its bytes (the
/// layout's spans are disjoint and each is taken once per call).
unsafe fn slice<'b, T: Plain>(base: *mut u8, span: Span) -> &'b mut [T] {
    // SAFETY: in bounds and aligned by `Layout::new`, initialised by
    // spiv_init's zeroing, valid for any bit pattern (`Plain`).
    unsafe { core::slice::from_raw_parts_mut(base.add(span.off).cast::<T>(), span.len) }
}

/// Carves the block into its buffers, the history resumed at `next_tick`.
///
/// # Safety
/// `base` is the block of a live handle whose layout is `l`, and nothing
/// else borrows its buffers while the parts live.
unsafe fn parts<'b, G: Gray + Plain>(
    base: *mut u8,
    l: &Layout,
    w: u16,
    h: u16,
    next_tick: u32,
) -> Result<Memory<'b, G>, SpivStatus> {
    // SAFETY (every call below): disjoint spans of the block, each taken
    // once (the function's contract).
    let s = |span| unsafe { slice::<u8>(base, span) };
    let history = History::new(unsafe { slice(base, l.history) }, w, h, 0, h, l.depth)
        .map_err(|_| SpivStatus::SpivErrConfig)?
        .resumed(next_tick);
    let ws = Workspace::new(
        l.sizes,
        Buffers {
            counts: unsafe { slice(base, l.counts) },
            c_t: s(l.c_t),
            class: s(l.class),
            labels: unsafe { slice(base, l.labels) },
            masks: unsafe { slice(base, l.masks) },
            tiles: s(l.tiles),
            parents: unsafe { slice(base, l.parents) },
            regions: unsafe { slice(base, l.regions) },
        },
    )
    .map_err(|_| SpivStatus::SpivErrConfig)?;
    let workspace = if l.mc.len > 0 {
        ws.with_motion_counts(s(l.mc))
            .map_err(|_| SpivStatus::SpivErrConfig)?
    } else {
        ws
    };
    let i = |span| unsafe { slice::<i16>(base, span) };
    let [r0, r1, r2, r3] = l.rows;
    Ok(Memory {
        history,
        workspace,
        frame: unsafe { slice(base, l.frame) },
        counts: s(l.tfp),
        send: SendBuffers {
            payload: s(l.payload),
            wire: s(l.wire),
            scratch: unsafe { slice(base, l.scratch) },
        },
        downlink: DownlinkBuffers {
            rx: s(l.rx),
            vx: i(r0),
            vy: i(r1),
            next_vx: i(r2),
            next_vy: i(r3),
            caps: unsafe { slice(base, l.caps[0]) },
            next_caps: unsafe { slice(base, l.caps[1]) },
        },
        refine: RefineBuffers {
            vx: i(l.refined[0]),
            vy: i(l.refined[1]),
        },
    })
}

/// Description of a frame, for [`SpivLink::frame`] and [`spiv_make_frame`].
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SpivFrameInfo {
    /// Frame number in the stream (loop; frames on demand: the sender's).
    pub frame_id: u32,
    /// Pair number.
    pub pair: u32,
    /// Centre tick.
    pub tick: u32,
    /// 0: the pair's first frame, 1: its second.
    pub member: u8,
    /// `SPIV_METHOD_*` the frame was made by.
    pub method: u8,
    /// 1 (8-bit samples) or 2 (16-bit, `full_scale` above 255).
    pub bytes_per_sample: u8,
    /// CRC-32 (ISO-HDLC) of the samples as little-endian 16-bit levels,
    /// as the parity lines print it.
    pub crc: u32,
    /// Samples (`width·height`, stored row order).
    pub samples: usize,
}

/// Where wire messages go: `send` takes each whole COBS-framed message
/// (delimiter included) and returns 0, or non-zero to refuse it (the
/// function then returns [`SpivStatus::SpivErrLink`]); `frame`, if set,
/// sees every frame as sent (exactly what a receiver decodes). Both get
/// `ctx`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SpivLink {
    /// Sends one message.
    pub send: Option<unsafe extern "C" fn(ctx: *mut c_void, bytes: *const u8, len: usize) -> i32>,
    /// Sees one sent frame: its description and its samples (`uint8_t` or
    /// `uint16_t`, `info->samples` of them).
    pub frame: Option<
        unsafe extern "C" fn(ctx: *mut c_void, info: *const SpivFrameInfo, samples: *const c_void),
    >,
    /// The caller's context.
    pub ctx: *mut c_void,
}

/// The link and probe of one call.
struct CLink<'l>(&'l SpivLink);

impl Link for CLink<'_> {
    type Error = i32;
    fn send(&mut self, message: &[u8]) -> Result<(), i32> {
        let Some(f) = self.0.send else {
            return Err(-1);
        };
        // SAFETY: the caller's callback, with a valid message slice.
        match unsafe { f(self.0.ctx, message.as_ptr(), message.len()) } {
            0 => Ok(()),
            e => Err(e),
        }
    }
}

impl CLink<'_> {
    fn frame<G: Gray>(&self, info: SpivFrameInfo, frame: &[G]) {
        if let Some(f) = self.0.frame {
            // SAFETY: the caller's callback; the pointers live for the call.
            unsafe { f(self.0.ctx, &info, frame.as_ptr().cast()) }
        }
    }
}

fn describe<G: Gray>(frame_id: u32, slot: Slot, method: Method, frame: &[G]) -> SpivFrameInfo {
    SpivFrameInfo {
        frame_id,
        pair: slot.pair,
        tick: slot.tick,
        member: slot.member,
        method: method.code(),
        bytes_per_sample: size_of::<G>() as u8,
        crc: frame_crc(frame),
        samples: frame.len(),
    }
}

/// The loop's probe: hands each sent frame to the link's `frame`.
struct CProbe<'l> {
    link: &'l SpivLink,
    method: Method,
}

impl<G: Gray> Probe<G> for CProbe<'_> {
    fn sent(&mut self, frame_id: u32, slot: Slot, frame: &[G]) {
        CLink(self.link).frame(describe(frame_id, slot, self.method, frame), frame);
    }
}

fn core_status(e: spiv_core::Error) -> SpivStatus {
    use spiv_core::Error as E;
    match e {
        E::PlaneSize { .. } | E::PlaneMismatch => SpivStatus::SpivErrPlane,
        E::TickUnavailable | E::TickOverflow => SpivStatus::SpivErrTick,
        E::BufferTooSmall { .. } => SpivStatus::SpivErrBuffer,
        E::BadDimensions | E::BadBand | E::BadParam(_) | E::Config(_) => SpivStatus::SpivErrConfig,
        E::Wire(_) => SpivStatus::SpivErrWire,
    }
}

fn link_status<E>(e: LinkError<E>) -> SpivStatus {
    match e {
        LinkError::Core(c) => core_status(c),
        LinkError::Link(_) => SpivStatus::SpivErrLink,
    }
}

/// Checks and claims the handle for one driver.
fn claim<'h>(sc: *mut SpivSidecar, mode: Mode) -> Result<(&'h mut State, *mut u8), SpivStatus> {
    let (st, base) = state(sc)?;
    match st.mode {
        Mode::Fresh => st.mode = mode,
        m if m == mode => {}
        _ => return Err(SpivStatus::SpivErrMode),
    }
    Ok((st, base))
}

fn status(r: Result<(), SpivStatus>) -> SpivStatus {
    match r {
        Ok(()) => SpivStatus::SpivOk,
        Err(e) => e,
    }
}

/// A byte slice from C (`len` 0 may come with a null pointer).
///
/// # Safety
/// `ptr` points at `len` readable bytes when `len > 0`.
unsafe fn bytes<'b>(ptr: *const u8, len: usize) -> Result<&'b [u8], SpivStatus> {
    if len == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(SpivStatus::SpivErrNull);
    }
    // SAFETY: the function's contract.
    Ok(unsafe { core::slice::from_raw_parts(ptr, len) })
}

/// Takes `len` bytes from the downlink (the host's control messages, any
/// chunking): a valid control applies from the start of its pair; a
/// corrupted one is counted and never applied. The loop only.
///
/// # Safety
/// `bytes` points at `len` readable bytes.
#[no_mangle]
pub unsafe extern "C" fn spiv_hear(
    sc: *mut SpivSidecar,
    bytes: *const u8,
    len: usize,
) -> SpivStatus {
    status((|| {
        let (st, base) = claim(sc, Mode::Loop)?;
        // SAFETY: the caller's promise.
        let b = unsafe { self::bytes(bytes, len)? };
        let next = st.sidecar.next_tick();
        // SAFETY: the handle's own block; nothing else borrows it now.
        let mut p = unsafe { parts::<u8>(base, &st.layout, st.width, st.height, next)? };
        st.sidecar.hear(&mut p.downlink, b);
        Ok(())
    })())
}

fn push<G: Gray + Plain>(
    st: &mut State,
    base: *mut u8,
    plane: &[u8],
    link: &SpivLink,
) -> Result<(), SpivStatus> {
    // SAFETY: the handle's own block; nothing else borrows it now.
    let mut mem = unsafe {
        parts::<G>(
            base,
            &st.layout,
            st.width,
            st.height,
            st.sidecar.next_tick(),
        )?
    };
    let mut probe = CProbe {
        link,
        method: st.cfg.method,
    };
    st.sidecar
        .push_plane(&mut mem, plane, &mut CLink(link), &mut probe)
        .map_err(link_status)
}

/// Ingests the next spike plane (`len` = `width·height/8` bytes, stored row
/// order) and sends every frame of the schedule it completes through
/// `link`. The loop only.
///
/// # Safety
/// `plane` points at `len` readable bytes; `link` at a valid [`SpivLink`].
#[no_mangle]
pub unsafe extern "C" fn spiv_push_plane(
    sc: *mut SpivSidecar,
    plane: *const u8,
    len: usize,
    link: *const SpivLink,
) -> SpivStatus {
    status((|| {
        // SAFETY: the caller's promises.
        let (plane, link) = unsafe { (bytes(plane, len)?, link.as_ref()) };
        let link = link.ok_or(SpivStatus::SpivErrNull)?;
        let (st, base) = claim(sc, Mode::Loop)?;
        if st.layout.wide {
            push::<u16>(st, base, plane, link)
        } else {
            push::<u8>(st, base, plane, link)
        }
    })())
}

/// What was sent so far (the final status reports the same).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SpivSent {
    /// Planes ingested.
    pub planes: u32,
    /// Frames sent.
    pub frames: u32,
    /// Messages sent.
    pub messages: u32,
    /// Bytes sent.
    pub bytes: u64,
    /// Control messages applied (the loop).
    pub controls_applied: u32,
    /// Downlink chunks refused (the loop).
    pub controls_refused: u32,
}

impl From<Sent> for SpivSent {
    fn from(s: Sent) -> Self {
        SpivSent {
            planes: s.planes,
            frames: s.frames,
            messages: s.messages,
            bytes: s.bytes,
            controls_applied: s.controls_applied,
            controls_refused: s.controls_refused,
        }
    }
}

/// Sends the final status message through `link` and writes the counts to
/// `out` (may be null).
///
/// # Safety
/// `link` points at a valid [`SpivLink`]; `out` is writable or null.
#[no_mangle]
pub unsafe extern "C" fn spiv_finish(
    sc: *mut SpivSidecar,
    link: *const SpivLink,
    out: *mut SpivSent,
) -> SpivStatus {
    status((|| {
        // SAFETY: the caller's promise.
        let link = unsafe { link.as_ref() }.ok_or(SpivStatus::SpivErrNull)?;
        let (st, base) = state(sc)?;
        let mut l = CLink(link);
        // SAFETY: the handle's own block; nothing else borrows it now.
        let mut p = unsafe { parts::<u8>(base, &st.layout, st.width, st.height, 0)? };
        let sent = if st.mode == Mode::Manual {
            st.sender
                .send_status(&mut p.send, &mut l)
                .map_err(link_status)?;
            st.sender.sent
        } else {
            st.sidecar
                .finish(&mut p.send, &mut l)
                .map_err(link_status)?
        };
        // SAFETY: writable or null (the caller's promise).
        if let Some(o) = unsafe { out.as_mut() } {
            *o = sent.into();
        }
        Ok(())
    })())
}

/// Frames on demand: ingests the next spike plane (`len` =
/// `width·height/8` bytes) into the history, nothing else; returns the
/// plane's tick in `tick` (may be null).
///
/// # Safety
/// `plane` points at `len` readable bytes; `tick` is writable or null.
#[no_mangle]
pub unsafe extern "C" fn spiv_ingest(
    sc: *mut SpivSidecar,
    plane: *const u8,
    len: usize,
    tick: *mut u32,
) -> SpivStatus {
    status((|| {
        // SAFETY: the caller's promise.
        let plane = unsafe { bytes(plane, len)? };
        let (st, base) = claim(sc, Mode::Manual)?;
        // SAFETY: the handle's own block; nothing else borrows it now.
        let mut p = unsafe { parts::<u8>(base, &st.layout, st.width, st.height, st.next_tick)? };
        let view = spiv_core::PlaneView::new(plane, st.width, st.height).map_err(core_status)?;
        let t = p.history.push(&view).map_err(core_status)?;
        st.next_tick = p.history.next_tick();
        st.sender.sent.planes = st.sender.sent.planes.wrapping_add(1);
        // SAFETY: writable or null.
        if let Some(o) = unsafe { tick.as_mut() } {
            *o = t;
        }
        Ok(())
    })())
}

/// The host's word for one frame on demand; every pointer may be null
/// (with its count 0).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SpivGuide {
    /// A window limit below `n_max`, ticks (0: none).
    pub n_max: u16,
    /// Window caps per band of 32 upright rows (top band first), ticks;
    /// adaptive frames.
    pub caps: *const u16,
    /// Entries of `caps`.
    pub n_caps: usize,
    /// Predicted x velocity of each stored row and tile column
    /// (`height × cols`, row-major), 1/4096 px per tick
    /// (motion-compensated frames; null: the bootstrap method).
    pub vx: *const i16,
    /// Predicted y velocity of each stored row and tile column (down),
    /// 1/4096 px per tick.
    pub vy: *const i16,
    /// Entries of `vx` and `vy` (at least `height × cols` when given).
    pub rows: usize,
    /// Tile columns per row (0 or 1: one velocity per row).
    pub cols: u16,
    /// Tile width, px, a positive multiple of 64 (ignored for one column).
    pub tile: u16,
}

fn make<G: Gray + Plain>(
    st: &mut State,
    base: *mut u8,
    tick: u32,
    guide: &Guide<'_>,
    info: &mut SpivFrameInfo,
) -> Result<*const c_void, SpivStatus> {
    // SAFETY: the handle's own block; nothing else borrows it now.
    let mut p = unsafe { parts::<G>(base, &st.layout, st.width, st.height, st.next_tick)? };
    let method = make_frame(
        &st.cfg,
        tick,
        guide,
        &p.history,
        FrameBuffers {
            workspace: &mut p.workspace,
            counts: p.counts,
            refine: &mut p.refine,
            frame: p.frame,
        },
    )
    .map_err(core_status)?;
    st.made = Some(Made { tick, method });
    let slot = Slot {
        tick,
        pair: 0,
        member: 0,
    };
    *info = describe(st.sender.sent.frames, slot, method, p.frame);
    Ok(p.frame.as_ptr().cast())
}

/// Frames on demand: makes the frame centred at `tick` by the handle's
/// method, guided by `guide` (may be null), into
/// the handle's frame buffer. Writes its description to `info` and a
/// pointer to its samples to `frame` (valid until the next call on the
/// handle); `info->pair` and `member` are 0 here.
///
/// The window (`n_max`, or the TFP window, ticks) is clipped to the planes
/// the history holds, as at the start of a stream: make the frame when its
/// last plane, `tick + ⌈window/2⌉ − 1`, has just been ingested (the loop's
/// moment) and its whole window is there. A tick outside the history is
/// refused ([`SpivStatus::SpivErrTick`]).
///
/// # Safety
/// `guide` is null or valid with arrays of its counts; `info` and `frame`
/// are writable.
#[no_mangle]
pub unsafe extern "C" fn spiv_make_frame(
    sc: *mut SpivSidecar,
    tick: u32,
    guide: *const SpivGuide,
    info: *mut SpivFrameInfo,
    frame: *mut *const c_void,
) -> SpivStatus {
    status((|| {
        // SAFETY: the caller's promises.
        let (g, info, frame) = unsafe { (guide.as_ref(), info.as_mut(), frame.as_mut()) };
        let (Some(info), Some(frame)) = (info, frame) else {
            return Err(SpivStatus::SpivErrNull);
        };
        let (st, base) = claim(sc, Mode::Manual)?;
        let (caps, vx, vy, n_max, grid) = match g {
            None => (&[][..], None, None, 0, (1, 0)),
            // SAFETY: arrays of the guide's counts (the caller's promise).
            Some(g) => unsafe {
                let c = core::slice::from_raw_parts(nonnull(g.caps, g.n_caps)?, g.n_caps);
                let (vx, vy) = if g.rows == 0 || g.vx.is_null() || g.vy.is_null() {
                    (None, None)
                } else {
                    (
                        Some(core::slice::from_raw_parts(g.vx, g.rows)),
                        Some(core::slice::from_raw_parts(g.vy, g.rows)),
                    )
                };
                let grid = (g.cols.max(1), g.tile);
                (c, vx, vy, g.n_max, grid)
            },
        };
        let motion = match vx.zip(vy) {
            Some((vx, vy)) => {
                Some(Motion::grid(vx, vy, grid.0, grid.1).map_err(|_| SpivStatus::SpivErrConfig)?)
            }
            None => None,
        };
        let guide = Guide {
            n_max: (n_max > 0).then_some(n_max),
            caps,
            motion,
        };
        *frame = if st.layout.wide {
            make::<u16>(st, base, tick, &guide, info)?
        } else {
            make::<u8>(st, base, tick, &guide, info)?
        };
        Ok(())
    })())
}

/// `ptr`, or a dangling aligned pointer when `n` is 0 (a valid empty
/// slice); null with `n > 0` is refused.
fn nonnull<T>(ptr: *const T, n: usize) -> Result<*const T, SpivStatus> {
    match (ptr.is_null(), n) {
        (_, 0) => Ok(core::ptr::NonNull::dangling().as_ptr()),
        (true, _) => Err(SpivStatus::SpivErrNull),
        (false, _) => Ok(ptr),
    }
}

fn send_made<G: Gray + Plain>(
    st: &mut State,
    base: *mut u8,
    made: Made,
    pair: u32,
    member: u8,
    link: &SpivLink,
) -> Result<(), SpivStatus> {
    // SAFETY: the handle's own block; nothing else borrows it now.
    let mut p = unsafe { parts::<G>(base, &st.layout, st.width, st.height, st.next_tick)? };
    let slot = Slot {
        tick: made.tick,
        pair,
        member,
    };
    let info = FrameInfo {
        slot,
        method: made.method,
        full_scale: st.cfg.params.full_scale,
        dt: st.cfg.schedule.dt,
    };
    let frame_id = st.sender.sent.frames;
    let mut l = CLink(link);
    st.sender
        .send_frame(
            &mut p.send,
            p.frame,
            &info,
            st.cfg.encoding,
            &st.cfg.lossy,
            &mut l,
        )
        .map_err(link_status)?;
    l.frame(describe(frame_id, slot, made.method, p.frame), p.frame);
    Ok(())
}

/// Frames on demand: codes the frame [`spiv_make_frame`] made last into
/// wire messages (tiles and a frame end naming `pair` and `member`, 0 or 1)
/// and sends them through `link`. A lossy encoding leaves the frame as the
/// receiver decodes it.
///
/// # Safety
/// `link` points at a valid [`SpivLink`].
#[no_mangle]
pub unsafe extern "C" fn spiv_send_frame(
    sc: *mut SpivSidecar,
    pair: u32,
    member: u8,
    link: *const SpivLink,
) -> SpivStatus {
    status((|| {
        // SAFETY: the caller's promise.
        let link = unsafe { link.as_ref() }.ok_or(SpivStatus::SpivErrNull)?;
        let (st, base) = claim(sc, Mode::Manual)?;
        let made = st.made.ok_or(SpivStatus::SpivErrMode)?;
        if member > 1 {
            return Err(SpivStatus::SpivErrConfig);
        }
        if st.layout.wide {
            send_made::<u16>(st, base, made, pair, member, link)
        } else {
            send_made::<u8>(st, base, made, pair, member, link)
        }
    })())
}

/// Frames on demand: the ticks of the next plane ([`spiv_ingest`] gives it
/// this one); the loop: the tick its next plane gets.
/// # Safety
/// `sc` is a handle from [`spiv_init`] (or null); `tick` writable or null.
#[no_mangle]
pub unsafe extern "C" fn spiv_next_tick(sc: *mut SpivSidecar, tick: *mut u32) -> SpivStatus {
    status((|| {
        let (st, _) = state(sc)?;
        // SAFETY: writable or null.
        let t = unsafe { tick.as_mut() }.ok_or(SpivStatus::SpivErrNull)?;
        *t = if st.mode == Mode::Manual {
            st.next_tick
        } else {
            st.sidecar.next_tick()
        };
        Ok(())
    })())
}

/// True (1) once every scheduled pair of the loop was sent.
/// # Safety
/// `sc` is a handle from [`spiv_init`] (or null).
#[no_mangle]
pub unsafe extern "C" fn spiv_done(sc: *mut SpivSidecar) -> i32 {
    state(sc).map_or(0, |(st, _)| i32::from(st.sidecar.done()))
}

/// What the downlink heard: valid controls, controls applied, chunks
/// refused (any pointer may be null).
/// # Safety
/// `sc` is a handle from [`spiv_init`] (or null); the outputs writable or
/// null.
#[no_mangle]
pub unsafe extern "C" fn spiv_downlink(
    sc: *mut SpivSidecar,
    heard: *mut u32,
    applied: *mut u32,
    refused: *mut u32,
) -> SpivStatus {
    status((|| {
        let (st, _) = state(sc)?;
        let d = st.sidecar.downlink();
        // SAFETY: each writable or null.
        unsafe {
            for (p, v) in [(heard, d.heard), (applied, d.applied), (refused, d.refused)] {
                if let Some(p) = p.as_mut() {
                    *p = v;
                }
            }
        }
        Ok(())
    })())
}

/// The static-light model's per-pixel state in the caller's arrays, each
/// of at least `len ≥ width·height` entries ([`spiv_core::light`]: last
/// spike tick mod 2¹⁶, period in 1/16 tick, mean rate in 2⁻²⁴ spikes per
/// tick, ticks of short intervals, lead in 1/16 tick, flags), and where
/// the model stands: the tick the next plane gets and the ticks seen.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SpivLight {
    /// Tick of each pixel's last spike, mod 2¹⁶.
    pub last: *mut u16,
    /// Period estimate, 1/16 tick (0: none).
    pub period: *mut u16,
    /// Mean rate, 2⁻²⁴ spikes per tick.
    pub rate: *mut u32,
    /// Ticks of short intervals since the last agreeing one.
    pub short_run: *mut u16,
    /// The spike train's lead on its period chain, 1/16 tick.
    pub lead: *mut i8,
    /// Bit 7: has spiked; bits 0–3: agreements with the period.
    pub flags: *mut u8,
    /// Entries in each array.
    pub len: usize,
    /// The tick the next plane gets.
    pub next: u32,
    /// Ticks taken so far.
    pub seen: u32,
}

/// One innovation event: pixel `index` (stored row-major) at `tick`,
/// `sign` +1 (a spike the static light did not predict) or −1 (a
/// predicted spike that did not come).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct SpivEvent {
    /// Pixel, stored row-major.
    pub index: u32,
    /// Tick of the spike or of the prediction.
    pub tick: u32,
    /// +1 or −1.
    pub sign: i8,
}

/// The light model's state borrowed from `l`.
///
/// # Safety
/// Each array of `l` holds `l.len` writable entries that nothing else
/// uses during the call.
unsafe fn light_state<'s>(l: &SpivLight) -> Result<spiv_core::light::LightState<'s>, SpivStatus> {
    if l.last.is_null()
        || l.period.is_null()
        || l.rate.is_null()
        || l.short_run.is_null()
        || l.lead.is_null()
        || l.flags.is_null()
    {
        return Err(SpivStatus::SpivErrNull);
    }
    // SAFETY: the function's contract: six arrays of `len` entries.
    unsafe {
        Ok(spiv_core::light::LightState {
            last: core::slice::from_raw_parts_mut(l.last, l.len),
            period: core::slice::from_raw_parts_mut(l.period, l.len),
            rate: core::slice::from_raw_parts_mut(l.rate, l.len),
            short: core::slice::from_raw_parts_mut(l.short_run, l.len),
            lead: core::slice::from_raw_parts_mut(l.lead, l.len),
            flags: core::slice::from_raw_parts_mut(l.flags, l.len),
        })
    }
}

/// The light model in `l`'s arrays, where `l` says it stands.
///
/// # Safety
/// As for [`light_state`].
unsafe fn resumed_light<'s>(
    l: &SpivLight,
    width: u16,
    height: u16,
) -> Result<spiv_core::light::Light<'s>, SpivStatus> {
    // SAFETY: the function's contract.
    let state = unsafe { light_state(l)? };
    let clock = spiv_core::light::LightClock {
        next: l.next,
        seen: l.seen,
    };
    spiv_core::light::Light::resume(width, height, clock, state).map_err(core_status)
}

/// Records in `l` where the model now stands.
fn keep_clock(l: &mut SpivLight, c: spiv_core::light::LightClock) {
    l.next = c.next;
    l.seen = c.seen;
}

impl From<spiv_core::light::Event> for SpivEvent {
    fn from(e: spiv_core::light::Event) -> SpivEvent {
        SpivEvent {
            index: e.index,
            tick: e.tick,
            sign: e.sign,
        }
    }
}

/// Starts the static-light model of a `width × height` sensor in `l`'s
/// arrays (cleared), the first plane pushed getting tick `first`.
///
/// # Safety
/// `l` is writable and its arrays hold `l.len` writable entries each.
#[no_mangle]
pub unsafe extern "C" fn spiv_light_init(
    l: *mut SpivLight,
    width: u16,
    height: u16,
    first: u32,
) -> SpivStatus {
    status((|| {
        // SAFETY: writable or null.
        let l = unsafe { l.as_mut() }.ok_or(SpivStatus::SpivErrNull)?;
        // SAFETY: the caller's promise on the arrays.
        let state = unsafe { light_state(l)? };
        let light =
            spiv_core::light::Light::new(width, height, first, state).map_err(core_status)?;
        keep_clock(l, light.clock());
        Ok(())
    })())
}

/// Takes the next spike plane (`len` = `width·height/8` bytes) into the
/// light model `l` and writes the events it settles to `events` (room for
/// `cap`, at least `width·height`: a pixel settles one event per plane at
/// most), their number to `n`: +1 events of this plane's tick and −1
/// events of earlier ticks, in pixel order. Refused before anything
/// changes when `cap` is short.
///
/// # Safety
/// `l` as for [`spiv_light_init`]; `plane` holds `len` readable bytes;
/// `events` holds `cap` writable entries; `n` is writable.
#[no_mangle]
pub unsafe extern "C" fn spiv_light_push(
    l: *mut SpivLight,
    width: u16,
    height: u16,
    plane: *const u8,
    len: usize,
    events: *mut SpivEvent,
    cap: usize,
    n: *mut usize,
) -> SpivStatus {
    status((|| {
        // SAFETY: writable or null.
        let (l, n) = match unsafe { (l.as_mut(), n.as_mut()) } {
            (Some(l), Some(n)) => (l, n),
            _ => return Err(SpivStatus::SpivErrNull),
        };
        // SAFETY: the caller's promise.
        let plane = unsafe { bytes(plane, len)? };
        let view = spiv_core::PlaneView::new(plane, width, height).map_err(core_status)?;
        if cap < usize::from(width) * usize::from(height) {
            return Err(SpivStatus::SpivErrBuffer);
        }
        if events.is_null() {
            return Err(SpivStatus::SpivErrNull);
        }
        // SAFETY: `cap` writable entries (the caller's promise).
        let out = unsafe { core::slice::from_raw_parts_mut(events, cap) };
        // SAFETY: the caller's promise on the arrays.
        let mut light = unsafe { resumed_light(l, width, height)? };
        let mut k = 0usize;
        light
            .push(&view, |e| {
                if let Some(slot) = out.get_mut(k) {
                    *slot = e.into();
                }
                k += 1;
            })
            .map_err(core_status)?;
        keep_clock(l, light.clock());
        *n = k.min(cap);
        Ok(())
    })())
}

/// An event ring over the caller's arrays ([`spiv_core::rungs::EventRing`]):
/// `entries` (`capacity` ≥ 1 events, 4 bytes each) and `starts` (`depth + 1`
/// entries, `depth` ≥ 1 ticks), and where it stands.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SpivRing {
    /// The events, a circular buffer.
    pub entries: *mut u32,
    /// Events `entries` holds.
    pub capacity: usize,
    /// The running count of events before each tick held.
    pub starts: *mut u32,
    /// Ticks the ring holds at most (`starts` holds one more entry).
    pub depth: usize,
    /// Oldest tick held.
    pub first: u32,
    /// The next tick.
    pub next: u32,
    /// Events stored so far.
    pub stored: u32,
    /// Events that did not fit.
    pub lost: u32,
    /// Ticks dropped to make room.
    pub evicted: u32,
}

/// A steady flow on a grid of nodes ([`spiv_core::warp::Flow`]): `nx × ny`
/// nodes (0 across or down: no motion), node `(r, c)` at `(x0 + c·pitch,
/// y0 + r·pitch)` in 1/16 px, velocities in 1/4096 px per tick and
/// accelerations in 1/65536 px per tick², each array `nx·ny` entries,
/// row-major.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SpivFlow {
    /// Nodes across.
    pub nx: u16,
    /// Nodes down.
    pub ny: u16,
    /// x of column 0, 1/16 px.
    pub x0: i32,
    /// y of row 0, 1/16 px.
    pub y0: i32,
    /// Node spacing, 1/16 px (16..=4096).
    pub pitch: u16,
    /// x velocity, Q12 px per tick.
    pub vx: *const i16,
    /// y velocity, Q12 px per tick.
    pub vy: *const i16,
    /// x acceleration along the path, Q16 px per tick².
    pub ax: *const i16,
    /// y acceleration along the path, Q16 px per tick².
    pub ay: *const i16,
}

/// The ring `r` over its arrays.
///
/// # Safety
/// `r`'s arrays hold `capacity` and `depth + 1` writable entries that
/// nothing else uses during the call.
unsafe fn ring_arrays<'s>(r: &SpivRing) -> Result<(&'s mut [u32], &'s mut [u32]), SpivStatus> {
    if r.entries.is_null() || r.starts.is_null() {
        return Err(SpivStatus::SpivErrNull);
    }
    let depth = r.depth.checked_add(1).ok_or(SpivStatus::SpivErrConfig)?;
    // SAFETY: the function's contract.
    unsafe {
        Ok((
            core::slice::from_raw_parts_mut(r.entries, r.capacity),
            core::slice::from_raw_parts_mut(r.starts, depth),
        ))
    }
}

/// The ring in `r`'s arrays, where `r` says it stands.
///
/// # Safety
/// As for [`ring_arrays`].
unsafe fn resumed_ring<'s>(r: &SpivRing) -> Result<spiv_core::rungs::EventRing<'s>, SpivStatus> {
    // SAFETY: the function's contract.
    let (entries, starts) = unsafe { ring_arrays(r)? };
    let at = spiv_core::rungs::RingCursor {
        first: r.first,
        next: r.next,
        stored: r.stored,
        lost: r.lost,
        evicted: r.evicted,
    };
    spiv_core::rungs::EventRing::resume(entries, starts, at).map_err(core_status)
}

/// Records in `r` where the ring now stands.
fn keep_cursor(r: &mut SpivRing, c: spiv_core::rungs::RingCursor) {
    (r.first, r.next, r.stored, r.lost, r.evicted) = (c.first, c.next, c.stored, c.lost, c.evicted);
}

/// Starts an empty ring in `r`'s arrays, its first tick `first` (the light
/// model's next tick).
///
/// # Safety
/// `r` is writable and its arrays hold `capacity` and `depth + 1`
/// writable entries.
#[no_mangle]
pub unsafe extern "C" fn spiv_ring_init(r: *mut SpivRing, first: u32) -> SpivStatus {
    status((|| {
        // SAFETY: writable or null.
        let r = unsafe { r.as_mut() }.ok_or(SpivStatus::SpivErrNull)?;
        // SAFETY: the caller's promise.
        let (entries, starts) = unsafe { ring_arrays(r)? };
        let c = spiv_core::rungs::EventRing::new(entries, starts, first)
            .map_err(core_status)?
            .cursor();
        keep_cursor(r, c);
        Ok(())
    })())
}

/// Takes the next spike plane (`len` = `width·height/8` bytes) through the
/// light model `l` into the ring `r` (`EventRing::push`): the ring keeps
/// the events the plane settles, dropping its oldest ticks when full.
///
/// # Safety
/// `r` as for [`spiv_ring_init`], `l` as for [`spiv_light_init`];
/// `plane` holds `len` readable bytes.
#[no_mangle]
pub unsafe extern "C" fn spiv_ring_push(
    r: *mut SpivRing,
    l: *mut SpivLight,
    width: u16,
    height: u16,
    plane: *const u8,
    len: usize,
) -> SpivStatus {
    status((|| {
        // SAFETY: writable or null.
        let (r, l) = match unsafe { (r.as_mut(), l.as_mut()) } {
            (Some(r), Some(l)) => (r, l),
            _ => return Err(SpivStatus::SpivErrNull),
        };
        // SAFETY: the caller's promise.
        let plane = unsafe { bytes(plane, len)? };
        let view = spiv_core::PlaneView::new(plane, width, height).map_err(core_status)?;
        // SAFETY: the caller's promise on the arrays.
        let mut ring = unsafe { resumed_ring(r)? };
        // SAFETY: the caller's promise on the arrays.
        let mut light = unsafe { resumed_light(l, width, height)? };
        ring.push(&mut light, &view).map_err(core_status)?;
        keep_cursor(r, ring.cursor());
        keep_clock(l, light.clock());
        Ok(())
    })())
}

/// Writes the events of ticks `a..b` that the ring `r` holds to `events`
/// (room for `cap`), in the order the ring stores them — the order
/// [`spiv_rung_frames`] adds them in — and their number to `n`. Refused
/// (`SPIV_ERR_BUFFER`, `n` the number needed) when `cap` is short.
///
/// # Safety
/// `r` as for [`spiv_ring_init`]; `events` holds `cap` writable entries;
/// `n` is writable.
#[no_mangle]
pub unsafe extern "C" fn spiv_ring_events(
    r: *mut SpivRing,
    a: u32,
    b: u32,
    events: *mut SpivEvent,
    cap: usize,
    n: *mut usize,
) -> SpivStatus {
    status((|| {
        // SAFETY: writable or null.
        let (r, n) = match unsafe { (r.as_ref(), n.as_mut()) } {
            (Some(r), Some(n)) => (r, n),
            _ => return Err(SpivStatus::SpivErrNull),
        };
        if events.is_null() && cap > 0 {
            return Err(SpivStatus::SpivErrNull);
        }
        let out: &mut [SpivEvent] = if cap == 0 {
            &mut []
        } else {
            // SAFETY: `cap` writable entries (the caller's promise).
            unsafe { core::slice::from_raw_parts_mut(events, cap) }
        };
        // SAFETY: the caller's promise on the arrays.
        let ring = unsafe { resumed_ring(r)? };
        let mut k = 0usize;
        ring.each(a, b, |e| {
            if let Some(slot) = out.get_mut(k) {
                *slot = e.into();
            }
            k += 1;
        });
        *n = k;
        if k > cap {
            return Err(SpivStatus::SpivErrBuffer);
        }
        Ok(())
    })())
}

/// Makes the rung frames of the pair whose midpoint is tick `mid` from the
/// ring `r` and the light model `l` as they stand, warped along `flow`
/// ([`spiv_core::rungs::rung_frames`]): for the `i`-th of the `count`
/// separations in `separations` (2..=255 ticks, at most 8), frame A
/// (`frames[2i·width·height..]`) and frame B (the next `width·height`
/// samples), in 1/64 spike, whole spikes, 0 below the rung's floor.
/// `len` is the room in `frames` (at least `2·count·width·height`).
///
/// # Safety
/// `r` as for [`spiv_ring_init`], `l` as for [`spiv_light_init`]; `flow`
/// readable, its arrays `nx·ny` readable entries each; `separations`
/// `count` readable entries; `frames` `len` writable entries.
#[no_mangle]
pub unsafe extern "C" fn spiv_rung_frames(
    r: *mut SpivRing,
    l: *mut SpivLight,
    width: u16,
    height: u16,
    flow: *const SpivFlow,
    mid: u32,
    separations: *const u16,
    count: usize,
    frames: *mut i16,
    len: usize,
) -> SpivStatus {
    status((|| {
        // SAFETY: each readable or null.
        let (r, l, f) = match unsafe { (r.as_ref(), l.as_ref(), flow.as_ref()) } {
            (Some(r), Some(l), Some(f)) => (r, l, f),
            _ => return Err(SpivStatus::SpivErrNull),
        };
        if count > spiv_core::rungs::MAX_RUNGS {
            return Err(SpivStatus::SpivErrConfig);
        }
        let seps = nonnull(separations, count)?;
        let mut rungs = spiv_core::rungs::Rungs::events(0);
        // SAFETY: `count` readable entries (the caller's promise).
        let given = unsafe { core::slice::from_raw_parts(seps, count) };
        rungs.separations[..count].copy_from_slice(given);
        rungs.count = count as u8;
        let nodes = usize::from(f.nx) * usize::from(f.ny);
        let arr = |p: *const i16| -> Result<&[i16], SpivStatus> {
            let p = nonnull(p, nodes)?;
            // SAFETY: `nx·ny` readable entries (the caller's promise).
            Ok(unsafe { core::slice::from_raw_parts(p, nodes) })
        };
        let flow = spiv_core::warp::Flow {
            nx: f.nx,
            ny: f.ny,
            x0: f.x0,
            y0: f.y0,
            pitch: f.pitch,
            vx: arr(f.vx)?,
            vy: arr(f.vy)?,
            ax: arr(f.ax)?,
            ay: arr(f.ay)?,
        };
        if frames.is_null() {
            return Err(SpivStatus::SpivErrNull);
        }
        // SAFETY: `len` writable entries (the caller's promise).
        let out = unsafe { core::slice::from_raw_parts_mut(frames, len) };
        // SAFETY: the caller's promise on the arrays.
        let ring = unsafe { resumed_ring(r)? };
        // SAFETY: the caller's promise on the arrays.
        let light = unsafe { resumed_light(l, width, height)? };
        spiv_core::rungs::rung_frames(&ring, &light, &flow, mid, &rungs, out).map_err(core_status)
    })())
}

/// Codes one tile, the band `samples` of `rows × width` levels (row by
/// row), as the wire codes it ([`spiv_core::wire::codec::encode_tile`])
/// with the lossless encoding `encoding` (`SPIV_ENCODING_RICE` or
/// `SPIV_ENCODING_CONTEXT`): the encoding it took (`*used`: the one asked
/// for, or raw where that would not be shorter than the raw tile) and the
/// payload in `out[..*len]`. `cap` is the room in `out`.
///
/// # Safety
/// `samples` `width·rows` readable entries; `out` `cap` writable bytes;
/// `used` and `len` writable.
#[no_mangle]
pub unsafe extern "C" fn spiv_encode_tile(
    encoding: u8,
    samples: *const u16,
    width: u16,
    rows: u16,
    out: *mut u8,
    cap: usize,
    used: *mut u8,
    len: *mut usize,
) -> SpivStatus {
    status((|| {
        let want = match Encoding::from_u8(encoding) {
            Some(e @ (Encoding::Rice | Encoding::Context)) => e,
            _ => return Err(SpivStatus::SpivErrConfig),
        };
        if width == 0 || rows == 0 {
            return Err(SpivStatus::SpivErrConfig);
        }
        let n = usize::from(width) * usize::from(rows);
        let p = nonnull(samples, n)?;
        if out.is_null() || used.is_null() || len.is_null() {
            return Err(SpivStatus::SpivErrNull);
        }
        // SAFETY: `width·rows` readable entries, `cap` writable bytes (the
        // caller's promise).
        let (given, dst) = unsafe {
            (
                core::slice::from_raw_parts(p, n),
                core::slice::from_raw_parts_mut(out, cap),
            )
        };
        let lossy = spiv_core::wire::codec::Lossy::DEFAULT;
        let (enc, n) =
            spiv_core::wire::codec::encode_tile(want, given, width, rows, &lossy, &mut [], dst)
                .map_err(core_status)?;
        // SAFETY: writable (the caller's promise), checked non-null above.
        unsafe {
            *used = enc as u8;
            *len = n;
        }
        Ok(())
    })())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_spans_are_disjoint_aligned_and_sum_to_total() {
        let cfg = Config::new(64, 13);
        let l = Layout::new(128, 64, &cfg).unwrap();
        let spans: [(Span, usize, usize); 8] = [
            (l.history, 8, 8),
            (l.masks, 8, 8),
            (l.regions, size_of::<Region>(), align_of::<Region>()),
            (l.labels, 2, 2),
            (l.counts, 8, 8),
            (l.frame, 1, 1),
            (l.payload, 1, 1),
            (l.rx, 1, 1),
        ];
        let mut end = size_of::<State>();
        for (s, size, align) in spans {
            assert_eq!(s.off % align, 0);
            assert!(s.off >= size_of::<State>());
            end = end.max(s.off + s.len * size);
        }
        assert!(end <= l.total);
        assert_eq!(l.history.len, History::words_needed(128, 64, 128).unwrap());
    }

    #[test]
    fn sizes_that_overflow_are_refused_not_wrapped() {
        let mut c = SpivConfig {
            width: 0,
            height: 0,
            method: 0,
            bootstrap: 0,
            encoding: 0,
            refine: 0,
            tfp_window: 0,
            n_max: 0,
            full_scale: 0,
            first: 0,
            dt: 0,
            every: 0,
            pairs: 0,
            status_every: 0,
            lossy_block: 0,
            lossy_tolerance: 0,
            lossy_contrast: 0,
            lossy_contrast_mc: 0,
        };
        // SAFETY: a writable config.
        let s = unsafe { spiv_config_default(u16::MAX, u16::MAX, 13, &mut c) };
        assert_eq!(s, SpivStatus::SpivOk);
        let mut n = 0usize;
        // 65535² px: representable on a 64-bit host, refused by the row
        // width check (a tile row must fit a message), never wrapped.
        // SAFETY: a readable config, a writable size.
        let s = unsafe { spiv_memory_size(&c, &mut n) };
        assert!(s == SpivStatus::SpivOk || s == SpivStatus::SpivErrConfig);
        if s == SpivStatus::SpivOk {
            assert!(n > usize::from(u16::MAX) * usize::from(u16::MAX));
        }
    }
}
