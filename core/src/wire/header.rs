//! The 30-byte message header.

use super::{Encoding, Kind, WireError, HEADER_LEN, MAGIC, VERSION};
use crate::error::Error;

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
    ///
    /// ```
    /// use spiv_core::wire::{Encoding, Header, Kind};
    /// let h = Header {
    ///     kind: Kind::FrameTile,
    ///     seq: 7,
    ///     frame_id: 2,
    ///     tick: 640,
    ///     width: 400,
    ///     height: 250,
    ///     row0: 40,
    ///     rows: 40,
    ///     encoding: Encoding::Rice,
    ///     payload_len: 1234,
    /// };
    /// assert_eq!(Header::parse(&h.to_bytes()), Ok(h));
    /// let mut bad = h.to_bytes();
    /// bad[0] ^= 1; // the magic
    /// assert!(Header::parse(&bad).is_err());
    /// ```
    pub fn parse(b: &[u8]) -> Result<Header, Error> {
        let b: &[u8; HEADER_LEN] = b
            .get(..HEADER_LEN)
            .and_then(|s| s.try_into().ok())
            .ok_or(WireError::Length)?;
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        if u16_at(0) != MAGIC {
            return Err(WireError::Magic.into());
        }
        if b[2] != VERSION {
            return Err(WireError::Version.into());
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
