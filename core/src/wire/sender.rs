//! The sending half of a sidecar: the pair schedule (docs/spec.md §8) and the
//! messages that carry a frame — tiles coded by [`crate::wire::codec`], framed
//! by [`crate::wire`], then a frame end and, now and then, a status. The
//! simulated firmware on the host and firmware on a real MCU run this same
//! code, so they put the same bytes on the wire.
//!
//! No allocation: the payload, COBS and codec buffers are the caller's
//! ([`SendBuffers`]); bytes leave through the caller's [`Link`].

use crate::error::{Error, LinkError};
use crate::gray::Gray;
use crate::wire::codec::{decode_tile, encode_tile, Lossy};
use crate::wire::{
    encode_message, frame_crc, Encoding, FrameEnd, Header, Kind, Status, WireError, MAX_PAYLOAD,
};

/// Where messages go: a USB endpoint, a UART, a socket, memory.
pub trait Link {
    /// The link's error.
    type Error;
    /// Sends one whole message (COBS-framed, delimiter included).
    fn send(&mut self, message: &[u8]) -> Result<(), Self::Error>;
}

/// When frames are made: pair `p` has its frames at ticks
/// `first + p·every` (member 0) and that plus `dt` (member 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Schedule {
    /// Tick of the first pair's first frame.
    pub first: u32,
    /// Ticks between the frames of a pair (Δt ≥ 1).
    pub dt: u32,
    /// Ticks between pairs (M ≥ Δt).
    pub every: u32,
    /// Pairs to send; `None`: until the input ends.
    pub pairs: Option<u32>,
}

/// One scheduled frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Slot {
    /// Centre tick.
    pub tick: u32,
    /// Pair counter.
    pub pair: u32,
    /// 0: the frame at k; 1: at k + Δt.
    pub member: u8,
}

impl Schedule {
    /// Frame number `n` of the stream (0, 1, 2, …), or `None` past the end
    /// (or past `u32` ticks).
    pub fn slot(&self, n: u64) -> Option<Slot> {
        let pair = u32::try_from(n / 2).ok()?;
        if self.pairs.is_some_and(|p| pair >= p) {
            return None;
        }
        let member = (n % 2) as u8;
        let k = u64::from(self.first)
            + u64::from(pair) * u64::from(self.every)
            + u64::from(member) * u64::from(self.dt);
        Some(Slot {
            tick: u32::try_from(k).ok()?,
            pair,
            member,
        })
    }

    /// True when a frame centred on `tick` with a window of `window` ticks
    /// can be made once plane `newest` has arrived: its window's last plane
    /// is `tick + ⌈window/2⌉ − 1`.
    pub fn ready(tick: u32, window: u16, newest: u32) -> bool {
        let ahead = u32::from(window - window / 2).saturating_sub(1);
        tick.saturating_add(ahead) <= newest
    }
}

/// Rows per tile for a `width`-pixel frame: as many as fit one payload raw
/// (`wide`: 16-bit samples), rounded down to a multiple of the sparse block
/// when the frame is taller, at most `height`. Zero when one row does not fit.
pub const fn tile_rows(width: u16, height: u16, wide: bool, block: u8) -> u16 {
    let bytes = if wide { 2 } else { 1 };
    let per_row = width as usize * bytes;
    if per_row == 0 {
        return 0;
    }
    let max_rows = MAX_PAYLOAD / per_row;
    let mut rows = if max_rows < height as usize {
        max_rows
    } else {
        height as usize
    };
    let b = if block == 0 { 1 } else { block as usize };
    if rows >= b && rows < height as usize {
        rows -= rows % b;
    }
    rows as u16
}

/// What the frame end says about a frame besides its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameInfo {
    /// Where it sits in the schedule.
    pub slot: Slot,
    /// How the frame was made.
    pub method: crate::method::Method,
    /// Gray level of full scale.
    pub full_scale: u16,
    /// Ticks between the pair's frames.
    pub dt: u32,
}

/// The caller's buffers: a payload of [`MAX_PAYLOAD`] bytes, a COBS output
/// of [`crate::wire::MAX_ENCODED`] bytes, and the sparse codec's scratch
/// ([`crate::wire::codec::tile_scratch`] samples for one tile; empty when
/// the encoding is never `Sparse`).
#[derive(Debug)]
pub struct SendBuffers<'b> {
    /// Tile payload.
    pub payload: &'b mut [u8],
    /// One framed message.
    pub wire: &'b mut [u8],
    /// Sparse codec scratch.
    pub scratch: &'b mut [u16],
}

/// Counts of what was sent (and what a status message reports).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sent {
    /// Planes ingested (the caller counts them; status reports them).
    pub planes: u32,
    /// Frames sent.
    pub frames: u32,
    /// Messages sent.
    pub messages: u32,
    /// Bytes sent.
    pub bytes: u64,
    /// Tiles per encoding actually used: raw8, raw16, lossless coded (Rice,
    /// Context), lossy (Sparse, SparseContext).
    pub tiles: [u32; 4],
    /// Control messages that took effect (the caller counts them; status
    /// reports them).
    pub controls_applied: u32,
    /// Downlink chunks refused (the caller counts them).
    pub controls_refused: u32,
}

/// The sender: message sequence numbers, frame ids and counts. It holds no
/// buffers; each call borrows the caller's [`SendBuffers`].
#[derive(Debug, Clone)]
pub struct Sender {
    width: u16,
    height: u16,
    tile_rows: u16,
    seq: u32,
    /// What was sent so far.
    pub sent: Sent,
}

