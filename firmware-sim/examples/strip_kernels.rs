//! The Cortex-M4 firmware's pipeline (`firmware-sim/cortex-m4`) on the host,
//! kernel by kernel, for exact instruction counts with callgrind
//! (`firmware-sim/cost.sh`): the same committed strip, the same schedule,
//! the same 8-bit frames and sender, each kernel behind an `#[inline(never)]`
//! function that `--toggle-collect` can bracket. Prints the parity line the
//! firmware prints.
//!
//! `cargo run --release -p spiv-firmware-sim --example strip_kernels`

use spiv_core::compress::Lossy;
use spiv_core::sender::{tile_rows, FrameInfo, Link, Schedule, SendBuffers, Sender};
use spiv_core::wire::{frame_crc, Encoding, CRC, MAX_ENCODED, MAX_PAYLOAD};
use spiv_core::{reconstruct_adaptive, History, Params, PlaneView, Workspace};
use spiv_firmware_sim::buffers::{HistoryBuf, WorkspaceBuf};

const W: u16 = 128;
const H: u16 = 64;
const DT: u32 = 13;
const DEPTH: u16 = 128;
static STRIP: &[u8] = include_bytes!("../cortex-m4/data/strip.dat");

struct Memory(Vec<u8>);

impl Link for Memory {
    type Error = std::convert::Infallible;
    fn send(&mut self, m: &[u8]) -> Result<(), Self::Error> {
        self.0.extend_from_slice(m);
        Ok(())
    }
}

#[inline(never)]
fn kernel_ingest(hist: &mut History<'_>, plane: &[u8]) -> Result<u32, spiv_core::Error> {
    hist.push(&PlaneView::new(plane, W, H)?)
}

#[inline(never)]
fn kernel_frame(
    hist: &History<'_>,
    k: u32,
    p: &Params,
    ws: &mut Workspace<'_>,
    out: &mut [u8],
) -> Result<(), spiv_core::Error> {
    reconstruct_adaptive(hist, k, p, ws, out).map(|_| ())
}

#[inline(never)]
fn kernel_send(
    sender: &mut Sender,
    buf: &mut SendBuffers<'_>,
    frame: &mut [u8],
    info: &FrameInfo,
    link: &mut Memory,
) {
    let r = sender.send_frame(buf, frame, info, Encoding::Rice, &Lossy::default(), link);
    if let Err(e) = r {
        eprintln!("strip_kernels: send: {e:?}");
        std::process::exit(1);
    }
}

fn main() -> Result<(), spiv_core::Error> {
    let px = usize::from(W) * usize::from(H);
    let params = Params::default();
    let mut hb = HistoryBuf::new(W, H, DEPTH)?;
    let mut hist = hb.history()?;
    let mut wb = WorkspaceBuf::whole(W, H);
    let mut ws = wb.workspace();
    let (mut payload, mut wire) = (vec![0u8; MAX_PAYLOAD], vec![0u8; MAX_ENCODED]);
    let mut buf = SendBuffers {
        payload: &mut payload,
        wire: &mut wire,
        scratch: &mut [],
    };
    let mut frame = vec![0u8; px];
    let mut sender = match Sender::new(W, H, tile_rows(W, H, false, 8)) {
        Ok(s) => s,
        Err(_) => return Err(spiv_core::Error::BadDimensions),
    };
    let mut link = Memory(Vec::new());
    let schedule = Schedule {
        first: u32::from(params.n_max / 2),
        dt: DT,
        every: 4 * DT,
        pairs: Some(1),
    };
    let mut crcs = Vec::new();
    let mut next = 0u64;
    for plane in STRIP.chunks_exact(px / 8) {
        if schedule.slot(next).is_none() {
            break;
        }
        let newest = kernel_ingest(&mut hist, plane)?;
        sender.sent.planes += 1;
        while let Some(slot) = schedule.slot(next) {
            if !Schedule::ready(slot.tick, params.n_max, newest) {
                break;
            }
            next += 1;
            kernel_frame(&hist, slot.tick, &params, &mut ws, &mut frame)?;
            let info = FrameInfo {
                slot,
                method: 0,
                full_scale: params.full_scale,
                dt: DT,
            };
            kernel_send(&mut sender, &mut buf, &mut frame, &info, &mut link);
            crcs.push(format!("{:08x}", frame_crc(&frame)));
        }
    }
    if sender.send_status(&mut buf, &mut link).is_err() {
        return Err(spiv_core::Error::BadDimensions);
    }
    let s = sender.sent;
    println!(
        "planes={} frames={} messages={} bytes={} stream_crc={:08x} frame_crcs={}",
        s.planes,
        s.frames,
        s.messages,
        s.bytes,
        CRC.checksum(&link.0),
        crcs.join(",")
    );
    Ok(())
}
