//! The Cortex-M4 firmware's pipeline (`firmware-sim/cortex-m4`) on the host,
//! for exact instruction counts with callgrind (`firmware-sim/cost.sh`): the
//! same committed strip, the same sidecar loop (`spiv_core::sidecar`), the
//! same 8-bit frames and sender. callgrind brackets the three kernels the
//! loop calls by their symbols (`History::push`, `reconstruct_adaptive`,
//! `Sender::send_frame`), which the core keeps out of line. Prints the
//! parity line the firmware prints. With the argument `mc`, the firmware's
//! second run: motion-compensated frames (refine on) after hearing the
//! committed control (`cortex-m4/data/control.bin`); its line without the
//! firmware's `mc ` prefix. With `light`, the firmware's third part: the
//! static-light model and its event ring over the strip's bottom 32 stored
//! rows and first 104 planes
//! (`EventRing::push`), then the rung frames (`rung_frames`); its line
//! without the firmware's `light ` prefix.
//!
//! `cargo run --release -p spiv-firmware-sim --example strip_kernels [mc|light]`

use std::convert::Infallible;

use spiv_core::buffers::SidecarBuf;
use spiv_core::error::LinkError;
use spiv_core::sidecar::{Config, Probe, Sidecar};
use spiv_core::wire::sender::{Link, Slot};
use spiv_core::wire::{crc32, frame_crc};

const W: u16 = 128;
const H: u16 = 64;
const DT: u32 = 13;
static STRIP: &[u8] = include_bytes!("../cortex-m4/data/strip.dat");
static CONTROL: &[u8] = include_bytes!("../cortex-m4/data/control.bin");

struct Memory(Vec<u8>);

impl Link for Memory {
    type Error = Infallible;
    fn send(&mut self, m: &[u8]) -> Result<(), Self::Error> {
        self.0.extend_from_slice(m);
        Ok(())
    }
}

/// The CRC of every frame as sent.
struct Crcs(Vec<String>);

impl Probe<u8> for Crcs {
    fn sent(&mut self, _frame_id: u32, _slot: Slot, frame: &[u8]) {
        self.0.push(format!("{:08x}", frame_crc(frame)));
    }
}

/// The firmware's `light()`: the same buffers' sizes, rungs, midpoint and
/// flow (`cortex-m4/src/main.rs`).
fn light() -> Result<(), spiv_core::Error> {
    use spiv_core::buffers::LightBuf;
    use spiv_core::light::Light;
    use spiv_core::plane::PlaneView;
    use spiv_core::rungs::{rung_frames, EventRing, Rungs};
    use spiv_core::warp::Flow;
    const RUNGS: [u16; 4] = [4, 8, 16, 32];
    // The strip's bottom 32 stored rows, its first 104 planes.
    let (h, planes) = (32u16, 104);
    let px = usize::from(W) * usize::from(h);
    let mut state = LightBuf::new(px);
    let mut model = Light::new(W, h, 0, state.state())?;
    let (mut entries, mut starts) = (vec![0u32; 16_384], vec![0u32; 105]);
    let mut ring = EventRing::new(&mut entries, &mut starts, 0)?;
    let plane_bytes = usize::from(W) * usize::from(H) / 8;
    for plane in STRIP.chunks_exact(plane_bytes).take(planes) {
        ring.push(&mut model, &PlaneView::new(&plane[..px / 8], W, h)?)?;
    }
    let vx = [2048i16; 4];
    let zeros = [0i16; 4];
    let flow = Flow {
        nx: 2,
        ny: 2,
        x0: 0,
        y0: 0,
        pitch: 128 * 16,
        vx: &vx,
        vy: &zeros,
        ax: &zeros,
        ay: &zeros,
    };
    let mut rungs = Rungs::events(0);
    rungs.separations[..RUNGS.len()].copy_from_slice(&RUNGS);
    rungs.count = RUNGS.len() as u8;
    let mut frames = vec![0i16; 2 * RUNGS.len() * px];
    rung_frames(&ring, &model, &flow, 52, &rungs, &mut frames)?;
    let bytes: Vec<u8> = frames.iter().flat_map(|v| v.to_le_bytes()).collect();
    let periodic = (0..px).filter(|&i| model.periodic(i)).count();
    let c = ring.cursor();
    println!(
        "events={} lost={} evicted={} periodic={} frames_crc={:08x}",
        c.stored,
        c.lost,
        c.evicted,
        periodic,
        crc32(&bytes)
    );
    Ok(())
}

fn main() -> Result<(), LinkError<Infallible>> {
    if std::env::args().nth(1).as_deref() == Some("light") {
        return Ok(light()?);
    }
    // `spiv-firmware-sim`'s defaults and the firmware's: first frame at
    // n_max/2, one pair, 8-bit frames, Rice tiles.
    let mut cfg = Config::new(0, DT);
    cfg.schedule.first = u32::from(cfg.params.n_max / 2);
    cfg.schedule.pairs = Some(1);
    let mc = std::env::args().nth(1).as_deref() == Some("mc");
    if mc {
        cfg.method = spiv_core::Method::Mc;
        cfg.bootstrap = spiv_core::Method::Adaptive;
        cfg.refine = Some(spiv_core::motion::Refine::default());
    }
    let mut sidecar = Sidecar::new(W, H, cfg)?;
    let mut buf = SidecarBuf::<u8>::new(W, H, &cfg)?;
    let mut mem = buf.memory(0)?;
    if mc {
        sidecar.hear(&mut mem.downlink, CONTROL);
    }
    let (mut link, mut crcs) = (Memory(Vec::new()), Crcs(Vec::new()));
    for plane in STRIP.chunks_exact(usize::from(W) * usize::from(H) / 8) {
        if sidecar.done() {
            break;
        }
        sidecar.push_plane(&mut mem, plane, &mut link, &mut crcs)?;
    }
    let s = sidecar.finish(&mut mem.send, &mut link)?;
    println!(
        "planes={} frames={} messages={} bytes={} stream_crc={:08x} frame_crcs={}",
        s.planes,
        s.frames,
        s.messages,
        s.bytes,
        crc32(&link.0),
        crcs.0.join(",")
    );
    Ok(())
}
