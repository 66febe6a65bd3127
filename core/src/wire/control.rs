//! The downlink's one payload: what the host tells the sidecar
//! ([`super::Kind::Control`]) — the predicted motion per stored row on a
//! grid of rows, the adaptive window caps per band, and a lower `n_max`.
//!
//! ```text
//! payload = from_pair u32 | n_max u16 | pitch u16 | nodes u16 | caps u16 |
//!           nodes × (vx i16, vy i16) | caps × cap u16
//! ```
//!
//! - `from_pair`: the first pair it may apply to (the sidecar applies it at
//!   the start of the first pair `≥ from_pair` it has not begun).
//! - `n_max`: the adaptive / motion-compensated window limit, ticks; 0
//!   keeps the sidecar's own (it can only lower it: its history is sized
//!   for its own).
//! - `pitch`: stored rows between velocity nodes (≥ 1 when `nodes > 0`).
//!   Node `i` is the velocity of stored row `i·pitch`, x right and y down in
//!   stored rows, in 1/4096 px per tick ([`crate::motion::Q`]). Rows between
//!   nodes are interpolated linearly ([`ControlView::rows_into`]); rows past
//!   the last node take the last node. `nodes = 0`: no motion (motion-
//!   compensated frames fall back to the paper's adaptive ones).
//! - `caps`: window limits, ticks, per band of
//!   [`crate::sidecar::CAP_BAND`] upright rows, top band first (0 entries:
//!   none).
//!
//! At most [`MAX_NODES`] nodes and [`MAX_CAPS`] caps, so a payload is at
//! most [`MAX_CONTROL_PAYLOAD`] bytes and a device's downlink buffer
//! [`MAX_CONTROL_ENCODED`] bytes.

use super::{Encoding, Header, Kind, WireError, CRC_LEN, HEADER_LEN};

/// Most velocity nodes in a control (8192 rows at a pitch of 4).
pub const MAX_NODES: usize = 2048;
/// Most cap entries (8192 rows in bands of 32).
pub const MAX_CAPS: usize = 256;
/// Bytes before the nodes.
pub const CONTROL_HEAD: usize = 12;
/// Largest control payload, bytes.
pub const MAX_CONTROL_PAYLOAD: usize = CONTROL_HEAD + 4 * MAX_NODES + 2 * MAX_CAPS;
/// Largest control message on the wire (COBS and delimiter included): the
/// receive buffer a sidecar needs for its downlink.
pub const MAX_CONTROL_ENCODED: usize =
    cobs::max_encoding_length(HEADER_LEN + MAX_CONTROL_PAYLOAD + CRC_LEN) + 1;

/// The fixed part of a control.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControlHead {
    /// First pair it may apply to.
    pub from_pair: u32,
    /// Window limit, ticks; 0: the sidecar's own.
    pub n_max: u16,
    /// Stored rows between velocity nodes.
    pub pitch: u16,
}

/// A checked control payload, read in place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControlView<'a> {
    /// The fixed part.
    pub head: ControlHead,
    nodes: &'a [u8],
    caps: &'a [u8],
}

fn u16_at(b: &[u8], i: usize) -> u16 {
    match b.get(i..i + 2) {
        Some(s) => u16::from_le_bytes([s[0], s[1]]),
        None => 0,
    }
}

impl<'a> ControlView<'a> {
    /// Parses and checks a payload: lengths agree, at most [`MAX_NODES`]
    /// nodes and [`MAX_CAPS`] caps, a pitch ≥ 1 when there are nodes.
    pub fn parse(b: &'a [u8]) -> Result<Self, WireError> {
        if b.len() < CONTROL_HEAD {
            return Err(WireError::Payload);
        }
        let head = ControlHead {
            from_pair: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            n_max: u16_at(b, 4),
            pitch: u16_at(b, 6),
        };
        let nodes = usize::from(u16_at(b, 8));
        let caps = usize::from(u16_at(b, 10));
        if nodes > MAX_NODES
            || caps > MAX_CAPS
            || (nodes > 0 && head.pitch == 0)
            || b.len() != CONTROL_HEAD + 4 * nodes + 2 * caps
        {
            return Err(WireError::Payload);
        }
        let (nodes, caps) = b[CONTROL_HEAD..].split_at(4 * nodes);
        Ok(ControlView { head, nodes, caps })
    }

