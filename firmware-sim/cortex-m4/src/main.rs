//! spiv-core on a Cortex-M4F (QEMU `mps2-an386`): the sidecar's real
//! pipeline on a committed spike strip — planes into the history ring,
//! segmentation, background suppression, adaptive integration, one frame
//! pair, tile coding and wire framing — through the core's sidecar loop
//! (`spiv_core::sidecar`), the very loop `spiv-firmware-sim` runs, so both
//! print the same parity line:
//!
//! ```text
//! planes=… frames=… messages=… bytes=… stream_crc=… frame_crcs=…,…
//! ```
//!
//! (`spiv-firmware-sim --input data/strip.dat --pairs 1 --checksum` on the
//! host). Then it runs the loop again with motion-compensated frames
//! (`Method::Mc`, refine on), hearing the committed control message
//! (`data/control.bin`: the strip's true motion per row in two 64-px
//! tile columns, from pair 0)
//! before the first plane, and prints that run's line after `mc `
//! (`spiv-firmware-sim --method mc --control data/control.bin …`,
//! `expected-mc.txt`). Both runs share one set of statics, sized for the
//! larger (motion-compensated) region tables.
//!
//! It also prints the RAM it reserves and checks the core's
//! documented bytes per pixel against it, then exits 0 through semihosting,
//! or 1 on any error. The `spiv_mark_*` functions, called by the loop's
//! probe, bracket the kernels for `cost.sh`, which counts QEMU's executed
//! instructions between them.
//!
//! All buffers are statics sized by the core's `const fn`s: no heap, no
//! allocation, nothing sized at run time.

#![no_std]
#![no_main]

use core::convert::Infallible;

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
use spiv_core::downlink::DownlinkBuffers;
use spiv_core::error::LinkError;
use spiv_core::light::{Light, LightState};
use spiv_core::motion::Refine;
use spiv_core::plane::PlaneView;
use spiv_core::region::Region;
use spiv_core::rungs::{rung_frames, EventRing, Rungs};
use spiv_core::sidecar::{Config, Memory, Probe, RefineBuffers, Sidecar, Stage, CAP_BAND};
use spiv_core::state::{Buffers, STATE_MILLIBYTES_PER_PIXEL};
use spiv_core::warp::Flow;
use spiv_core::wire::codec::{encode_tile, tile_scratch, Lossy};
use spiv_core::wire::control::MAX_CONTROL_ENCODED;
use spiv_core::wire::sender::{tile_rows, Link, SendBuffers, Slot};
use spiv_core::wire::Encoding;
use spiv_core::wire::{frame_crc, MAX_ENCODED, MAX_PAYLOAD};
use spiv_core::{History, Params, Workspace, WorkspaceSizes};

/// The strip: 128 × 64 px of the default `paper-linear` scene (glare band
/// and moving particles), 144 planes, stored row order (`data/scene.json`).
const W: u16 = 128;
const H: u16 = 64;
const PX: usize = W as usize * H as usize;
const PLANE_BYTES: usize = PX / 8;
static STRIP: &[u8] = include_bytes!("../data/strip.dat");
/// The host's control for the motion-compensated run: the strip's true
/// velocity of every stored row in each 64-px tile column, applying from
/// pair 0
/// (`firmware-sim/tests/m4_parity.rs` rebuilds it from `data/scene.json`).
static CONTROL: &[u8] = include_bytes!("../data/control.bin");

/// Ticks between the frames of the pair (the strip's `scene.json`).
const DT: u32 = 13;
/// History depth = the adaptive window limit n_max (the default 128).
const DEPTH: u16 = 128;
const HIST_WORDS: usize = match History::words_needed(W, H, DEPTH) {
    Some(n) => n,
    None => 0,
};
const SIZES: WorkspaceSizes = WorkspaceSizes::for_strip(W, H);
/// Motion-compensated frames find more regions (1 per 16 px).
const MC_SIZES: WorkspaceSizes = WorkspaceSizes::for_motion(W, H);
/// Velocity entries of a motion: every stored row in every 64-px tile
/// column, the finest grid a control may carry.
const GRID: usize = H as usize * W.div_ceil(64) as usize;
const CAP_BANDS: usize = H.div_ceil(CAP_BAND) as usize;

