//! Messages back into frames and pairs. A frame is delivered only when all
//! its rows arrived and the CRC of the reassembled samples matches the one
//! its frame-end message carries, so every delivered frame is bit-exact with
//! what the sidecar sent; anything else is counted as lost.
//!
//! Memory is bounded before anything is allocated: a message whose header
//! claims a frame of zero pixels or larger than the receiver's
//! [`FrameLimit`] is counted as rejected (and its frame as lost), and at
//! most `OPEN_BEHIND + 1` = 3 frames are open at once, so the assembler
//! holds at most 3 × limit × 2 bytes of samples (400 MB at the default
//! 8192 × 8192).

use std::collections::BTreeMap;

use spiv_core::wire::codec::{decode_tile, tile_scratch};
use spiv_core::wire::{frame_crc, FrameEnd, Kind, Message, Status};

/// A frame as received (stored row order: the camera's rows bottom-up).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReceivedFrame {
    /// Frame counter.
    pub frame_id: u32,
    /// Centre tick.
    pub tick: u32,
    /// Width, px.
    pub width: u16,
    /// Height, px.
    pub height: u16,
    /// Pairing, method, full scale, dt, CRC.
    pub end: FrameEnd,
    /// Samples, stored row order.
    pub data: Vec<u16>,
}

impl ReceivedFrame {
    /// The samples upright (row 0 at the top).
    pub fn upright(&self) -> Vec<u16> {
        crate::reconstruct::upright(&self.data, self.width, true)
    }
}

/// What the assembler counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct AssemblyStats {
    /// Frames delivered bit-exact.
    pub frames: u64,
    /// Frames lost: never seen, missing rows, or failing their CRC.
    pub lost_frames: u64,
    /// Of those, frames whose CRC did not match.
    pub crc_mismatch: u64,
    /// Messages with a valid CRC that were refused all the same: a frame of
    /// zero pixels or over the [`FrameLimit`], rows outside the frame, a
    /// size that disagrees with the frame's other messages, a tile payload
    /// that does not decode, a malformed frame end.
    pub rejected: u64,
    /// Status messages.
    pub status: u64,
}

#[derive(Debug)]
struct Partial {
    tick: u32,
    width: u16,
    height: u16,
    data: Vec<u16>,
    rows: Vec<bool>,
    end: Option<FrameEnd>,
}

/// The largest frame a receiver accepts, px. Default 8192 × 8192.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameLimit {
    /// Widest frame, px.
    pub width: u16,
    /// Tallest frame, px.
    pub height: u16,
}

impl Default for FrameLimit {
    fn default() -> Self {
        FrameLimit {
            width: 8192,
            height: 8192,
        }
    }
}

impl FrameLimit {
    /// Whether a `width × height` frame is non-empty and within the limit.
    pub fn admits(&self, width: u16, height: u16) -> bool {
        width > 0 && height > 0 && width <= self.width && height <= self.height
    }
}

impl std::str::FromStr for FrameLimit {
    type Err = String;
    /// `WxH`, both in `1..=65535`.
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("frame limit {s:?}: expected WxH, each 1..=65535 (e.g. 8192x8192)");
        let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
        let (width, height) = (
            w.trim().parse::<u16>().map_err(|_| bad())?,
            h.trim().parse::<u16>().map_err(|_| bad())?,
        );
        if width == 0 || height == 0 {
            return Err(bad());
        }
        Ok(FrameLimit { width, height })
    }
}

/// Frames in, from messages.
#[derive(Debug, Default)]
pub struct Assembler {
    limit: FrameLimit,
    partial: BTreeMap<u32, Partial>,
    closed: std::collections::BTreeSet<u32>,
    highest: Option<u32>,
    scratch: Vec<u16>,
    stats: AssemblyStats,
    /// The sidecar's last status.
    pub last_status: Option<Status>,
}

/// Frames kept open behind the newest one (reordering tolerated).
const OPEN_BEHIND: u32 = 2;

impl Assembler {
    /// An empty assembler that accepts frames up to `limit`.
    pub fn new(limit: FrameLimit) -> Self {
        Assembler {
            limit,
            ..Self::default()
        }
    }

    /// Refuses a message; a frame that has nothing open yet is lost with it
    /// (closed, so its other messages are not counted twice).
    fn reject(&mut self, id: u32) -> Option<ReceivedFrame> {
        self.stats.rejected += 1;
        if !self.partial.contains_key(&id) && self.closed.insert(id) {
            self.stats.lost_frames += 1;
        }
        None
    }

    /// Counts so far.
    pub fn stats(&self) -> AssemblyStats {
        self.stats
    }

