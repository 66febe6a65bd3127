//! What one pair costs on the wire: the core's frames and events of a pair
//! ([`PairInput`]) sent through the wire's [`Sender`] as lossless
//! `Context`-coded tiles, the bytes counted as they leave (headers, CRCs
//! and COBS framing included). A receiver decodes them with the wire's
//! own tile decoder.
//!
//! - each rung frame (upright, in spikes, integer) as 16-bit levels above
//!   its smallest value, plus that offset (2 bytes);
//! - each tick of events as a stored-order plane of levels 0 (none),
//!   1 (−1) and 2 (+1);
//! - with the events, the static rate of every stored pixel (16-bit).

use spiv_core::method::Method;
use spiv_core::wire::codec::Lossy;
use spiv_core::wire::sender::{tile_rows, FrameInfo, Link, SendBuffers, SendError, Sender, Slot};
use spiv_core::wire::{Encoding, WireError, MAX_ENCODED, MAX_PAYLOAD};

use super::ladder::PairInput;

/// Bytes of one pair on the wire, by what they carry.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct PairBytes {
    /// The rung frames.
    pub rung_frames: u64,
    /// The events, tick by tick.
    pub events: u64,
    /// The static rates sent with the events.
    pub rates: u64,
}

impl PairBytes {
    /// Every byte of the pair.
    pub fn total(&self) -> u64 {
        self.rung_frames + self.events + self.rates
    }
}

/// A link that only counts.
#[derive(Default)]
struct Count(u64);

impl Link for Count {
    type Error = std::convert::Infallible;
    fn send(&mut self, message: &[u8]) -> Result<(), Self::Error> {
        self.0 += message.len() as u64;
        Ok(())
    }
}

/// A sender's payload and message buffers, allocated once per pair.
struct Buffers {
    payload: Vec<u8>,
    wire: Vec<u8>,
}

/// Bytes of `frame` (`width × height` levels) sent as `Context` tiles.
fn frame_bytes<G: spiv_core::gray::Gray>(
    bufs: &mut Buffers,
    frame: &mut [G],
    width: usize,
    height: usize,
    wide: bool,
) -> Result<u64, WireError> {
    let (w, h) = (
        u16::try_from(width).map_err(|_| WireError::Field)?,
        u16::try_from(height).map_err(|_| WireError::Field)?,
    );
    let rows = tile_rows(w, h, wide, Lossy::DEFAULT.block);
    let mut sender = Sender::new(w, h, rows)?;
    let mut buf = SendBuffers {
        payload: &mut bufs.payload,
        wire: &mut bufs.wire,
        // `Context` tiles need no scratch.
        scratch: &mut [],
    };
    let info = FrameInfo {
        slot: Slot {
            tick: 0,
            pair: 0,
            member: 0,
        },
        method: Method::Mc,
        full_scale: G::MAX,
        dt: 0,
    };
    let mut link = Count::default();
    sender
        .send_frame(
            &mut buf,
            frame,
            &info,
            Encoding::Context,
            &Lossy::DEFAULT,
            &mut link,
        )
        .map_err(|e| match e {
            SendError::Wire(w) => w,
            SendError::Link(never) => match never {},
        })?;
    Ok(link.0)
}

/// What `input` costs on the wire.
pub fn pair_bytes(input: &PairInput) -> Result<PairBytes, WireError> {
    let mut out = PairBytes::default();
    let mut bufs = Buffers {
        payload: vec![0u8; MAX_PAYLOAD],
        wire: vec![0u8; MAX_ENCODED],
    };
    for (_, frames) in &input.rungs {
        for f in frames {
            let (h, w) = f.dim();
            let low = f.iter().copied().fold(f32::INFINITY, f32::min);
            let low = if low.is_finite() { low } else { 0.0 };
            let mut levels: Vec<u16> = f
                .iter()
                .map(|&x| (x - low).round().clamp(0.0, f32::from(u16::MAX)) as u16)
                .collect();
            out.rung_frames += 2 + frame_bytes(&mut bufs, &mut levels, w, h, true)?;
        }
    }
    if let Some(ev) = &input.events {
        let (w, h) = (ev.stored_width, ev.height);
        let mut plane = vec![0u8; w * h];
        for t in 0..ev.ticks {
            plane.fill(0);
            for &(i, sign) in ev.tick(t) {
                if let Some(p) = plane.get_mut(i as usize) {
                    *p = if sign > 0 { 2 } else { 1 };
                }
            }
            out.events += frame_bytes(&mut bufs, &mut plane, w, h, false)?;
        }
        let mut rates = ev.rates().to_vec();
        out.rates += frame_bytes(&mut bufs, &mut rates, w, h, true)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    /// A blank frame costs its framing only; one with particles costs
    /// more, and the sum of the parts is what the total says.
    #[test]
    fn bytes_grow_with_content() {
        let blank = Array2::<f32>::zeros((64, 96));
        let mut dots = blank.clone();
        for k in 0..40 {
            dots[[(k * 7) % 64, (k * 13) % 96]] = 5.0 + k as f32;
        }
        let pair = |a: &Array2<f32>| PairInput {
            events: None,
            start: None,
            rungs: vec![(16, [a.clone(), a.clone()])],
        };
        let b0 = pair_bytes(&pair(&blank)).unwrap();
        let b1 = pair_bytes(&pair(&dots)).unwrap();
        assert!(b0.rung_frames > 0 && b0.events == 0 && b0.rates == 0);
        assert!(b1.rung_frames > b0.rung_frames + 40, "{b1:?} {b0:?}");
        assert!(b1.rung_frames < 2 * 64 * 96 * 2, "coded below raw: {b1:?}");
        assert_eq!(b1.total(), b1.rung_frames);
    }
}