    /// Velocity nodes.
    pub fn nodes(&self) -> usize {
        self.nodes.len() / 4
    }

    /// Node `i`: `(vx, vy)`, 1/4096 px per tick ((0, 0) past the end).
    pub fn node(&self, i: usize) -> (i16, i16) {
        (
            u16_at(self.nodes, 4 * i) as i16,
            u16_at(self.nodes, 4 * i + 2) as i16,
        )
    }

    /// Cap entries.
    pub fn caps(&self) -> usize {
        self.caps.len() / 2
    }

    /// Cap `i`, ticks (0 past the end).
    pub fn cap(&self, i: usize) -> u16 {
        u16_at(self.caps, 2 * i)
    }

    /// The velocity of every stored row into `vx`, `vy` (as many rows as
    /// the shorter holds): linear between nodes, rounded half up, the last
    /// node's beyond it. Nothing is written when there are no nodes.
    pub fn rows_into(&self, vx: &mut [i16], vy: &mut [i16]) {
        let n = self.nodes();
        if n == 0 {
            return;
        }
        let pitch = i32::from(self.head.pitch.max(1));
        let lerp = |a: i16, b: i16, f: i32| -> i16 {
            let d = (i32::from(b) - i32::from(a)) * f;
            let v = i32::from(a) + (2 * d + pitch).div_euclid(2 * pitch);
            v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
        };
        for (r, (x, y)) in vx.iter_mut().zip(vy.iter_mut()).enumerate() {
            let i = r / pitch as usize;
            let f = (r % pitch as usize) as i32;
            let (ax, ay) = self.node(i.min(n - 1));
            if i + 1 >= n {
                (*x, *y) = (ax, ay);
            } else {
                let (bx, by) = self.node(i + 1);
                (*x, *y) = (lerp(ax, bx, f), lerp(ay, by, f));
            }
        }
    }
}

/// Writes a control payload into `out` from velocity nodes `vx`, `vy` (as
/// many as the shorter; at most [`MAX_NODES`]) and `caps` (at most
/// [`MAX_CAPS`]); returns its length.
pub fn encode_control(
    head: &ControlHead,
    vx: &[i16],
    vy: &[i16],
    caps: &[u16],
    out: &mut [u8],
) -> Result<usize, WireError> {
    let nodes = vx.len().min(vy.len());
    if nodes > MAX_NODES || caps.len() > MAX_CAPS || (nodes > 0 && head.pitch == 0) {
        return Err(WireError::Payload);
    }
    let len = CONTROL_HEAD + 4 * nodes + 2 * caps.len();
    let out = out.get_mut(..len).ok_or(WireError::TooLarge)?;
    out[0..4].copy_from_slice(&head.from_pair.to_le_bytes());
    out[4..6].copy_from_slice(&head.n_max.to_le_bytes());
    out[6..8].copy_from_slice(&head.pitch.to_le_bytes());
    out[8..10].copy_from_slice(&(nodes as u16).to_le_bytes());
    out[10..12].copy_from_slice(&(caps.len() as u16).to_le_bytes());
    let (node_bytes, cap_bytes) = out[CONTROL_HEAD..].split_at_mut(4 * nodes);
    for ((d, x), y) in node_bytes.chunks_exact_mut(4).zip(vx).zip(vy) {
        d[0..2].copy_from_slice(&x.to_le_bytes());
        d[2..4].copy_from_slice(&y.to_le_bytes());
    }
    for (d, c) in cap_bytes.chunks_exact_mut(2).zip(caps) {
        d.copy_from_slice(&c.to_le_bytes());
    }
    Ok(len)
}

/// The header of control message `seq` (the host's own counter) for a
/// `width × height` sensor.
pub fn control_header(seq: u32, width: u16, height: u16) -> Header {
    Header {
        kind: Kind::Control,
        seq,
        frame_id: 0,
        tick: 0,
        width,
        height,
        row0: 0,
        rows: 0,
        encoding: Encoding::None,
        payload_len: 0,
    }
}

