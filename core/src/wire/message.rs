//! The payloads that are not samples: the frame end (pairing, method,
//! checksum) and the firmware's status counters.

use super::{Crc32, WireError};
use crate::error::Error;
use crate::method::Method;

/// Payload of [`super::Kind::FrameEnd`] (20 bytes): which pair the frame belongs
/// to and a CRC of the whole frame, so a receiver knows it reassembled it
/// bit-exact.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameEnd {
    /// Pair counter.
    pub pair: u32,
    /// 0 for the first frame of the pair (tick k), 1 for the second (k + dt).
    pub member: u8,
    /// How the frame was made (byte: [`Method::code`]; an unknown code is
    /// a malformed payload).
    pub method: Method,
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
        b[5] = self.method.code();
        b[6..8].copy_from_slice(&self.full_scale.to_le_bytes());
        b[8..12].copy_from_slice(&self.dt.to_le_bytes());
        b[12..14].copy_from_slice(&self.tiles.to_le_bytes());
        b[14] = self.lossy;
        b[16..20].copy_from_slice(&self.frame_crc.to_le_bytes());
        b
    }

    /// Parses a payload.
    pub fn parse(b: &[u8]) -> Result<FrameEnd, Error> {
        let b: &[u8; Self::LEN] = b.try_into().map_err(|_| WireError::Payload)?;
        Ok(FrameEnd {
            pair: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            member: b[4],
            method: Method::from_code(b[5]).ok_or(WireError::Payload)?,
            full_scale: u16::from_le_bytes([b[6], b[7]]),
            dt: u32::from_le_bytes([b[8], b[9], b[10], b[11]]),
            tiles: u16::from_le_bytes([b[12], b[13]]),
            lossy: b[14],
            frame_crc: u32::from_le_bytes([b[16], b[17], b[18], b[19]]),
        })
    }
}

/// Payload of [`super::Kind::Status`] (32 bytes): the firmware's counters.
/// A 24-byte status (firmware from before the downlink) still parses, its
/// control counts 0.
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
    /// Control messages from the host that took effect.
    pub controls_applied: u32,
    /// Chunks on the downlink that were refused: corrupted, malformed, for
    /// another sensor size, or older than one already heard.
    pub controls_refused: u32,
}

impl Status {
    /// Payload bytes.
    pub const LEN: usize = 32;
    /// Payload bytes of a status without the control counts.
    pub const LEN_V0: usize = 24;

    /// The payload.
    pub fn to_bytes(&self) -> [u8; Self::LEN] {
        let mut b = [0u8; Self::LEN];
        b[0..4].copy_from_slice(&self.planes.to_le_bytes());
        b[4..8].copy_from_slice(&self.frames.to_le_bytes());
        b[8..12].copy_from_slice(&self.messages.to_le_bytes());
        b[12..16].copy_from_slice(&self.dropped_planes.to_le_bytes());
        b[16..24].copy_from_slice(&self.bytes.to_le_bytes());
        b[24..28].copy_from_slice(&self.controls_applied.to_le_bytes());
        b[28..32].copy_from_slice(&self.controls_refused.to_le_bytes());
        b
    }

    /// Parses a payload of [`Status::LEN`] or [`Status::LEN_V0`] bytes.
    pub fn parse(b: &[u8]) -> Result<Status, Error> {
        if b.len() != Self::LEN && b.len() != Self::LEN_V0 {
            return Err(WireError::Payload.into());
        }
        let u32_at = |i: usize| match b.get(i..i + 4) {
            Some(s) => u32::from_le_bytes([s[0], s[1], s[2], s[3]]),
            None => 0,
        };
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(&b[16..24]);
        Ok(Status {
            planes: u32_at(0),
            frames: u32_at(4),
            messages: u32_at(8),
            dropped_planes: u32_at(12),
            bytes: u64::from_le_bytes(bytes),
            controls_applied: u32_at(24),
            controls_refused: u32_at(28),
        })
    }
}

/// CRC-32 of frame samples as little-endian u16 (the [`FrameEnd`] check).
pub fn frame_crc<G: crate::gray::Gray>(samples: &[G]) -> u32 {
    // 64 samples' bytes per update: the CRC takes 16 bytes a step (the
    // tables) or 64 (the host's folding), and two bytes per call would
    // leave it the byte-at-a-time tail.
    let mut d = Crc32::new();
    let mut bytes = [0u8; 128];
    for chunk in samples.chunks(64) {
        for (b, s) in bytes.chunks_exact_mut(2).zip(chunk) {
            b.copy_from_slice(&s.level().to_le_bytes());
        }
        d.update(&bytes[..2 * chunk.len()]);
    }
    d.finalize()
}