const EMPTY_REGION: Region = Region {
    pixels: 0,
    ring_pixels: 0,
    ring_sum: 0,
    row0: 0,
    row1: 0,
    col0: 0,
    col1: 0,
    n_star: 0,
    win_len: 0,
    max_count: 0,
    root: 0,
};

/// The static-light model, its event ring and the rung frames ([`light`])
/// over the strip's bottom 32 stored rows (the glare band) and its first
/// [`LIGHT_PLANES`] planes: rows, pixels, events held, ticks of ring, rungs.
const LIGHT_H: u16 = 32;
const LIGHT_PX: usize = W as usize * LIGHT_H as usize;
const LIGHT_PLANES: usize = 104;
const LIGHT_EVENTS: usize = 16_384;
const LIGHT_TICKS: usize = 105;
const LIGHT_RUNGS: [u16; 4] = [4, 8, 16, 32];
/// The pair's midpoint: the longest rung and the events' tolerance fit on
/// both sides within the planes read.
const LIGHT_MID: u32 = 52;
/// The flow the rung frames are warped along: 0.5 px per tick right at
/// every node of a 2 × 2 grid over the strip (Q12 px per tick).
const LIGHT_VX: [i16; 4] = [2048; 4];

/// What the light kernels use ([`light`]): the model's state, the ring and
/// the frames.
struct LightRam {
    last: [u16; LIGHT_PX],
    period: [u16; LIGHT_PX],
    rate: [u32; LIGHT_PX],
    short: [u16; LIGHT_PX],
    lead: [i8; LIGHT_PX],
    flags: [u8; LIGHT_PX],
    entries: [u32; LIGHT_EVENTS],
    starts: [u32; LIGHT_TICKS],
    frames: [i16; 2 * LIGHT_RUNGS.len() * LIGHT_PX],
}

/// Every byte of RAM the pipeline uses besides the stack.
struct Ram {
    history: [u64; HIST_WORDS],
    counts: [u64; SIZES.count_words()],
    c_t: [u8; PX],
    class: [u8; PX],
    labels: [u16; PX],
    masks: [u64; SIZES.mask_words()],
    tiles: [u8; SIZES.tiles()],
    /// Sized for the larger, motion-compensated tables; the adaptive run
    /// takes the first `SIZES.parents()` / `SIZES.regions()`.
    parents: [u16; MC_SIZES.parents()],
    regions: [Region; MC_SIZES.regions()],
    frame: [u8; PX],
    payload: [u8; MAX_PAYLOAD],
    wire: [u8; MAX_ENCODED],
    /// Motion-compensated counts (the particle test's).
    mc: [u8; PX],
    /// The downlink: receive buffer, applied and waiting rows and caps.
    control_rx: [u8; MAX_CONTROL_ENCODED],
    rows: [[i16; GRID]; 4],
    caps: [[u16; CAP_BANDS]; 2],
    /// Refined velocities.
    refined: [[i16; GRID]; 2],
    /// The tile codecs' scratch (the largest: `SparseContext`).
    codec_scratch: [u16; CODEC_SCRATCH],
}

/// Scratch of the `SparseContext` codec for one tile of the strip.
const CODEC_SCRATCH: usize = tile_scratch(
    Encoding::SparseContext,
    W,
    tile_rows(W, H, false, Lossy::DEFAULT.block),
    Lossy::DEFAULT.block,
);

static CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The link: a running CRC-32 of the message stream (a real sidecar would
/// queue the bytes on its USB bulk IN endpoint here).
struct CrcLink {
    digest: crc::Digest<'static, u32>,
}

impl Link for CrcLink {
    type Error = Infallible;
    fn send(&mut self, message: &[u8]) -> Result<(), Infallible> {
        // The parity checksum is not the sidecar's work: cost.sh counts it
        // apart from the sender.
        spiv_mark_link_begin();
        self.digest.update(message);
        spiv_mark_link_end();
        Ok(())
    }
}

/// Cost markers for `cost.sh`: empty functions with stable symbols, given
/// distinct bodies so the linker never folds them together.
macro_rules! markers {
    ($($name:ident = $id:literal),* $(,)?) => {$(
        #[inline(never)]
        #[no_mangle]
        extern "C" fn $name() {
            core::hint::black_box($id as u32);
        }
    )*};
}

/// The loop's probe: cost markers around each stage, and the CRC of each
/// frame as sent (for the parity line).
struct Marks {
    frame_crcs: [u32; 2],
    /// The motion-compensated run (its own markers).
    mc: bool,
}

impl Probe<u8> for Marks {
    #[inline(always)]
    fn enter(&mut self, stage: Stage) {
        match (stage, self.mc) {
            (Stage::Ingest, false) => spiv_mark_ingest_begin(),
            (Stage::Frame, false) => spiv_mark_frame_begin(),
            (Stage::Send, false) => spiv_mark_send_begin(),
            (Stage::Ingest, true) => spiv_mark_mc_ingest_begin(),
            (Stage::Frame, true) => spiv_mark_mc_frame_begin(),
            (Stage::Send, true) => spiv_mark_mc_send_begin(),
        }
    }
    #[inline(always)]
    fn leave(&mut self, stage: Stage) {
        match (stage, self.mc) {
            (Stage::Ingest, false) => spiv_mark_ingest_end(),
            (Stage::Frame, false) => spiv_mark_frame_end(),
            (Stage::Send, false) => spiv_mark_send_end(),
            (Stage::Ingest, true) => spiv_mark_mc_ingest_end(),
            (Stage::Frame, true) => spiv_mark_mc_frame_end(),
            (Stage::Send, true) => spiv_mark_mc_send_end(),
        }
    }
    fn sent(&mut self, _frame_id: u32, slot: Slot, frame: &[u8]) {
        if let Some(c) = self.frame_crcs.get_mut(usize::from(slot.member)) {
            *c = frame_crc(frame);
        }
    }
}

markers!(
    spiv_mark_ingest_begin = 1,
    spiv_mark_ingest_end = 2,
    spiv_mark_frame_begin = 3,
    spiv_mark_frame_end = 4,
    spiv_mark_send_begin = 5,
    spiv_mark_send_end = 6,
    spiv_mark_link_begin = 7,
    spiv_mark_link_end = 8,
    spiv_mark_mc_ingest_begin = 9,
    spiv_mark_mc_ingest_end = 10,
    spiv_mark_mc_frame_begin = 11,
    spiv_mark_mc_frame_end = 12,
    spiv_mark_mc_send_begin = 13,
    spiv_mark_mc_send_end = 14,
    spiv_mark_hear_begin = 15,
    spiv_mark_hear_end = 16,
    spiv_mark_rice_begin = 17,
    spiv_mark_rice_end = 18,
    spiv_mark_context_begin = 19,
    spiv_mark_context_end = 20,
    spiv_mark_sparse_begin = 21,
    spiv_mark_sparse_end = 22,
    spiv_mark_sparse_context_begin = 23,
    spiv_mark_sparse_context_end = 24,
    spiv_mark_light_begin = 25,
    spiv_mark_light_end = 26,
    spiv_mark_rungs_begin = 27,
    spiv_mark_rungs_end = 28,
);

#[entry]
fn main() -> ! {
    match run() {
        Ok(()) => debug::exit(debug::EXIT_SUCCESS),
        Err(e) => {
            hprintln!("spiv-firmware-m4: error: {}", e);
            debug::exit(debug::EXIT_FAILURE);
        }
    }
    #[allow(clippy::empty_loop)]
    loop {}
}

/// What went wrong, for the one error line.
enum Failure {
    Core(spiv_core::Error),
    Memory(&'static str),
}

impl core::fmt::Display for Failure {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Failure::Core(e) => write!(f, "core: {e}"),
            Failure::Memory(m) => f.write_str(m),
        }
    }
}