/// What the host tells the sidecar down the control link
/// (this module's message): window caps per band, the predicted motion
/// per row and a lower window limit.
#[cfg(feature = "std")]
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Control {
    /// Adaptive window limit per band of [`crate::sidecar::CAP_BAND`] upright rows (top
    /// first, the camera's stored rows being bottom-up); empty: `n_max`
    /// everywhere.
    pub caps: std::vec::Vec<u16>,
    /// `Mc` frames: x and y velocity of each stored row, 1/4096 px per tick
    /// (empty: none).
    pub motion: (std::vec::Vec<i16>, std::vec::Vec<i16>),
    /// Window limit, ticks; 0: the sidecar's own.
    pub n_max: u16,
}

#[cfg(feature = "std")]
impl Control {
    /// True when it tells nothing.
    pub fn is_empty(&self) -> bool {
        self.caps.is_empty() && self.motion.0.is_empty() && self.n_max == 0
    }

    /// The framed control message `seq` for a `width × height` sensor,
    /// applying from pair `from_pair`. Rows beyond [`MAX_NODES`] are sent
    /// as every `⌈rows / MAX_NODES⌉`-th row (the sidecar interpolates).
    pub fn message(
        &self,
        from_pair: u32,
        seq: u32,
        width: u16,
        height: u16,
    ) -> Result<std::vec::Vec<u8>, WireError> {
        let (vx, vy) = &self.motion;
        let rows = vx.len().min(vy.len());
        let pitch = rows.div_ceil(MAX_NODES).max(1);
        let nx: std::vec::Vec<i16> = vx.iter().take(rows).step_by(pitch).copied().collect();
        let ny: std::vec::Vec<i16> = vy.iter().take(rows).step_by(pitch).copied().collect();
        let head = ControlHead {
            from_pair,
            n_max: self.n_max,
            pitch: u16::try_from(pitch).map_err(|_| WireError::Payload)?,
        };
        let mut payload = std::vec![0u8; MAX_CONTROL_PAYLOAD];
        let n = encode_control(&head, &nx, &ny, &self.caps, &mut payload)?;
        let mut out = std::vec![0u8; MAX_CONTROL_ENCODED];
        let m =
            super::encode_message(&control_header(seq, width, height), &payload[..n], &mut out)?;
        out.truncate(m);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_the_documented_ones() {
        assert_eq!(MAX_CONTROL_PAYLOAD, 8716);
        assert_eq!(MAX_CONTROL_ENCODED, 8786);
    }

    #[test]
    fn round_trip_and_interpolation() {
        let head = ControlHead {
            from_pair: 7,
            n_max: 96,
            pitch: 4,
        };
        let (vx, vy) = ([0i16, 40, -40], [10i16, 10, 11]);
        let mut buf = [0u8; 64];
        let n = encode_control(&head, &vx, &vy, &[8, 16], &mut buf).unwrap();
        assert_eq!(n, CONTROL_HEAD + 12 + 4);
        let v = ControlView::parse(&buf[..n]).unwrap();
        assert_eq!(v.head, head);
        assert_eq!((v.nodes(), v.caps(), v.cap(1)), (3, 2, 16));
        let (mut x, mut y) = ([0i16; 11], [0i16; 11]);
        v.rows_into(&mut x, &mut y);
        assert_eq!(x, [0, 10, 20, 30, 40, 20, 0, -20, -40, -40, -40]);
        // 10 + 1·f/4 rounded half up: 10, 10, 11 (10.5), 11, then 11 on.
        assert_eq!(y, [10, 10, 10, 10, 10, 10, 11, 11, 11, 11, 11]);
    }

    #[test]
    fn malformed_payloads_are_refused() {
        let mut buf = [0u8; 64];
        let head = ControlHead {
            from_pair: 0,
            n_max: 0,
            pitch: 1,
        };
        let n = encode_control(&head, &[1, 2], &[3, 4], &[], &mut buf).unwrap();
        assert!(ControlView::parse(&buf[..n - 1]).is_err());
        assert!(ControlView::parse(&buf[..5]).is_err());
        let mut zero_pitch = buf;
        zero_pitch[6] = 0;
        assert!(ControlView::parse(&zero_pitch[..n]).is_err());
        let mut many = buf;
        many[8..10].copy_from_slice(&(MAX_NODES as u16 + 1).to_le_bytes());
        assert!(ControlView::parse(&many[..n]).is_err());
        let zero = ControlHead { pitch: 0, ..head };
        assert_eq!(
            encode_control(&zero, &[1], &[1], &[], &mut buf),
            Err(WireError::Payload)
        );
    }
}
