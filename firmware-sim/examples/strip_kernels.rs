//! The Cortex-M4 firmware's pipeline (`firmware-sim/cortex-m4`) on the host,
//! for exact instruction counts with callgrind (`firmware-sim/cost.sh`): the
//! same committed strip, the same sidecar loop (`spiv_core::sidecar`), the
//! same 8-bit frames and sender. callgrind brackets the three kernels the
//! loop calls by their symbols (`History::push`, `reconstruct_adaptive`,
//! `Sender::send_frame`), which the core keeps out of line. Prints the
//! parity line the firmware prints. With the argument `mc`, the firmware's
//! second run: motion-compensated frames (refine on) after hearing the
//! committed control (`cortex-m4/data/control.bin`); its line without the
//! firmware's `mc ` prefix.
//!
//! `cargo run --release -p spiv-firmware-sim --example strip_kernels [mc]`

use std::convert::Infallible;

use spiv_core::buffers::SidecarBuf;
use spiv_core::sidecar::{Config, Probe, Sidecar, SidecarError};
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

fn main() -> Result<(), SidecarError<Infallible>> {
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
