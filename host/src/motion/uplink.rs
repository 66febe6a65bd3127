//! A pair of the live loop on the wire, both ways: the core's pair
//! ([`CorePair`]) sent as its head ([`spiv_core::wire::pair::PairHead`])
//! and its parts — lossless `Context` tiles through the wire's
//! [`Sender`] — and read back bit-exact from the messages
//! ([`PairReader`]: the frame assembler's CRC-checked frames, put
//! together by the head). What each part costs is counted as it leaves
//! (headers, CRCs and COBS framing included):
//!
//! - each rung frame as 16-bit levels above its smallest sample, whose
//!   value the head carries;
//! - each tick of events as a stored-order plane of levels 0 (none),
//!   1 (−1) and 2 (+1);
//! - with the events, the static rate of every stored pixel (16-bit).

use spiv_core::method::Method;
use spiv_core::rungs::MAX_RUNGS;
use spiv_core::wire::codec::Lossy;
use spiv_core::wire::pair::{PairHead, MAX_EVENT_TICKS};
use spiv_core::wire::sender::{tile_rows, FrameInfo, Link, SendBuffers, SendError, Sender, Slot};
use spiv_core::wire::{Encoding, Kind, Message, WireError, MAX_ENCODED, MAX_PAYLOAD};

use super::make::{CoreEvents, CorePair};
use crate::receive::assemble::{Assembler, FrameLimit, ReceivedFrame};

/// Bytes of one pair on the wire, by what they carry.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct PairBytes {
    /// The head.
    pub head: u64,
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
        self.head + self.rung_frames + self.events + self.rates
    }
}

/// A link that keeps every message and counts its bytes.
#[derive(Debug, Default)]
struct Keep {
    messages: Vec<Vec<u8>>,
    bytes: u64,
}

impl Link for Keep {
    type Error = std::convert::Infallible;
    fn send(&mut self, message: &[u8]) -> Result<(), Self::Error> {
        self.bytes += message.len() as u64;
        self.messages.push(message.to_vec());
        Ok(())
    }
}

fn wire(e: SendError<std::convert::Infallible>) -> WireError {
    match e {
        SendError::Wire(w) => w,
        SendError::Link(never) => match never {},
    }
}

/// One stream of live-loop pairs out of a `width × height` sensor: one
/// sender (its message and frame counters run on), its buffers.
#[derive(Debug)]
pub struct Uplink {
    sender: Sender,
    payload: Vec<u8>,
    wire: Vec<u8>,
}

impl Uplink {
    /// A stream for a sensor of `width × height` stored pixels.
    pub fn new((width, height): (u16, u16)) -> Result<Uplink, WireError> {
        let rows = tile_rows(width, height, true, Lossy::DEFAULT.block);
        Ok(Uplink {
            sender: Sender::new(width, height, rows)?,
            payload: vec![0u8; MAX_PAYLOAD],
            wire: vec![0u8; MAX_ENCODED],
        })
    }

    /// Sends `p` as pair number `pair`: its messages, in order, and what
    /// they cost. Refused when `p` is not this stream's size, has more
    /// rungs or ticks of events than a head carries, or a rung frame is
    /// not one frame of samples.
    pub fn send(
        &mut self,
        pair: u32,
        p: &CorePair,
    ) -> Result<(Vec<Vec<u8>>, PairBytes), WireError> {
        let px = usize::from(p.size.0) * usize::from(p.size.1);
        let mut head = PairHead {
            pair,
            mid: p.mid,
            from_pair: p.from_pair,
            ..PairHead::default()
        };
        if p.rungs.len() > MAX_RUNGS {
            return Err(WireError::Payload);
        }
        let mut rung_levels = Vec::with_capacity(2 * p.rungs.len());
        for (k, (s, frames)) in p.rungs.iter().enumerate() {
            head.separations[k] = *s;
            for (j, f) in frames.iter().enumerate() {
                if f.len() != px {
                    return Err(WireError::Payload);
                }
                let low = f.iter().copied().min().unwrap_or(0);
                head.offsets[2 * k + j] = low;
                rung_levels.push(
                    f.iter()
                        .map(|&v| (i32::from(v) - i32::from(low)) as u16)
                        .collect::<Vec<u16>>(),
                );
            }
        }
        head.count = p.rungs.len() as u8;
        if let Some(ev) = &p.events {
            head.ev_first = ev.first;
            head.ev_ticks = u16::try_from(ev.ticks.len())
                .ok()
                .filter(|&n| n <= MAX_EVENT_TICKS)
                .ok_or(WireError::Payload)?;
            if ev.rates.len() != px {
                return Err(WireError::Payload);
            }
        }
        let mut out = PairBytes::default();
        let mut link = Keep::default();
        let mut buf = SendBuffers {
            payload: &mut self.payload,
            wire: &mut self.wire,
            // `Context` tiles need no scratch.
            scratch: &mut [],
        };
        self.sender
            .send_pair_head(&mut buf, &head, &mut link)
            .map_err(wire)?;
        out.head = link.bytes;
        let mut member = 0u8;
        let mut info = |dt: u32| {
            let i = FrameInfo {
                slot: Slot {
                    tick: p.mid,
                    pair,
                    member,
                },
                method: Method::Mc,
                full_scale: u16::MAX,
                dt,
            };
            member = member.wrapping_add(1);
            i
        };
        let s = &mut self.sender;
        for (k, levels) in rung_levels.iter_mut().enumerate() {
            let i = info(u32::from(head.separations[k / 2]));
            out.rung_frames += send_part(s, &mut buf, &mut link, levels, &i)?;
        }
        if let Some(ev) = &p.events {
            let mut plane = vec![0u8; px];
            for tick in &ev.ticks {
                plane.fill(0);
                for &(i, sign) in tick {
                    if let Some(x) = plane.get_mut(i as usize) {
                        *x = if sign > 0 { 2 } else { 1 };
                    }
                }
                let i = info(0);
                out.events += send_part(s, &mut buf, &mut link, &mut plane, &i)?;
            }
            let mut rates = ev.rates.clone();
            let i = info(0);
            out.rates += send_part(s, &mut buf, &mut link, &mut rates, &i)?;
        }
        Ok((link.messages, out))
    }
}

