//! Framing: a message out as COBS with its CRC and delimiter, and the
//! stream [`Decoder`] that takes bytes in any chunking and resynchronises on
//! the next delimiter.

use super::{crc32, Crc32, Header, WireError, CRC_LEN, HEADER_LEN, MAX_PAYLOAD};
use crate::error::Error;

/// Frames one message into `out`: COBS of header, payload and CRC, then the
/// `0x00` delimiter. Returns the bytes written (at most [`MAX_ENCODED`]).
/// `header.payload_len` is set from `payload`.
///
/// A message framed and read back by the stream decoder:
///
/// ```
/// use spiv_core::wire::{encode_message, Decoder, Encoding, Header, Kind, WireError};
/// use spiv_core::wire::{MAX_ENCODED, MAX_MESSAGE};
///
/// # fn main() -> Result<(), spiv_core::Error> {
/// let header = Header {
///     kind: Kind::Status,
///     seq: 0,
///     frame_id: 0,
///     tick: 0,
///     width: 64,
///     height: 32,
///     row0: 0,
///     rows: 0,
///     encoding: Encoding::None,
///     payload_len: 0,
/// };
/// let mut wire = vec![0u8; MAX_ENCODED];
/// let n = encode_message(&header, &[1, 2, 3], &mut wire)?;
/// let mut rx = vec![0u8; MAX_MESSAGE + 8];
/// let mut dec = Decoder::new(&mut rx);
/// let mut input = &wire[..n];
/// let m = dec.feed(&mut input).ok_or(WireError::Payload)??;
/// assert_eq!((m.header.kind, m.payload), (Kind::Status, &[1u8, 2, 3][..]));
/// # Ok(())
/// # }
/// ```
pub fn encode_message(header: &Header, payload: &[u8], out: &mut [u8]) -> Result<usize, Error> {
    if payload.len() > MAX_PAYLOAD {
        return Err(WireError::TooLarge.into());
    }
    let mut h = *header;
    h.payload_len = payload.len() as u32;
    let hb = h.to_bytes();
    let mut digest = Crc32::new();
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
    state: DecoderState,
}

/// Where a [`Decoder`] stands, without its buffer: a caller that borrows
/// the receive buffer only for each call (the sidecar's downlink) keeps
/// this between calls.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecoderState {
    len: usize,
    overflow: bool,
    next_seq: Option<u32>,
    stats: DecoderStats,
}

impl<'b> Decoder<'b> {
    /// A decoder receiving into `buf`.
    pub fn new(buf: &'b mut [u8]) -> Self {
        Decoder::resume(buf, DecoderState::default())
    }

    /// A decoder that goes on from `state` with `buf` holding the bytes of
    /// the message it had begun (a buffer shorter than those bytes drops
    /// that message as an overflow).
    pub fn resume(buf: &'b mut [u8], mut state: DecoderState) -> Self {
        if state.len > buf.len() {
            state.len = 0;
            state.overflow = true;
        }
        Decoder { buf, state }
    }

    /// Where it stands (for [`Decoder::resume`]).
    pub fn state(&self) -> DecoderState {
        self.state
    }

    /// The counts so far.
    pub fn stats(&self) -> DecoderStats {
        self.state.stats
    }

    /// Bytes held of a message not yet delimited (a truncated tail at the
    /// end of a stream shows here).
    pub fn pending(&self) -> usize {
        self.state.len
    }

    /// Consumes `input` up to and including the next delimiter that closes
    /// a non-empty chunk; returns that chunk as a message or as the reason
    /// it is not one. `None` once `input` is used up with no chunk closed.
    pub fn feed<'s>(&'s mut self, input: &mut &[u8]) -> Option<Result<Message<'s>, Error>> {
        loop {
            let Some(pos) = input.iter().position(|&b| b == 0) else {
                self.take(input);
                self.state.stats.bytes += input.len() as u64;
                *input = &[];
                return None;
            };
            let (body, rest) = input.split_at(pos);
            self.take(body);
            self.state.stats.bytes += pos as u64 + 1;
            *input = &rest[1..];
            if self.state.overflow {
                self.state.overflow = false;
                self.state.len = 0;
                self.state.stats.overflow += 1;
                return Some(Err(WireError::Overflow.into()));
            }
            if self.state.len == 0 {
                continue;
            }
            let len = core::mem::take(&mut self.state.len);
            return Some(self.check(len));
        }
    }

    fn take(&mut self, bytes: &[u8]) {
        if self.state.overflow {
            return;
        }
        match self
            .buf
            .get_mut(self.state.len..self.state.len + bytes.len())
        {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                self.state.len += bytes.len();
            }
            None => self.state.overflow = true,
        }
    }

    fn check(&mut self, len: usize) -> Result<Message<'_>, Error> {
        let r = validate(&mut self.buf[..len]);
        let (header, n) = match r {
            Ok(v) => v,
            Err(e) => {
                self.state.stats.corrupt += 1;
                return Err(e);
            }
        };
        self.state.stats.messages += 1;
        match self.state.next_seq {
            Some(next) if header.seq != next => {
                let gap = header.seq.wrapping_sub(next);
                if gap < 1 << 31 {
                    self.state.stats.lost += u64::from(gap);
                    self.state.next_seq = Some(header.seq.wrapping_add(1));
                } else {
                    self.state.stats.late += 1;
                    self.state.stats.lost = self.state.stats.lost.saturating_sub(1);
                }
            }
            _ => self.state.next_seq = Some(header.seq.wrapping_add(1)),
        }
        let payload = &self.buf[HEADER_LEN..HEADER_LEN + n];
        Ok(Message { header, payload })
    }
}

/// COBS-decodes a chunk in place and checks it; returns the header and the
/// payload length.
fn validate(chunk: &mut [u8]) -> Result<(Header, usize), Error> {
    let n = cobs::decode_in_place(chunk).map_err(|_| WireError::Cobs)?;
    let msg = chunk.get(..n).ok_or(WireError::Cobs)?;
    if n < HEADER_LEN + CRC_LEN {
        return Err(WireError::Length.into());
    }
    let (body, crc) = msg.split_at(n - CRC_LEN);
    let want = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if crc32(body) != want {
        return Err(WireError::Crc.into());
    }
    let header = Header::parse(body)?;
    let plen = body.len() - HEADER_LEN;
    if header.payload_len as usize != plen || plen > MAX_PAYLOAD {
        return Err(WireError::Length.into());
    }
    Ok((header, plen))
}
