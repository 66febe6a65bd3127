//! The wire format between sidecar and host (SPEC section 8), pinned:
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
//! ([`Kind::Status`], payload [`Status`]). Payloads are at most
//! [`MAX_PAYLOAD`] = 16 KiB, so a device needs one message buffer of
//! [`MAX_MESSAGE`] bytes and one COBS buffer of [`MAX_ENCODED`] bytes.
//!
//! The [`Decoder`] takes bytes in any chunking, resynchronises on the next
//! `0x00` after corruption, loss or truncation, counts what it lost and never
//! panics; its receive buffer is caller-supplied, and bytes beyond it before
//! a delimiter are dropped and counted.

use crc::{Crc, CRC_32_ISO_HDLC};

/// `"SP"`.
pub const MAGIC: u16 = 0x5053;
/// The version this code writes and reads.
pub const VERSION: u8 = 1;
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

/// The CRC of the link: CRC-32/ISO-HDLC, as zlib's `crc32`.
pub const CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

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
}

impl Kind {
    fn from_u8(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::FrameTile),
            2 => Some(Kind::FrameEnd),
            3 => Some(Kind::Status),
            _ => None,
        }
    }
}

/// How a tile's payload codes its samples (layouts in `docs/protocol.md`
/// and [`crate::compress`]).
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
}

impl Encoding {
    /// From the header byte.
    pub fn from_u8(b: u8) -> Option<Encoding> {
        match b {
            0 => Some(Encoding::None),
            1 => Some(Encoding::Raw8),
            2 => Some(Encoding::Raw16),
            3 => Some(Encoding::Rice),
            4 => Some(Encoding::Sparse),
            _ => None,
        }
    }
}

/// Why bytes were not a message, or a message could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireError {
    /// More bytes than the receive buffer before a delimiter (dropped).
    Overflow,
    /// Not valid COBS.
    Cobs,
    /// Shorter than a header and a CRC, or `payload_len` disagrees with the
    /// message length.
    Length,
    /// The CRC does not match.
    Crc,
    /// Wrong magic.
    Magic,
    /// A version this code does not read.
    Version,
    /// Unknown kind or encoding.
    Field,
    /// A payload above [`MAX_PAYLOAD`], or an output buffer too small.
    TooLarge,
    /// A payload that does not decode to the rows its header names.
    Payload,
}

impl core::fmt::Display for WireError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            WireError::Overflow => "message longer than the receive buffer",
            WireError::Cobs => "invalid COBS framing",
            WireError::Length => "message length disagrees with its header",
            WireError::Crc => "CRC mismatch",
            WireError::Magic => "bad magic",
            WireError::Version => "unsupported protocol version",
            WireError::Field => "unknown message kind or encoding",
            WireError::TooLarge => "payload or buffer too large",
            WireError::Payload => "payload does not decode to its rows",
        })
    }
}

#[cfg(feature = "std")]
extern crate std;
#[cfg(feature = "std")]
impl std::error::Error for WireError {}

/// A message header (the 30 bytes before the payload).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Header {
    /// What the message carries.
    pub kind: Kind,
    /// Message counter, wrapping; a gap is a lost message.
    pub seq: u32,
    /// Frame counter.
    pub frame_id: u32,
    /// The frame's centre tick (planes since the stream began).
    pub tick: u32,
    /// Frame width, px.
    pub width: u16,
    /// Frame height, px.
    pub height: u16,
    /// First row of the band, stored row order.
    pub row0: u16,
    /// Rows in the band (0 for frame end and status).
    pub rows: u16,
    /// How the payload codes samples.
    pub encoding: Encoding,
    /// Payload bytes.
    pub payload_len: u32,
}