/// Sends one part as a lossless `Context` frame; returns its bytes.
fn send_part<G: spiv_core::gray::Gray>(
    sender: &mut Sender,
    buf: &mut SendBuffers<'_>,
    link: &mut Keep,
    frame: &mut [G],
    info: &FrameInfo,
) -> Result<u64, WireError> {
    let before = link.bytes;
    sender
        .send_frame(buf, frame, info, Encoding::Context, &Lossy::DEFAULT, link)
        .map_err(wire)?;
    Ok(link.bytes - before)
}

/// What `p` costs on the wire, sent as the first pair of a stream.
pub fn pair_bytes(p: &CorePair) -> Result<PairBytes, WireError> {
    Ok(Uplink::new(p.size)?.send(0, p)?.1)
}

/// Live-loop pairs back from the messages of one stream: each pair once
/// its head and every part arrived bit-exact (the frame assembler's CRC);
/// a pair with a part missing is dropped when the next head comes, and
/// counted.
#[derive(Debug)]
pub struct PairReader {
    frames: Assembler,
    head: Option<(PairHead, u16, u16)>,
    parts: Vec<Option<ReceivedFrame>>,
    /// Pairs delivered.
    pub pairs: u64,
    /// Pairs dropped with a part missing.
    pub incomplete: u64,
}

impl PairReader {
    /// A reader that takes frames up to `limit`.
    pub fn new(limit: FrameLimit) -> PairReader {
        PairReader {
            frames: Assembler::new(limit),
            head: None,
            parts: Vec::new(),
            pairs: 0,
            incomplete: 0,
        }
    }

    /// Takes one message; returns a pair (its number and the core's pair)
    /// when the message completes one.
    pub fn push(&mut self, m: &Message<'_>) -> Option<(u32, CorePair)> {
        if m.header.kind == Kind::PairHead {
            let h = PairHead::parse(m.payload).ok()?;
            if self.head.is_some() {
                self.incomplete += 1;
            }
            self.head = Some((h, m.header.width, m.header.height));
            self.parts = vec![None; usize::from(h.parts())];
            return self.complete();
        }
        let f = self.frames.push(m)?;
        let (h, _, _) = self.head.as_ref()?;
        if f.end.pair == h.pair {
            if let Some(slot) = self.parts.get_mut(usize::from(f.end.member)) {
                *slot = Some(f);
            }
        }
        self.complete()
    }

