//! The host end of the sidecar link: a [`source::Source`] of bytes, the
//! core's stream decoder ([`spiv_core::wire::Decoder`]), frame reassembly
//! and pairing ([`assemble`]), with counts of everything lost.

pub mod assemble;
pub mod source;

use ndarray::Array2;
use serde::Serialize;
use spiv_core::pairs::CorePair;
use spiv_core::wire::pair::PairHead;
use spiv_core::wire::{Decoder, Kind, MAX_ENCODED};

use crate::estimator::uplink::PairReader;
use crate::piv::Settings;
use crate::Error;

pub use assemble::{Assembler, AssemblyStats, FrameLimit, Pairer, ReceivedFrame};
pub use source::{Source, Spec};

/// The PIV settings `spiv receive --piv` uses on each received pair: the
/// given window of each pass (px) and [`Settings::for_spike_frames`].
pub fn receiver_settings(windows: Vec<usize>) -> Settings {
    Settings {
        windows,
        ..Settings::for_spike_frames()
    }
}

/// A received frame upright as PIV input.
pub fn upright_f32(f: &ReceivedFrame) -> Array2<f32> {
    crate::piv::to_f32(&f.upright(), usize::from(f.width), usize::from(f.height))
}

/// Final counts of a reception.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Report {
    /// Bytes read.
    pub bytes: u64,
    /// Valid messages.
    pub messages: u64,
    /// Chunks that were not valid messages (COBS, CRC, header, overlong),
    /// and valid messages refused by the assembler (a frame of zero pixels
    /// or over the [`FrameLimit`], rows outside their frame, a tile that
    /// does not decode).
    pub corrupted: u64,
    /// Messages missing by sequence number.
    pub lost_messages: u64,
    /// Messages that arrived out of order.
    pub late_messages: u64,
    /// Frames delivered bit-exact.
    pub frames: u64,
    /// Frames lost (missing, incomplete or failing their CRC).
    pub lost_frames: u64,
    /// Pairs delivered.
    pub pairs: u64,
    /// Pairs with a member lost.
    pub broken_pairs: u64,
    /// Bytes of an unterminated message at the end of the stream.
    pub truncated_tail: u64,
}

/// What a receiver hands its caller.
#[derive(Debug)]
pub enum Event {
    /// A frame arrived whole.
    Frame(ReceivedFrame),
    /// Both frames of a pair arrived.
    Pair(Box<[ReceivedFrame; 2]>),
    /// A pair of the live loop of the time ladder arrived whole: its head
    /// and what the sidecar made ([`crate::estimator::uplink::PairReader`]).
    Ladder(Box<(PairHead, CorePair)>),
}

/// Reads `source` to its end, accepting frames up to `limit`; calls `on`
/// with every frame and pair, and `progress` with the running report after
/// every read. A stream whose messages include a pair head
/// ([`spiv_core::wire::Kind::PairHead`]) is the live loop of the time
/// ladder: from that head on, its messages make [`Event::Ladder`] pairs.
pub fn receive<E>(
    source: &mut dyn Source,
    limit: FrameLimit,
    mut on: impl FnMut(Event) -> Result<(), E>,
    mut progress: impl FnMut(&Report),
) -> Result<Report, E>
where
    E: From<Error>,
{
    let mut rx = vec![0u8; MAX_ENCODED];
    let mut dec = Decoder::new(&mut rx);
    let mut asm = Assembler::new(limit);
    let mut pairer = Pairer::default();
    let mut ladder: Option<PairReader> = None;
    let mut buf = vec![0u8; 64 * 1024];
    let mut report = Report::default();
    loop {
        let n = source.read(&mut buf)?;
        if n == 0 {
            break;
        }
        let mut input = &buf[..n];
        while let Some(m) = dec.feed(&mut input) {
            let Ok(m) = m else { continue };
            if ladder.is_none() && m.header.kind == Kind::PairHead {
                ladder = Some(PairReader::new(limit));
            }
            if let Some(r) = ladder.as_mut() {
                if let Some(p) = r.push(&m) {
                    on(Event::Ladder(Box::new(p)))?;
                }
                continue;
            }
            if let Some(f) = asm.push(&m) {
                if let Some(pair) = pairer.push(f.clone()) {
                    on(Event::Frame(f))?;
                    report.pairs += 1;
                    on(Event::Pair(Box::new(pair)))?;
                } else {
                    on(Event::Frame(f))?;
                }
            }
        }
        fill(&mut report, &dec, &asm, &pairer, ladder.as_ref());
        progress(&report);
    }
    report.truncated_tail = dec.pending() as u64;
    asm.finish();
    if let Some(r) = ladder.as_mut() {
        r.finish();
    }
    fill(&mut report, &dec, &asm, &pairer, ladder.as_ref());
    Ok(report)
}

