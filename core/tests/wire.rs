//! The link under abuse: the stream decoder over any chunking, bit flips,
//! truncation, drops, duplicates and garbage (never a panic, never a wrong
//! payload, every lost message counted), and the tile codecs over random
//! tiles and random payloads. Case counts from `PROPTEST_CASES`; the
//! deterministic sweep feeds 10^6 mutated streams.

use proptest::prelude::*;
use spiv_core::wire::codec::{decode_tile, encode_tile, tile_scratch, Lossy};
use spiv_core::wire::{encode_message, Decoder, Encoding, Header, Kind, MAX_ENCODED};

fn header(seq: u32) -> Header {
    Header {
        kind: Kind::FrameTile,
        seq,
        frame_id: seq / 3,
        tick: seq * 13,
        width: 16,
        height: 16,
        row0: 0,
        rows: 1,
        encoding: Encoding::Raw8,
        payload_len: 0,
    }
}

/// Messages `seq = 0..n` with payloads derived from the seq, framed back to back.
fn stream(n: u32, payload_len: usize) -> (Vec<Vec<u8>>, Vec<u8>) {
    let mut payloads = Vec::new();
    let mut wire = Vec::new();
    let mut buf = vec![0u8; MAX_ENCODED];
    for seq in 0..n {
        let p: Vec<u8> = (0..payload_len + seq as usize % 5)
            .map(|i| (i as u32 * 31 + seq * 7) as u8)
            .collect();
        let len = encode_message(&header(seq), &p, &mut buf).unwrap();
        wire.extend_from_slice(&buf[..len]);
        payloads.push(p);
    }
    (payloads, wire)
}

/// Feeds `wire` in chunks; returns (seq, payload) of every delivered message
/// and the decoder's counts.
fn receive(wire: &[u8], chunks: &[usize]) -> (Vec<(u32, Vec<u8>)>, spiv_core::wire::DecoderStats) {
    let mut rx = vec![0u8; MAX_ENCODED];
    let mut dec = Decoder::new(&mut rx);
    let mut got = Vec::new();
    let mut rest = wire;
    let mut i = 0;
    while !rest.is_empty() {
        let c = chunks
            .get(i % chunks.len().max(1))
            .copied()
            .unwrap_or(1)
            .clamp(1, rest.len());
        i += 1;
        let (mut part, tail) = rest.split_at(c);
        rest = tail;
        while let Some(m) = dec.feed(&mut part) {
            if let Ok(m) = m {
                got.push((m.header.seq, m.payload.to_vec()));
            }
        }
    }
    (got, dec.stats())
}