impl Header {
    /// The 30 header bytes.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[0..2].copy_from_slice(&MAGIC.to_le_bytes());
        b[2] = VERSION;
        b[3] = self.kind as u8;
        b[4..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..12].copy_from_slice(&self.frame_id.to_le_bytes());
        b[12..16].copy_from_slice(&self.tick.to_le_bytes());
        b[16..18].copy_from_slice(&self.width.to_le_bytes());
        b[18..20].copy_from_slice(&self.height.to_le_bytes());
        b[20..22].copy_from_slice(&self.row0.to_le_bytes());
        b[22..24].copy_from_slice(&self.rows.to_le_bytes());
        b[24] = self.encoding as u8;
        b[25] = 0;
        b[26..30].copy_from_slice(&self.payload_len.to_le_bytes());
        b
    }

    /// Parses and checks magic, version, kind and encoding.
    pub fn parse(b: &[u8]) -> Result<Header, WireError> {
        let b: &[u8; HEADER_LEN] = b
            .get(..HEADER_LEN)
            .and_then(|s| s.try_into().ok())
            .ok_or(WireError::Length)?;
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        if u16_at(0) != MAGIC {
            return Err(WireError::Magic);
        }
        if b[2] != VERSION {
            return Err(WireError::Version);
        }
        Ok(Header {
            kind: Kind::from_u8(b[3]).ok_or(WireError::Field)?,
            seq: u32_at(4),
            frame_id: u32_at(8),
            tick: u32_at(12),
            width: u16_at(16),
            height: u16_at(18),
            row0: u16_at(20),
            rows: u16_at(22),
            encoding: Encoding::from_u8(b[24]).ok_or(WireError::Field)?,
            payload_len: u32_at(26),
        })
    }
}

/// Frames one message into `out`: COBS of header, payload and CRC, then the
/// `0x00` delimiter. Returns the bytes written (at most [`MAX_ENCODED`]).
/// `header.payload_len` is set from `payload`.
pub fn encode_message(header: &Header, payload: &[u8], out: &mut [u8]) -> Result<usize, WireError> {
    if payload.len() > MAX_PAYLOAD {
        return Err(WireError::TooLarge);
    }
    let mut h = *header;
    h.payload_len = payload.len() as u32;
    let hb = h.to_bytes();
    let mut digest = CRC.digest();
    digest.update(&hb);
    digest.update(payload);
    let crc = digest.finalize().to_le_bytes();
    let mut enc = cobs::CobsEncoder::new(out);
    enc.push(&hb).map_err(|_| WireError::TooLarge)?;
    enc.push(payload).map_err(|_| WireError::TooLarge)?;
    enc.push(&crc).map_err(|_| WireError::TooLarge)?;
    let n = enc.finalize();
    let end = out.get_mut(n).ok_or(WireError::TooLarge)?;
    *end = 0;
    Ok(n + 1)
}

/// One decoded message: its header and a view of its payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Message<'a> {
    /// The header.
    pub header: Header,
    /// The payload (`header.payload_len` bytes).
    pub payload: &'a [u8],
}

/// What a decoder has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecoderStats {
    /// Bytes fed.
    pub bytes: u64,
    /// Messages delivered.
    pub messages: u64,
    /// Delimited chunks that were not a valid message (COBS, length, CRC,
    /// magic, version, field).
    pub corrupt: u64,
    /// Chunks longer than the receive buffer, dropped.
    pub overflow: u64,
    /// Messages missing by sequence number (net of late arrivals).
    pub lost: u64,
    /// Messages that arrived after a later one.
    pub late: u64,
}

/// A stream decoder over a caller-supplied receive buffer (at least
/// [`MAX_ENCODED`] bytes to receive every legal message).
#[derive(Debug)]
pub struct Decoder<'b> {
    buf: &'b mut [u8],
    len: usize,
    overflow: bool,
    next_seq: Option<u32>,
    stats: DecoderStats,
}

impl<'b> Decoder<'b> {
    /// A decoder receiving into `buf`.
    pub fn new(buf: &'b mut [u8]) -> Self {
        Decoder {
            buf,
            len: 0,
            overflow: false,
            next_seq: None,
            stats: DecoderStats::default(),
        }
    }

