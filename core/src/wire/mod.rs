//! The wire format between sidecar and host (docs/spec.md §8), pinned:
//!
//! ```text
//! message  = COBS(header | payload | crc32) 0x00
//! header   = magic u16 0x5053 "SP" | version u8 | kind u8 | seq u32 |
//!            frame_id u32 | tick u32 | width u16 | height u16 | row0 u16 |
//!            rows u16 | encoding u8 | reserved u8 | payload_len u32   (30 bytes)
//! crc32    = CRC-32/ISO-HDLC (zlib) over header and payload
//! ```
//!
//! All integers little-endian. A message carries a band of rows of one frame
//! ([`Kind::FrameTile`]), the end of a frame with its pairing and checksum
//! ([`Kind::FrameEnd`], payload [`FrameEnd`]), or the firmware's counters
//! ([`Kind::Status`], payload [`Status`]) up the link, and what the host
//! tells the sidecar ([`Kind::Control`], payload [`control::ControlView`];
//! in the live loop [`Kind::Ask`], payload [`ask::AskView`]) down it. Payloads are at most
//! [`MAX_PAYLOAD`] = 16 KiB, so a device needs one message buffer of
//! [`MAX_MESSAGE`] bytes and one COBS buffer of [`MAX_ENCODED`] bytes.
//!
//! The [`Decoder`] takes bytes in any chunking, resynchronises on the next
//! `0x00` after corruption, loss or truncation, counts what it lost and never
//! panics; its receive buffer is caller-supplied, and bytes beyond it before
//! a delimiter are dropped and counted.

//!
//! | module | owns |
//! |---|---|
//! | [`header`] | the 30-byte message header |
//! | [`stream`] | COBS framing with CRC, and the stream decoder |
//! | [`crc`] | the link's CRC-32 ([`Crc32`], [`crc32`]) |
//! | [`message`] | the frame-end and status payloads, the frame checksum |
//! | [`control`] | the downlink's control payload: predicted motion, window caps |
//! | [`ask`] | the live loop's downlink payload: rungs, events' reach, node flow |
//! | [`pair`] | the live loop's uplink head: what a pair's parts carry |
//! | [`codec`] | tile codecs: raw, lossless Rice, lossy sparse |
//! | [`sender`] | the pair schedule and the messages that carry a frame |

pub mod ask;
pub mod codec;
pub mod control;
pub mod crc;
pub mod header;
pub mod message;
pub mod pair;
pub mod sender;
pub mod stream;

pub use crate::error::WireError;
pub use crc::{crc32, Crc32};
pub use header::Header;
pub use message::{frame_crc, FrameEnd, Status};
pub use stream::{encode_message, Decoder, DecoderState, DecoderStats, Message};

/// `"SP"`.
pub const MAGIC: u16 = 0x5053;
/// The version this code writes and reads (3 since controls carry a grid
/// of tile columns; 2 had one velocity per row, 1 had them in 1/256 px
/// per tick).
pub const VERSION: u8 = 3;
/// Header bytes.
pub const HEADER_LEN: usize = 30;
/// CRC bytes.
pub const CRC_LEN: usize = 4;
/// Largest payload, bytes.
pub const MAX_PAYLOAD: usize = 16 * 1024;
/// Largest message before COBS, bytes.
pub const MAX_MESSAGE: usize = HEADER_LEN + MAX_PAYLOAD + CRC_LEN;
/// Largest message on the wire: COBS overhead and the delimiter included.
pub const MAX_ENCODED: usize = cobs::max_encoding_length(MAX_MESSAGE) + 1;

/// What a message carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Kind {
    /// A band of rows `row0..row0+rows` of frame `frame_id`.
    FrameTile = 1,
    /// Frame `frame_id` is complete; payload [`FrameEnd`].
    FrameEnd = 2,
    /// The firmware's counters; payload [`Status`].
    Status = 3,
    /// Host to sidecar: predicted motion and window caps; payload
    /// [`control::ControlView`].
    Control = 4,
    /// Host to sidecar, the live loop: the rung frames and events of the
    /// next pairs and the flow they follow; payload [`ask::AskView`].
    Ask = 5,
    /// Sidecar to host, the live loop: what the pair's parts that follow
    /// carry; payload [`pair::PairHead`].
    PairHead = 6,
}

impl Kind {
    fn from_u8(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::FrameTile),
            2 => Some(Kind::FrameEnd),
            3 => Some(Kind::Status),
            4 => Some(Kind::Control),
            5 => Some(Kind::Ask),
            6 => Some(Kind::PairHead),
            _ => None,
        }
    }
}