impl From<spiv_core::Error> for Failure {
    fn from(e: spiv_core::Error) -> Self {
        Failure::Core(e)
    }
}

impl From<LinkError<Infallible>> for Failure {
    fn from(e: LinkError<Infallible>) -> Self {
        match e {
            LinkError::Core(c) => Failure::Core(c),
            LinkError::Link(never) => match never {},
        }
    }
}

fn run() -> Result<(), Failure> {
    let ram: &'static mut Ram = cortex_m::singleton!(: Ram = Ram {
        history: [0; HIST_WORDS],
        counts: [0; SIZES.count_words()],
        c_t: [0; PX],
        class: [0; PX],
        labels: [0; PX],
        masks: [0; SIZES.mask_words()],
        tiles: [0; SIZES.tiles()],
        parents: [0; MC_SIZES.parents()],
        regions: [EMPTY_REGION; MC_SIZES.regions()],
        frame: [0; PX],
        payload: [0; MAX_PAYLOAD],
        wire: [0; MAX_ENCODED],
        mc: [0; PX],
        control_rx: [0; MAX_CONTROL_ENCODED],
        rows: [[0; GRID]; 4],
        caps: [[0; CAP_BANDS]; 2],
        refined: [[0; GRID]; 2],
        codec_scratch: [0; CODEC_SCRATCH],
    })
    .ok_or(Failure::Memory("RAM taken twice"))?;
    report_memory(ram)?;

    // `spiv-firmware-sim`'s defaults: first frame at n_max/2, one pair.
    let params = Params::default();
    let mut cfg = Config::new(u32::from(params.n_max / 2), DT);
    cfg.schedule.pairs = Some(1);
    strip(ram, cfg, false)?;

    // `spiv-firmware-sim --method mc`: refine on. The control applies from
    // the first frame, so the bootstrap never runs; adaptive needs no TFP
    // counts (the native loop's default TFP bootstrap prints the same line).
    let mut mc = cfg;
    mc.method = spiv_core::Method::Mc;
    mc.bootstrap = spiv_core::Method::Adaptive;
    mc.refine = Some(Refine::default());
    strip(ram, mc, true)?;
    codecs(ram)?;
    light()
}