    /// The counts so far.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Bytes held of a message not yet delimited (a truncated tail at the
    /// end of a stream shows here).
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Consumes `input` up to and including the next delimiter that closes
    /// a non-empty chunk; returns that chunk as a message or as the reason
    /// it is not one. `None` once `input` is used up with no chunk closed.
    pub fn feed<'s>(&'s mut self, input: &mut &[u8]) -> Option<Result<Message<'s>, WireError>> {
        loop {
            let Some(pos) = input.iter().position(|&b| b == 0) else {
                self.take(input);
                self.stats.bytes += input.len() as u64;
                *input = &[];
                return None;
            };
            let (body, rest) = input.split_at(pos);
            self.take(body);
            self.stats.bytes += pos as u64 + 1;
            *input = &rest[1..];
            if self.overflow {
                self.overflow = false;
                self.len = 0;
                self.stats.overflow += 1;
                return Some(Err(WireError::Overflow));
            }
            if self.len == 0 {
                continue;
            }
            let len = core::mem::take(&mut self.len);
            return Some(self.check(len));
        }
    }

    fn take(&mut self, bytes: &[u8]) {
        if self.overflow {
            return;
        }
        match self.buf.get_mut(self.len..self.len + bytes.len()) {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                self.len += bytes.len();
            }
            None => self.overflow = true,
        }
    }

    fn check(&mut self, len: usize) -> Result<Message<'_>, WireError> {
        let r = validate(&mut self.buf[..len]);
        let (header, n) = match r {
            Ok(v) => v,
            Err(e) => {
                self.stats.corrupt += 1;
                return Err(e);
            }
        };
        self.stats.messages += 1;
        match self.next_seq {
            Some(next) if header.seq != next => {
                let gap = header.seq.wrapping_sub(next);
                if gap < 1 << 31 {
                    self.stats.lost += u64::from(gap);
                    self.next_seq = Some(header.seq.wrapping_add(1));
                } else {
                    self.stats.late += 1;
                    self.stats.lost = self.stats.lost.saturating_sub(1);
                }
            }
            _ => self.next_seq = Some(header.seq.wrapping_add(1)),
        }
        let payload = &self.buf[HEADER_LEN..HEADER_LEN + n];
        Ok(Message { header, payload })
    }
}

/// COBS-decodes a chunk in place and checks it; returns the header and the
/// payload length.
fn validate(chunk: &mut [u8]) -> Result<(Header, usize), WireError> {
    let n = cobs::decode_in_place(chunk).map_err(|_| WireError::Cobs)?;
    let msg = chunk.get(..n).ok_or(WireError::Cobs)?;
    if n < HEADER_LEN + CRC_LEN {
        return Err(WireError::Length);
    }
    let (body, crc) = msg.split_at(n - CRC_LEN);
    let want = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if CRC.checksum(body) != want {
        return Err(WireError::Crc);
    }
    let header = Header::parse(body)?;
    let plen = body.len() - HEADER_LEN;
    if header.payload_len as usize != plen || plen > MAX_PAYLOAD {
        return Err(WireError::Length);
    }
    Ok((header, plen))
}

/// Payload of [`Kind::FrameEnd`] (20 bytes): which pair the frame belongs
/// to and a CRC of the whole frame, so a receiver knows it reassembled it
/// bit-exact.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameEnd {
    /// Pair counter.
    pub pair: u32,
    /// 0 for the first frame of the pair (tick k), 1 for the second (k + dt).
    pub member: u8,
    /// How the frame was made: 0 adaptive, 1 TFP, 2 TFI.
    pub method: u8,
    /// Gray level of full scale.
    pub full_scale: u16,
    /// Ticks between the pair's frames.
    pub dt: u32,
    /// Tiles sent for this frame.
    pub tiles: u16,
    /// 1 when any tile was coded lossy.
    pub lossy: u8,
    /// CRC-32 of the frame's samples as little-endian u16, stored row order,
    /// as the sidecar computed them (lossy tiles: as the receiver decodes).
    pub frame_crc: u32,
}