    /// Takes one message; returns a frame when it completes one.
    pub fn push(&mut self, m: &Message<'_>) -> Option<ReceivedFrame> {
        let h = m.header;
        if h.kind == Kind::Status {
            self.stats.status += 1;
            self.last_status = Status::parse(m.payload).ok();
            return None;
        }
        if matches!(h.kind, Kind::Control | Kind::Ask) {
            // A downlink message has no business on the uplink.
            self.stats.rejected += 1;
            return None;
        }
        if h.kind == Kind::PairHead {
            // A live-loop pair's head: its parts are frames, and the
            // pair's reader (`estimator::uplink::PairReader`) reads the head.
            return None;
        }
        let id = h.frame_id;
        // Frames never seen between the highest so far and this one are lost.
        match self.highest {
            None => self.highest = Some(id),
            Some(top) => {
                let ahead = id.wrapping_sub(top);
                if ahead != 0 && ahead < 1 << 31 {
                    self.stats.lost_frames += u64::from(ahead - 1);
                    self.highest = Some(id);
                } else if ahead != 0 && top.wrapping_sub(id) > OPEN_BEHIND {
                    // Too late: its frame was closed and counted already.
                    return None;
                }
            }
        }
        // A size no frame can have is refused whatever its frame's state.
        if !self.limit.admits(h.width, h.height) {
            return self.reject(id);
        }
        if self.closed.contains(&id) {
            return None;
        }
        self.evict(id);
        let px = usize::from(h.width) * usize::from(h.height);
        let p = self.partial.entry(id).or_insert_with(|| Partial {
            tick: h.tick,
            width: h.width,
            height: h.height,
            data: vec![0; px],
            rows: vec![false; usize::from(h.height)],
            end: None,
        });
        if p.width != h.width || p.height != h.height || p.tick != h.tick {
            return self.reject(id);
        }
        match h.kind {
            Kind::FrameTile => {
                let (r0, rows) = (usize::from(h.row0), usize::from(h.rows));
                let w = usize::from(h.width);
                if rows == 0 || r0 + rows > usize::from(h.height) {
                    return self.reject(id);
                }
                let need = tile_scratch(h.encoding, h.width, h.rows, 2);
                if self.scratch.len() < need {
                    self.scratch.resize(need, 0);
                }
                let out = &mut p.data[r0 * w..(r0 + rows) * w];
                if decode_tile(
                    h.encoding,
                    m.payload,
                    h.width,
                    h.rows,
                    &mut self.scratch,
                    out,
                )
                .is_err()
                {
                    return self.reject(id);
                }
                p.rows[r0..r0 + rows].fill(true);
            }
            Kind::FrameEnd => match FrameEnd::parse(m.payload) {
                Ok(e) => p.end = Some(e),
                Err(_) => return self.reject(id),
            },
            Kind::Status | Kind::Control | Kind::Ask | Kind::PairHead => return None,
        }
        self.try_complete(id)
    }

    fn try_complete(&mut self, id: u32) -> Option<ReceivedFrame> {
        let p = self.partial.get(&id)?;
        let end = p.end?;
        if !p.rows.iter().all(|&r| r) {
            return None;
        }
        let p = self.partial.remove(&id)?;
        self.closed.insert(id);
        if frame_crc(&p.data) != end.frame_crc {
            self.stats.crc_mismatch += 1;
            self.stats.lost_frames += 1;
            return None;
        }
        self.stats.frames += 1;
        Some(ReceivedFrame {
            frame_id: id,
            tick: p.tick,
            width: p.width,
            height: p.height,
            end,
            data: p.data,
        })
    }

    /// Closes frames more than [`OPEN_BEHIND`] behind `id` as lost.
    fn evict(&mut self, id: u32) {
        let stale: Vec<u32> = self
            .partial
            .keys()
            .copied()
            .filter(|&k| {
                let behind = id.wrapping_sub(k);
                behind < 1 << 31 && behind > OPEN_BEHIND
            })
            .collect();
        for k in stale {
            self.partial.remove(&k);
            self.stats.lost_frames += 1;
        }
        self.closed
            .retain(|&k| id.wrapping_sub(k) <= OPEN_BEHIND || id.wrapping_sub(k) >= 1 << 31);
    }

    /// At the end of the stream: every open frame is lost.
    pub fn finish(&mut self) -> AssemblyStats {
        self.stats.lost_frames += self.partial.len() as u64;
        // Frames after the last one seen, which the sidecar's final status
        // says it sent, were lost too.
        if let (Some(s), Some(top)) = (self.last_status, self.highest) {
            let seen = u64::from(top) + 1;
            self.stats.lost_frames += u64::from(s.frames).saturating_sub(seen);
        }
        self.partial.clear();
        self.stats
    }
}

/// Frames into pairs (k, k + dt) by their pair counter.
#[derive(Debug, Default)]
pub struct Pairer {
    first: BTreeMap<u32, ReceivedFrame>,
    /// Pairs missing a member (one frame of it lost).
    pub broken: u64,
}

impl Pairer {
    /// Takes a frame; returns a pair when it completes one.
    pub fn push(&mut self, f: ReceivedFrame) -> Option<[ReceivedFrame; 2]> {
        let pair = f.end.pair;
        // Older pairs still waiting lost their second frame.
        let stale: Vec<u32> = self.first.keys().copied().filter(|&p| p < pair).collect();
        for p in stale {
            self.first.remove(&p);
            self.broken += 1;
        }
        if f.end.member == 0 {
            self.first.insert(pair, f);
            return None;
        }
        match self.first.remove(&pair) {
            Some(a) => Some([a, f]),
            None => {
                self.broken += 1;
                None
            }
        }
    }
}