proptest! {
    #[test]
    fn any_chunking_recovers_every_message(n in 1u32..20, len in 0usize..300,
                                           chunks in prop::collection::vec(1usize..700, 1..8)) {
        let (payloads, wire) = stream(n, len);
        let (got, stats) = receive(&wire, &chunks);
        prop_assert_eq!(got.len(), n as usize);
        for (seq, p) in got {
            prop_assert_eq!(&p, &payloads[seq as usize]);
        }
        prop_assert_eq!(stats.lost + stats.corrupt + stats.overflow, 0);
    }

    #[test]
    fn dropped_messages_show_as_gaps(n in 3u32..30, drop in prop::collection::vec(any::<bool>(), 30)) {
        let mut wire = Vec::new();
        let mut buf = vec![0u8; MAX_ENCODED];
        let mut sent = 0u64;
        for seq in 0..n {
            // Never drop the first or last message: a loss at either end
            // is invisible to sequence numbers.
            if drop[seq as usize] && seq > 0 && seq + 1 < n {
                continue;
            }
            let len = encode_message(&header(seq), &[seq as u8; 9], &mut buf).unwrap();
            wire.extend_from_slice(&buf[..len]);
            sent += 1;
        }
        let (got, stats) = receive(&wire, &[64]);
        prop_assert_eq!(got.len() as u64, sent);
        prop_assert_eq!(stats.lost, u64::from(n) - sent);
    }

    #[test]
    fn mutations_never_yield_a_wrong_payload(n in 1u32..12, len in 0usize..200,
            flips in prop::collection::vec((any::<prop::sample::Index>(), 0u8..8), 0..6),
            cut in any::<prop::sample::Index>(), garbage in prop::collection::vec(any::<u8>(), 0..64)) {
        let (payloads, mut wire) = stream(n, len);
        for (at, bit) in flips {
            let i = at.index(wire.len());
            wire[i] ^= 1 << bit;
        }
        let c = cut.index(wire.len() + 1);
        let mut w = garbage.clone();
        w.extend_from_slice(&wire[..c]);
        w.extend_from_slice(&garbage);
        let (got, _) = receive(&w, &[13, 200]);
        for (seq, p) in got {
            prop_assert!(seq < n);
            prop_assert_eq!(&p, &payloads[seq as usize]);
        }
    }

    #[test]
    fn tiles_round_trip(w in 1u16..90, h in 1u16..20, seed in any::<u64>(), peak in 0u16..=u16::MAX,
                        block in 2u8..=16, tolerance in 0u16..40, contrast in 0u16..40) {
        let n = usize::from(w) * usize::from(h);
        let mut s = seed | 1;
        let data: Vec<u16> = (0..n).map(|_| {
            s ^= s << 13; s ^= s >> 7; s ^= s << 17;
            // Mostly a flat noisy background, some bright spots.
            if s % 11 == 0 { (s >> 20) as u16 % (peak.max(1)) } else { 20 + (s >> 40) as u16 % 6 }
        }).collect();
        let lossy = Lossy { block, tolerance, contrast, contrast_mc: contrast };
        let mut scratch = vec![0u16; tile_scratch(Encoding::SparseContext, w, h, block)];
        let mut buf = vec![0u8; 4 * n + 64];
        let mut sparse = Vec::new();
        for want in [Encoding::Raw8, Encoding::Raw16, Encoding::Rice, Encoding::Sparse,
                     Encoding::Context, Encoding::SparseContext] {
            let (enc, len) = encode_tile(want, &data, w, h, &lossy, &mut scratch, &mut buf).unwrap();
            let mut back = vec![0u16; n];
            decode_tile(enc, &buf[..len], w, h, &mut scratch, &mut back).unwrap();
            // Each mode or its lossless fallback.
            let fallback = [Encoding::Raw8, Encoding::Raw16, Encoding::Rice, Encoding::Context];
            prop_assert!(enc == want || fallback.contains(&enc), "{:?} -> {:?}", want, enc);
            if enc == Encoding::Sparse {
                sparse = back.clone();
            }
            if enc == Encoding::SparseContext && !sparse.is_empty() {
                // The same decisions: the same decoded samples.
                prop_assert_eq!(&back, &sparse);
            }
            if matches!(enc, Encoding::Sparse | Encoding::SparseContext) {
                for (a, b) in data.iter().zip(&back) {
                    prop_assert!((i32::from(*a) - i32::from(*b)).abs() <= i32::from(tolerance));
                }
            } else {
                prop_assert_eq!(&back, &data);
            }
        }
    }

    #[test]
    fn random_payloads_never_panic(w in 1u16..64, h in 1u16..8, bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        let mut scratch = vec![0u16; 4096];
        let mut out8 = vec![0u8; usize::from(w) * usize::from(h)];
        let mut out16 = vec![0u16; usize::from(w) * usize::from(h)];
        for enc in [Encoding::None, Encoding::Raw8, Encoding::Raw16, Encoding::Rice, Encoding::Sparse,
                    Encoding::Context, Encoding::SparseContext] {
            let _ = decode_tile(enc, &bytes, w, h, &mut scratch, &mut out8);
            let _ = decode_tile(enc, &bytes, w, h, &mut scratch, &mut out16);
        }
    }
}

/// 10^6 streams: each a few messages, mutated by a seeded mix of bit flips,
/// dropped bytes, duplicated spans, truncation and junk. Delivered payloads
/// must be the ones sent; nothing may panic.
#[test]
fn a_million_mutated_streams() {
    let streams: u64 = std::env::var("SPIV_WIRE_STREAMS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let (payloads, wire) = stream(4, 24);
    let mut rx = vec![0u8; 512];
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let mut buf = Vec::with_capacity(2 * wire.len());
    let (mut delivered, mut rejected) = (0u64, 0u64);
    for _ in 0..streams {
        buf.clear();
        buf.extend_from_slice(&wire);
        for _ in 0..(next() % 4) {
            let r = next();
            let i = (r >> 8) as usize % buf.len().max(1);
            match r % 5 {
                0 => buf[i] ^= 1 << ((r >> 40) % 8),
                1 => {
                    buf.remove(i);
                }
                2 => {
                    let j = (i + (r >> 32) as usize % 40).min(buf.len());
                    let span: Vec<u8> = buf[i..j].to_vec();
                    buf.splice(i..i, span);
                }
                3 => buf.truncate(i),
                _ => buf.insert(i, (r >> 48) as u8),
            }
            if buf.is_empty() {
                break;
            }
        }
        let mut dec = Decoder::new(&mut rx);
        let mut input = &buf[..];
        while let Some(m) = dec.feed(&mut input) {
            match m {
                Ok(m) => {
                    assert_eq!(m.payload, &payloads[m.header.seq as usize][..]);
                    delivered += 1;
                }
                Err(_) => rejected += 1,
            }
        }
    }
    assert!(delivered > streams, "most messages survive light mutation");
    assert!(rejected > 0, "some mutations are caught");
}