/// The static-light model and its event ring over the strip's bottom 32
/// stored rows for its first 104 planes, then the frames of rungs 4, 8, 16
/// and 32 ticks around tick 52 warped along a uniform 0.5 px per tick,
/// between cost markers. Prints
/// `light events=… lost=… evicted=… periodic=… frames_crc=…` (the host's
/// `strip_kernels light` prints the same after `light `).
fn light() -> Result<(), Failure> {
    let ram: &'static mut LightRam = cortex_m::singleton!(: LightRam = LightRam {
        last: [0; LIGHT_PX],
        period: [0; LIGHT_PX],
        rate: [0; LIGHT_PX],
        short: [0; LIGHT_PX],
        lead: [0; LIGHT_PX],
        flags: [0; LIGHT_PX],
        entries: [0; LIGHT_EVENTS],
        starts: [0; LIGHT_TICKS],
        frames: [0; 2 * LIGHT_RUNGS.len() * LIGHT_PX],
    })
    .ok_or(Failure::Memory("light RAM taken twice"))?;
    let state = LightState {
        last: &mut ram.last,
        period: &mut ram.period,
        rate: &mut ram.rate,
        short: &mut ram.short,
        lead: &mut ram.lead,
        flags: &mut ram.flags,
    };
    let mut model = Light::new(W, LIGHT_H, 0, state)?;
    let mut ring = EventRing::new(&mut ram.entries, &mut ram.starts, 0)?;
    spiv_mark_light_begin();
    for plane in STRIP.chunks_exact(PLANE_BYTES).take(LIGHT_PLANES) {
        ring.push(
            &mut model,
            &PlaneView::new(&plane[..LIGHT_PX / 8], W, LIGHT_H)?,
        )?;
    }
    spiv_mark_light_end();
    let zeros = [0i16; 4];
    let flow = Flow {
        nx: 2,
        ny: 2,
        x0: 0,
        y0: 0,
        pitch: 128 * 16,
        vx: &LIGHT_VX,
        vy: &zeros,
        ax: &zeros,
        ay: &zeros,
    };
    let mut rungs = Rungs::events(0);
    rungs.separations[..LIGHT_RUNGS.len()].copy_from_slice(&LIGHT_RUNGS);
    rungs.count = LIGHT_RUNGS.len() as u8;
    spiv_mark_rungs_begin();
    rung_frames(&ring, &model, &flow, LIGHT_MID, &rungs, &mut ram.frames)?;
    spiv_mark_rungs_end();
    let mut digest = CRC32.digest();
    for v in ram.frames.iter() {
        digest.update(&v.to_le_bytes());
    }
    let periodic = (0..LIGHT_PX).filter(|&i| model.periodic(i)).count();
    let c = ring.cursor();
    hprintln!(
        "light events={} lost={} evicted={} periodic={} frames_crc={:08x}",
        c.stored,
        c.lost,
        c.evicted,
        periodic,
        digest.finalize()
    );
    Ok(())
}

/// Codes the last frame (the motion-compensated pair's second) with each
/// tile codec, between cost markers, and prints the bytes of each.
fn codecs(ram: &mut Ram) -> Result<(), Failure> {
    let rows = tile_rows(W, H, false, Lossy::DEFAULT.block);
    let mut bytes = [0usize; 4];
    let codecs = [
        Encoding::Rice,
        Encoding::Context,
        Encoding::Sparse,
        Encoding::SparseContext,
    ];
    for (k, enc) in codecs.into_iter().enumerate() {
        codec_mark(k, true);
        for tile in ram.frame.chunks(usize::from(rows) * usize::from(W)) {
            let (_, len) = encode_tile(
                enc,
                tile,
                W,
                (tile.len() / usize::from(W)) as u16,
                &Lossy::DEFAULT,
                &mut ram.codec_scratch,
                &mut ram.payload,
            )?;
            bytes[k] += len;
        }
        codec_mark(k, false);
    }
    hprintln!(
        "codecs rice={} context={} sparse={} sparse_context={}",
        bytes[0],
        bytes[1],
        bytes[2],
        bytes[3]
    );
    Ok(())
}

fn codec_mark(k: usize, begin: bool) {
    match (k, begin) {
        (0, true) => spiv_mark_rice_begin(),
        (0, false) => spiv_mark_rice_end(),
        (1, true) => spiv_mark_context_begin(),
        (1, false) => spiv_mark_context_end(),
        (2, true) => spiv_mark_sparse_begin(),
        (2, false) => spiv_mark_sparse_end(),
        (3, true) => spiv_mark_sparse_context_begin(),
        _ => spiv_mark_sparse_context_end(),
    }
}