impl Sender {
    /// A sender of `width × height` frames in bands of `tile_rows` rows
    /// (see [`tile_rows`]).
    pub fn new(width: u16, height: u16, tile_rows: u16) -> Result<Self, Error> {
        if width == 0 || height == 0 || tile_rows == 0 {
            return Err(WireError::Field.into());
        }
        Ok(Sender {
            width,
            height,
            tile_rows,
            seq: 0,
            sent: Sent::default(),
        })
    }

    /// Rows per tile.
    pub fn tile_rows(&self) -> u16 {
        self.tile_rows
    }

    /// Sends `frame` (stored row order, `width × height` samples) as tiles
    /// coded `encoding` (lossy: with [`Lossy::for_method`] of the frame's
    /// method) and a frame end. Lossy tiles are decoded back into
    /// `frame`, so after the call it holds exactly what a receiver gets and
    /// the frame CRC covers that.
    pub fn send_frame<G: Gray, L: Link>(
        &mut self,
        buf: &mut SendBuffers<'_>,
        frame: &mut [G],
        info: &FrameInfo,
        encoding: Encoding,
        lossy: &Lossy,
        link: &mut L,
    ) -> Result<(), LinkError<L::Error>> {
        let w = usize::from(self.width);
        let n = w * usize::from(self.height);
        let frame = frame.get_mut(..n).ok_or(WireError::Payload)?;
        let frame_id = self.sent.frames;
        let (mut tiles, mut any_lossy, mut row0) = (0u16, 0u8, 0u16);
        let lossy = &lossy.for_method(info.method);
        while row0 < self.height {
            let rows = self.tile_rows.min(self.height - row0);
            let span = usize::from(row0) * w..(usize::from(row0) + usize::from(rows)) * w;
            let (enc, len) = encode_tile(
                encoding,
                &frame[span.clone()],
                self.width,
                rows,
                lossy,
                buf.scratch,
                buf.payload,
            )?;
            if matches!(enc, Encoding::Sparse | Encoding::SparseContext) {
                decode_tile(
                    enc,
                    &buf.payload[..len],
                    self.width,
                    rows,
                    buf.scratch,
                    &mut frame[span],
                )?;
                any_lossy = 1;
            }
            let slot = match enc {
                Encoding::Raw8 => 0,
                Encoding::Raw16 => 1,
                Encoding::Rice | Encoding::Context => 2,
                _ => 3,
            };
            self.sent.tiles[slot] = self.sent.tiles[slot].saturating_add(1);
            let h = self.header(Kind::FrameTile, frame_id, info.slot.tick, row0, rows, enc);
            let m = encode_message(&h, &buf.payload[..len], buf.wire)?;
            self.emit(buf, m, link)?;
            tiles = tiles.saturating_add(1);
            row0 += rows;
        }
        let end = FrameEnd {
            pair: info.slot.pair,
            member: info.slot.member,
            method: info.method,
            full_scale: info.full_scale,
            dt: info.dt,
            tiles,
            lossy: any_lossy,
            frame_crc: frame_crc(frame),
        };
        let h = self.header(
            Kind::FrameEnd,
            frame_id,
            info.slot.tick,
            0,
            0,
            Encoding::None,
        );
        let m = encode_message(&h, &end.to_bytes(), buf.wire)?;
        self.emit(buf, m, link)?;
        self.sent.frames = self.sent.frames.wrapping_add(1);
        Ok(())
    }

    /// Sends the head of a live-loop pair ([`super::pair::PairHead`]),
    /// before its parts: its frame id is the next frame's, its tick the
    /// pair's midpoint.
    pub fn send_pair_head<L: Link>(
        &mut self,
        buf: &mut SendBuffers<'_>,
        head: &super::pair::PairHead,
        link: &mut L,
    ) -> Result<(), LinkError<L::Error>> {
        head.check()?;
        let h = self.header(
            Kind::PairHead,
            self.sent.frames,
            head.mid,
            0,
            0,
            Encoding::None,
        );
        let m = encode_message(&h, &head.to_bytes(), buf.wire)?;
        self.emit(buf, m, link)
    }

    /// Sends a status message with the counts so far.
    pub fn send_status<L: Link>(
        &mut self,
        buf: &mut SendBuffers<'_>,
        link: &mut L,
    ) -> Result<(), LinkError<L::Error>> {
        let s = Status {
            planes: self.sent.planes,
            frames: self.sent.frames,
            messages: self.sent.messages.wrapping_add(1),
            dropped_planes: 0,
            bytes: self.sent.bytes,
            controls_applied: self.sent.controls_applied,
            controls_refused: self.sent.controls_refused,
        };
        let h = self.header(Kind::Status, 0, 0, 0, 0, Encoding::None);
        let m = encode_message(&h, &s.to_bytes(), buf.wire)?;
        self.emit(buf, m, link)
    }

    fn header(
        &self,
        kind: Kind,
        frame_id: u32,
        tick: u32,
        row0: u16,
        rows: u16,
        encoding: Encoding,
    ) -> Header {
        Header {
            kind,
            seq: self.seq,
            frame_id,
            tick,
            width: self.width,
            height: self.height,
            row0,
            rows,
            encoding,
            payload_len: 0,
        }
    }

    fn emit<L: Link>(
        &mut self,
        buf: &SendBuffers<'_>,
        n: usize,
        link: &mut L,
    ) -> Result<(), LinkError<L::Error>> {
        let bytes = buf.wire.get(..n).ok_or(WireError::TooLarge)?;
        link.send(bytes).map_err(LinkError::Link)?;
        self.seq = self.seq.wrapping_add(1);
        self.sent.messages = self.sent.messages.wrapping_add(1);
        self.sent.bytes = self.sent.bytes.saturating_add(n as u64);
        Ok(())
    }
}