impl FrameEnd {
    /// Payload bytes.
    pub const LEN: usize = 20;

    /// The payload.
    pub fn to_bytes(&self) -> [u8; Self::LEN] {
        let mut b = [0u8; Self::LEN];
        b[0..4].copy_from_slice(&self.pair.to_le_bytes());
        b[4] = self.member;
        b[5] = self.method;
        b[6..8].copy_from_slice(&self.full_scale.to_le_bytes());
        b[8..12].copy_from_slice(&self.dt.to_le_bytes());
        b[12..14].copy_from_slice(&self.tiles.to_le_bytes());
        b[14] = self.lossy;
        b[16..20].copy_from_slice(&self.frame_crc.to_le_bytes());
        b
    }

    /// Parses a payload.
    pub fn parse(b: &[u8]) -> Result<FrameEnd, WireError> {
        let b: &[u8; Self::LEN] = b.try_into().map_err(|_| WireError::Payload)?;
        Ok(FrameEnd {
            pair: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            member: b[4],
            method: b[5],
            full_scale: u16::from_le_bytes([b[6], b[7]]),
            dt: u32::from_le_bytes([b[8], b[9], b[10], b[11]]),
            tiles: u16::from_le_bytes([b[12], b[13]]),
            lossy: b[14],
            frame_crc: u32::from_le_bytes([b[16], b[17], b[18], b[19]]),
        })
    }
}

/// Payload of [`Kind::Status`] (24 bytes): the firmware's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Spike planes ingested.
    pub planes: u32,
    /// Frames sent.
    pub frames: u32,
    /// Messages sent (this one included).
    pub messages: u32,
    /// Planes the firmware could not ingest (input stalls, overruns).
    pub dropped_planes: u32,
    /// Bytes sent before this message.
    pub bytes: u64,
}

impl Status {
    /// Payload bytes.
    pub const LEN: usize = 24;

    /// The payload.
    pub fn to_bytes(&self) -> [u8; Self::LEN] {
        let mut b = [0u8; Self::LEN];
        b[0..4].copy_from_slice(&self.planes.to_le_bytes());
        b[4..8].copy_from_slice(&self.frames.to_le_bytes());
        b[8..12].copy_from_slice(&self.messages.to_le_bytes());
        b[12..16].copy_from_slice(&self.dropped_planes.to_le_bytes());
        b[16..24].copy_from_slice(&self.bytes.to_le_bytes());
        b
    }

    /// Parses a payload.
    pub fn parse(b: &[u8]) -> Result<Status, WireError> {
        let b: &[u8; Self::LEN] = b.try_into().map_err(|_| WireError::Payload)?;
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(&b[16..24]);
        Ok(Status {
            planes: u32_at(0),
            frames: u32_at(4),
            messages: u32_at(8),
            dropped_planes: u32_at(12),
            bytes: u64::from_le_bytes(bytes),
        })
    }
}

/// CRC-32 of frame samples as little-endian u16 (the [`FrameEnd`] check).
pub fn frame_crc<G: crate::gray::Gray>(samples: &[G]) -> u32 {
    let mut d = CRC.digest();
    for s in samples {
        d.update(&s.level().to_le_bytes());
    }
    d.finalize()
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
    fn crc_is_zlibs() {
        assert_eq!(CRC.checksum(b"123456789"), 0xCBF4_3926);
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
        assert_eq!(dec.feed(&mut input), Some(Err(WireError::Overflow)));
        let mut input = &wire[..n];
        assert!(dec.feed(&mut input).unwrap().is_ok());
    }

    #[test]
    fn end_and_status_round_trip() {
        let e = FrameEnd {
            pair: 3,
            member: 1,
            method: 0,
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
        };
        assert_eq!(Status::parse(&s.to_bytes()), Ok(s));
    }
}