/// How a tile's payload codes its samples (layouts in `docs/protocol.md`
/// and [`crate::wire::codec`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Encoding {
    /// No samples (frame end, status).
    None = 0,
    /// One byte per sample, row by row (lossless, levels ≤ 255).
    Raw8 = 1,
    /// Two bytes per sample, little-endian (lossless).
    Raw16 = 2,
    /// Adaptive Rice code of left-neighbour residuals (lossless).
    Rice = 3,
    /// Background at low resolution, particles exact (lossy).
    Sparse = 4,
    /// Median-predictor residuals range-coded with neighbourhood contexts
    /// (lossless).
    Context = 5,
    /// `Sparse`'s samples, range-coded with neighbourhood contexts (lossy,
    /// decodes to exactly what `Sparse` decodes to).
    SparseContext = 6,
}

impl Encoding {
    /// The codecs a user picks, by the names the command lines take.
    pub const NAMED: [(&'static str, Encoding); 5] = [
        ("rice", Encoding::Rice),
        ("context", Encoding::Context),
        ("sparse", Encoding::Sparse),
        ("sparse-context", Encoding::SparseContext),
        ("raw", Encoding::Raw8),
    ];

    /// From its name in [`Encoding::NAMED`].
    pub fn from_name(name: &str) -> Option<Encoding> {
        Encoding::NAMED
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, e)| e)
    }

    /// From the header byte.
    pub fn from_u8(b: u8) -> Option<Encoding> {
        match b {
            0 => Some(Encoding::None),
            1 => Some(Encoding::Raw8),
            2 => Some(Encoding::Raw16),
            3 => Some(Encoding::Rice),
            4 => Some(Encoding::Sparse),
            5 => Some(Encoding::Context),
            6 => Some(Encoding::SparseContext),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(seq: u32) -> Header {
        Header {
            kind: Kind::FrameTile,
            seq,
            frame_id: 7,
            tick: 1234,
            width: 400,
            height: 250,
            row0: 40,
            rows: 40,
            encoding: Encoding::Raw8,
            payload_len: 0,
        }
    }

    #[test]
    fn round_trip_any_chunking() {
        let payload: [u8; 300] = core::array::from_fn(|i| (i * 7) as u8);
        let mut wire = [0u8; 1024];
        let n = encode_message(&header(5), &payload, &mut wire).unwrap();
        assert_eq!(wire[n - 1], 0);
        assert!(!wire[..n - 1].contains(&0));
        for chunk in [1, 2, 7, 64, n] {
            let mut rx = [0u8; MAX_ENCODED];
            let mut dec = Decoder::new(&mut rx);
            let mut got = 0;
            for part in wire[..n].chunks(chunk) {
                let mut input = part;
                while let Some(m) = dec.feed(&mut input) {
                    let m = m.unwrap();
                    assert_eq!(m.header.seq, 5);
                    assert_eq!(m.payload, &payload[..]);
                    got += 1;
                }
            }
            assert_eq!(got, 1);
        }
    }

    #[test]
    fn gaps_and_late_messages_are_counted() {
        let mut rx = [0u8; 4096];
        let mut dec = Decoder::new(&mut rx);
        let mut wire = [0u8; 256];
        for seq in [0u32, 1, 3, 2, 4] {
            let n = encode_message(&header(seq), &[1, 2, 3], &mut wire).unwrap();
            let mut input = &wire[..n];
            assert!(dec.feed(&mut input).unwrap().is_ok());
        }
        let s = dec.stats();
        assert_eq!((s.messages, s.lost, s.late), (5, 0, 1));
    }

    #[test]
    fn overflow_is_dropped_and_resynchronised() {
        let mut rx = [0u8; 64];
        let mut dec = Decoder::new(&mut rx);
        let junk = [0x55u8; 200];
        let mut input = &junk[..];
        assert!(dec.feed(&mut input).is_none());
        let mut wire = [0u8; 128];
        let n = encode_message(&header(0), &[9; 8], &mut wire).unwrap();
        let mut input = &wire[..n];
        assert_eq!(dec.feed(&mut input), Some(Err(WireError::Overflow.into())));
        let mut input = &wire[..n];
        assert!(dec.feed(&mut input).unwrap().is_ok());
    }

    #[test]
    fn end_and_status_round_trip() {
        let e = FrameEnd {
            pair: 3,
            member: 1,
            method: crate::method::Method::Adaptive,
            full_scale: 255,
            dt: 13,
            tiles: 7,
            lossy: 1,
            frame_crc: 0xDEAD_BEEF,
        };
        assert_eq!(FrameEnd::parse(&e.to_bytes()), Ok(e));
        let s = Status {
            planes: 1,
            frames: 2,
            messages: 3,
            dropped_planes: 4,
            bytes: 1 << 40,
            controls_applied: 5,
            controls_refused: 6,
        };
        assert_eq!(Status::parse(&s.to_bytes()), Ok(s));
        // A status from before the downlink: no control counts.
        let old = Status::parse(&s.to_bytes()[..Status::LEN_V0]).unwrap();
        assert_eq!((old.bytes, old.controls_applied), (1 << 40, 0));
        assert!(Status::parse(&s.to_bytes()[..28]).is_err());
    }
}