/// The sidecar loop over the committed strip with `cfg`; motion-compensated
/// (`mc`) after hearing [`CONTROL`]. Prints the parity line.
fn strip(ram: &mut Ram, cfg: Config, mc: bool) -> Result<(), Failure> {
    let mut sidecar = Sidecar::new(W, H, cfg)?;
    let sizes = if mc { MC_SIZES } else { SIZES };
    let workspace = Workspace::new(
        sizes,
        Buffers {
            counts: &mut ram.counts,
            c_t: &mut ram.c_t,
            class: &mut ram.class,
            labels: &mut ram.labels,
            masks: &mut ram.masks,
            tiles: &mut ram.tiles,
            parents: &mut ram.parents[..sizes.parents()],
            regions: &mut ram.regions[..sizes.regions()],
        },
    )?;
    let [vx, vy, next_vx, next_vy] = &mut ram.rows;
    let [caps, next_caps] = &mut ram.caps;
    let [rvx, rvy] = &mut ram.refined;
    let mut mem = Memory {
        history: History::new(&mut ram.history, W, H, 0, H, DEPTH)?,
        workspace: if mc {
            workspace.with_motion_counts(&mut ram.mc)?
        } else {
            workspace
        },
        frame: &mut ram.frame,
        counts: &mut [],
        send: SendBuffers {
            payload: &mut ram.payload,
            wire: &mut ram.wire,
            scratch: &mut [],
        },
        downlink: if mc {
            DownlinkBuffers {
                rx: &mut ram.control_rx,
                vx,
                vy,
                caps,
                next_vx,
                next_vy,
                next_caps,
            }
        } else {
            DownlinkBuffers::none()
        },
        refine: if mc {
            RefineBuffers { vx: rvx, vy: rvy }
        } else {
            RefineBuffers::none()
        },
    };
    if mc {
        spiv_mark_hear_begin();
        sidecar.hear(&mut mem.downlink, CONTROL);
        spiv_mark_hear_end();
        let d = sidecar.downlink();
        if d.heard != 1 || d.refused != 0 {
            return Err(Failure::Memory("the committed control was not heard"));
        }
    }
    let mut link = CrcLink {
        digest: CRC32.digest(),
    };
    let mut marks = Marks {
        frame_crcs: [0; 2],
        mc,
    };
    for plane in STRIP.chunks_exact(PLANE_BYTES) {
        if sidecar.done() {
            break;
        }
        sidecar.push_plane(&mut mem, plane, &mut link, &mut marks)?;
    }
    let s = sidecar.finish(&mut mem.send, &mut link)?;
    hprintln!(
        "{}planes={} frames={} messages={} bytes={} stream_crc={:08x} frame_crcs={:08x},{:08x}",
        if mc { "mc " } else { "" },
        s.planes,
        s.frames,
        s.messages,
        s.bytes,
        link.digest.finalize(),
        marks.frame_crcs[0],
        marks.frame_crcs[1]
    );
    Ok(())
}

/// Prints what the pipeline reserves and holds the core to its documented
/// bytes per pixel.
fn report_memory(ram: &Ram) -> Result<(), Failure> {
    use core::mem::size_of_val;
    let history = size_of_val(&ram.history);
    let state = size_of_val(&ram.counts)
        + size_of_val(&ram.c_t)
        + size_of_val(&ram.class)
        + size_of_val(&ram.labels)
        + size_of_val(&ram.masks);
    let tables = size_of_val(&ram.tiles) + size_of_val(&ram.parents) + size_of_val(&ram.regions);
    let io = size_of_val(&ram.frame) + size_of_val(&ram.payload) + size_of_val(&ram.wire);
    let motion = size_of_val(&ram.mc)
        + size_of_val(&ram.control_rx)
        + size_of_val(&ram.rows)
        + size_of_val(&ram.caps)
        + size_of_val(&ram.refined);
    hprintln!(
        "memory: {}x{} px, history {} B ({} planes, {} milli-B/px), state {} B ({} milli-B/px), tables {} B (motion-compensated sizes), frame+payload+wire {} B, motion (counts, downlink, refine) {} B, codec scratch {} B, total {} B",
        W,
        H,
        history,
        DEPTH,
        history * 1000 / PX,
        state,
        state * 1000 / PX,
        tables,
        io,
        motion,
        size_of_val(&ram.codec_scratch),
        core::mem::size_of::<Ram>()
    );
    if state * 1000 != STATE_MILLIBYTES_PER_PIXEL * PX || state != SIZES.per_pixel_bytes() {
        return Err(Failure::Memory(
            "per-pixel state differs from the core's documented 5.375 B/px",
        ));
    }
    Ok(())
}