fn fill(
    r: &mut Report,
    dec: &Decoder<'_>,
    asm: &Assembler,
    pairer: &Pairer,
    ladder: Option<&PairReader>,
) {
    let d = dec.stats();
    let mut a = asm.stats();
    if let Some(l) = ladder {
        let b = l.stats();
        a.frames += b.frames;
        a.lost_frames += b.lost_frames;
        a.rejected += b.rejected;
        r.pairs = l.pairs;
        r.broken_pairs = l.incomplete;
    }
    r.bytes = d.bytes;
    r.messages = d.messages;
    r.corrupted = d.corrupt + d.overflow + a.rejected;
    r.lost_messages = d.lost;
    r.late_messages = d.late;
    r.frames = a.frames;
    r.lost_frames = a.lost_frames;
    if ladder.is_none() {
        r.broken_pairs = pairer.broken;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spiv_firmware_sim::firmware::{Config, Faults, Faulty, Firmware};

    struct Bytes(std::io::Cursor<Vec<u8>>);
    impl Source for Bytes {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
            use std::io::Read;
            Ok(self.0.read(buf).unwrap_or(0))
        }
        fn name(&self) -> String {
            "memory".into()
        }
    }

    fn planes(w: u16, h: u16, n: usize) -> Vec<Vec<u8>> {
        // A bright band in the stored rows near 0 and a few moving dots.
        let mut s = 12345u64;
        (0..n)
            .map(|t| {
                let mut p = vec![0u8; usize::from(w) * usize::from(h) / 8];
                for y in 0..usize::from(h) {
                    for x in 0..usize::from(w) {
                        s ^= s << 13;
                        s ^= s >> 7;
                        s ^= s << 17;
                        let dot = (x + 40 - t % 40) % 20 < 3 && y % 16 < 3;
                        let rate = if dot {
                            60
                        } else if y < 6 {
                            40
                        } else {
                            4
                        };
                        if s % 100 < rate {
                            let i = y * usize::from(w) + x;
                            p[i / 8] |= 1 << (i % 8);
                        }
                    }
                }
                p
            })
            .collect()
    }

    fn run_fw(faults: Faults) -> (Vec<u8>, Vec<spiv_firmware_sim::firmware::SentFrame>) {
        let (w, h) = (64u16, 48u16);
        let mut cfg = Config::new(64, 5);
        cfg.schedule.every = 10;
        cfg.schedule.pairs = Some(4);
        let mut fw = Firmware::new(w, h, cfg, Faulty::new(Vec::new(), faults, 7)).unwrap();
        fw.keep = Some(Vec::new());
        for p in planes(w, h, 64 + 35 + 64) {
            fw.push_plane(&p).unwrap();
        }
        fw.finish().unwrap();
        let kept = fw.keep.take().unwrap();
        (fw.into_link().into_inner(), kept)
    }

    /// Receives `bytes`; returns the report and the frames delivered.
    fn frames_of(bytes: Vec<u8>) -> (Report, Vec<ReceivedFrame>) {
        let mut got = Vec::new();
        let r = receive::<Error>(
            &mut Bytes(std::io::Cursor::new(bytes)),
            FrameLimit::default(),
            |e| {
                if let Event::Frame(f) = e {
                    got.push(f);
                }
                Ok(())
            },
            |_| {},
        )
        .unwrap();
        (r, got)
    }

    #[test]
    fn clean_link_delivers_every_frame_bit_exact() {
        let (bytes, sent) = run_fw(Faults::default());
        assert_eq!(sent.len(), 8);
        let (r, got) = frames_of(bytes);
        assert_eq!(
            (r.frames, r.pairs, r.lost_frames, r.corrupted),
            (8, 4, 0, 0)
        );
        for (g, s) in got.iter().zip(&sent) {
            assert_eq!((g.frame_id, g.tick), (s.frame_id, s.tick));
            assert_eq!(g.data, s.data);
        }
    }

    #[test]
    fn faulty_link_loses_frames_but_never_delivers_a_wrong_one() {
        let faults = Faults::parse("drop=0.05,corrupt=0.05,truncate=0.05,reorder=0.1").unwrap();
        let (bytes, sent) = run_fw(faults);
        let (r, got) = frames_of(bytes);
        // The faults hit: frames were lost and chunks were corrupt, so the
        // accounting below is tested on a damaged stream.
        assert!(r.lost_frames > 0 && r.corrupted > 0, "{r:?}");
        assert!(r.frames > 0, "{r:?}");
        assert_eq!(r.frames + r.lost_frames, sent.len() as u64, "{r:?}");
        for g in &got {
            let s = &sent[g.frame_id as usize];
            assert_eq!(g.data, s.data);
        }
    }

    /// A tile and a frame end of one frame of `w × h`, well formed (COBS,
    /// CRC, magic, version), with a raw 8-bit payload of `rows` rows.
    fn crafted(w: u16, h: u16, rows: u16) -> Vec<u8> {
        use spiv_core::wire::{encode_message, Encoding, FrameEnd, Header, Kind};
        let payload = vec![7u8; usize::from(w) * usize::from(rows)];
        let mut tile = Header {
            kind: Kind::FrameTile,
            seq: 0,
            frame_id: 0,
            tick: 64,
            width: w,
            height: h,
            row0: 0,
            rows,
            encoding: Encoding::Raw8,
            payload_len: 0,
        };
        let end = FrameEnd {
            pair: 0,
            member: 0,
            method: spiv_core::Method::Adaptive,
            full_scale: 255,
            dt: 13,
            tiles: 1,
            lossy: 0,
            frame_crc: spiv_core::wire::frame_crc(&vec![7u16; payload.len()]),
        };
        let mut out = vec![0u8; 2 * MAX_ENCODED];
        let n = encode_message(&tile, &payload, &mut out).unwrap();
        tile.kind = Kind::FrameEnd;
        tile.seq = 1;
        tile.rows = 0;
        let m = encode_message(&tile, &end.to_bytes(), &mut out[n..]).unwrap();
        out.truncate(n + m);
        out
    }

    #[test]
    fn a_frame_claiming_65535_squared_pixels_is_refused_before_allocation() {
        // 92 bytes that once made the receiver allocate 8.6 GB and abort.
        let bytes = crafted(65535, 65535, 0);
        assert_eq!(bytes.len(), 92);
        // The same bytes `spiv receive` is tested on (host/tests/cli.rs);
        // `SPIV_BLESS=1` rewrites them (after a wire version change).
        if std::env::var_os("SPIV_BLESS").is_some() {
            let path = concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/tests/data/frame_65535x65535.bin"
            );
            std::fs::write(path, &bytes).expect("fixture written");
            return;
        }
        let fixture = include_bytes!("../../tests/data/frame_65535x65535.bin");
        assert_eq!(&bytes[..], &fixture[..]);
        let (r, got) = frames_of(bytes);
        assert!(got.is_empty());
        assert_eq!(
            (r.messages, r.corrupted, r.frames, r.lost_frames),
            (2, 2, 0, 1)
        );
    }

    #[test]
    fn an_empty_frame_is_counted_not_dropped_silently() {
        let (r, got) = frames_of(crafted(0, 0, 0));
        assert!(got.is_empty());
        assert_eq!(
            (r.messages, r.corrupted, r.frames, r.lost_frames),
            (2, 2, 0, 1)
        );
        let (r, _) = frames_of(crafted(16, 0, 0));
        assert_eq!((r.corrupted, r.lost_frames), (2, 1));
    }

    #[test]
    fn the_frame_limit_is_the_callers() {
        // A well-formed 16 × 4 frame is delivered under the default limit …
        let (r, got) = frames_of(crafted(16, 4, 4));
        assert_eq!((r.frames, r.corrupted, r.lost_frames), (1, 0, 0));
        assert_eq!(got[0].data, vec![7u16; 64]);
        // … and refused, counted, under a 8 × 8 one.
        let mut asm = Assembler::new("8x8".parse().unwrap());
        let bytes = crafted(16, 4, 4);
        let mut rx = vec![0u8; MAX_ENCODED];
        let mut dec = Decoder::new(&mut rx);
        let mut input = &bytes[..];
        while let Some(m) = dec.feed(&mut input) {
            assert!(asm.push(&m.unwrap()).is_none());
        }
        let s = asm.finish();
        assert_eq!((s.frames, s.rejected, s.lost_frames), (0, 2, 1));
        assert!("0x8".parse::<FrameLimit>().is_err());
        assert!("8x65536".parse::<FrameLimit>().is_err());
        assert!("8".parse::<FrameLimit>().is_err());
    }
}