    /// The pending pair, if every part is in.
    fn complete(&mut self) -> Option<(u32, CorePair)> {
        if self.parts.iter().any(Option::is_none) {
            return None;
        }
        let (h, w, hh) = self.head.take()?;
        let parts: Vec<ReceivedFrame> = std::mem::take(&mut self.parts)
            .into_iter()
            .flatten()
            .collect();
        let px = usize::from(w) * usize::from(hh);
        if parts.iter().any(|f| f.data.len() != px) {
            self.incomplete += 1;
            return None;
        }
        let count = usize::from(h.count);
        let rungs = (0..count)
            .map(|k| {
                let frame = |j: usize| -> Vec<i16> {
                    let off = i32::from(h.offsets[2 * k + j]);
                    parts[2 * k + j]
                        .data
                        .iter()
                        .map(|&l| (i32::from(l) + off) as i16)
                        .collect()
                };
                (h.separations[k], [frame(0), frame(1)])
            })
            .collect();
        let events = (h.ev_ticks > 0).then(|| {
            let planes = &parts[2 * count..2 * count + usize::from(h.ev_ticks)];
            CoreEvents {
                first: h.ev_first,
                ticks: planes
                    .iter()
                    .map(|f| {
                        f.data
                            .iter()
                            .enumerate()
                            .filter(|(_, &l)| l != 0)
                            .map(|(i, &l)| (i as u32, if l == 2 { 1 } else { -1 }))
                            .collect()
                    })
                    .collect(),
                rates: parts[2 * count + usize::from(h.ev_ticks)].data.clone(),
            }
        });
        self.pairs += 1;
        Some((
            h.pair,
            CorePair {
                size: (w, hh),
                mid: h.mid,
                from_pair: h.from_pair,
                rungs,
                events,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spiv_core::wire::Decoder;

    /// A pair of a 40 × 24 sensor: two rungs of frames with negative and
    /// positive samples, events on 5 ticks, rates.
    fn pair(seed: i32) -> CorePair {
        let px: usize = 40 * 24;
        let frame = |k: i32| -> Vec<i16> {
            (0..px as i32)
                .map(|i| ((i * 37 + k * 11 + seed) % 301 - 120) as i16 * 16)
                .collect()
        };
        CorePair {
            size: (40, 24),
            mid: 500 + seed as u32,
            from_pair: 3,
            rungs: vec![(16, [frame(0), frame(1)]), (32, [frame(2), frame(3)])],
            events: Some(CoreEvents {
                first: 480,
                ticks: (0..5)
                    .map(|t| {
                        (0..px as u32)
                            .filter(|i| (i * 7 + t * 13) % 29 == 0)
                            .map(|i| (i, if i % 3 == 0 { -1 } else { 1 }))
                            .collect()
                    })
                    .collect(),
                rates: (0..px).map(|i| (i * 13 % 4000) as u16).collect(),
            }),
        }
    }

    /// Every pair `reader` reads from `messages`.
    fn read(reader: &mut PairReader, messages: &[Vec<u8>]) -> Vec<(u32, CorePair)> {
        let mut rx = vec![0u8; MAX_ENCODED];
        let mut dec = Decoder::new(&mut rx);
        let mut out = Vec::new();
        for m in messages {
            let mut input = m.as_slice();
            while let Some(r) = dec.feed(&mut input) {
                if let Ok(msg) = r {
                    out.extend(reader.push(&msg));
                }
            }
        }
        out
    }

    /// Pairs come back bit-exact, in a stream; the bytes counted are the
    /// bytes sent, and less than the frames raw.
    #[test]
    fn pairs_come_back_bit_exact() {
        let mut up = Uplink::new((40, 24)).unwrap();
        let mut reader = PairReader::new(FrameLimit::default());
        for k in 0..3 {
            let p = pair(k);
            let (messages, bytes) = up.send(k as u32 + 7, &p).unwrap();
            let sent: u64 = messages.iter().map(|m| m.len() as u64).sum();
            assert_eq!(bytes.total(), sent);
            assert!(bytes.head > 0 && bytes.rung_frames > 0 && bytes.events > 0 && bytes.rates > 0);
            assert!(bytes.rung_frames < 4 * 40 * 24 * 2, "{bytes:?}");
            assert_eq!(read(&mut reader, &messages), vec![(k as u32 + 7, p)]);
        }
        // A pair of events alone.
        let p = CorePair {
            rungs: Vec::new(),
            from_pair: spiv_core::wire::pair::NO_ASK,
            ..pair(9)
        };
        let (messages, bytes) = up.send(20, &p).unwrap();
        assert_eq!(bytes.rung_frames, 0);
        assert_eq!(read(&mut reader, &messages), vec![(20, p)]);
    }

    /// A damaged part loses its pair, never the next one, and the loss is
    /// counted; a pair the head cannot carry is refused before sending.
    #[test]
    fn a_damaged_part_loses_its_pair_only() {
        let mut up = Uplink::new((40, 24)).unwrap();
        let mut reader = PairReader::new(FrameLimit::default());
        let (mut first, _) = up.send(0, &pair(1)).unwrap();
        let k = first.len() / 2;
        let n = first[k].len();
        first[k][n / 2] ^= 0x10;
        assert!(read(&mut reader, &first).is_empty());
        let (second, _) = up.send(1, &pair(2)).unwrap();
        assert_eq!(read(&mut reader, &second), vec![(1, pair(2))]);
        assert_eq!(reader.incomplete, 1);
        let mut long = pair(3);
        if let Some(ev) = &mut long.events {
            ev.ticks = vec![Vec::new(); usize::from(MAX_EVENT_TICKS) + 1];
        }
        assert!(up.send(2, &long).is_err());
        let mut odd = pair(3);
        odd.rungs[0].1[0].pop();
        assert!(up.send(2, &odd).is_err());
    }
}
