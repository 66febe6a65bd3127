//! The downlink's one payload: what the host tells the sidecar
//! ([`super::Kind::Control`]) — the predicted motion on a grid of rows and
//! tile columns, the adaptive window caps per band, and a lower `n_max`.
//!
//! ```text
//! payload = from_pair u32 | n_max u16 | pitch u16 | nodes u16 | caps u16 |
//!           cols u16 | tile u16 |
//!           nodes × cols × (vx i16, vy i16) | caps × cap u16
//! ```
//!
//! (Wire version 3; version 2 had no `cols` and `tile`: one velocity per
//! node row.)
//!
//! - `from_pair`: the first pair it may apply to (the sidecar applies it at
//!   the start of the first pair `≥ from_pair` it has not begun).
//! - `n_max`: the adaptive / motion-compensated window limit, ticks; 0
//!   keeps the sidecar's own (it can only lower it: its history is sized
//!   for its own).
//! - `pitch`: stored rows between node rows (≥ 1 when `nodes > 0`). Node
//!   row `i` holds the velocities of stored row `i·pitch`, one per tile
//!   column (`cols` of them, each `tile` px wide, a multiple of 64; the
//!   last column also covers the rest of the row: [`crate::motion::Motion`]),
//!   x right and y down in stored rows, in 1/4096 px per tick
//!   ([`crate::motion::Q`]). Rows between node rows are interpolated
//!   linearly per column ([`ControlView::rows_into`]); rows past the last
//!   take the last. `nodes = 0`: no motion (motion-compensated frames fall
//!   back to the paper's adaptive ones). A per-row motion is `cols = 1`.
//! - `caps`: window limits, ticks, per band of
//!   [`crate::sidecar::CAP_BAND`] upright rows, top band first (0 entries:
//!   none).
//!
//! At most [`MAX_NODES`] velocities (`nodes × cols`), [`MAX_CAPS`] caps
//! and [`crate::motion::MAX_COLS`] columns, so a payload is at most
//! [`MAX_CONTROL_PAYLOAD`] bytes and a device's downlink buffer
//! [`MAX_CONTROL_ENCODED`] bytes.

use super::{Encoding, Header, Kind, WireError, CRC_LEN, HEADER_LEN};
use crate::error::Error;

/// Most velocities in a control, node rows × columns (8192 rows at a
/// pitch of 4 per row; a 1024-row sensor in 4 columns at a pitch of 2).
pub const MAX_NODES: usize = 2048;
/// Most cap entries (8192 rows in bands of 32).
pub const MAX_CAPS: usize = 256;
/// Bytes before the nodes.
pub const CONTROL_HEAD: usize = 16;
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
    /// Stored rows between node rows.
    pub pitch: u16,
    /// Tile columns per node row (≥ 1 when there are nodes).
    pub cols: u16,
    /// Tile width, px (a positive multiple of 64 when there are nodes).
    pub tile: u16,
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
    /// velocities and [`MAX_CAPS`] caps; when there are nodes, a pitch
    /// ≥ 1, 1..=[`crate::motion::MAX_COLS`] columns and a tile that is a
    /// positive multiple of 64 px.
    pub fn parse(b: &'a [u8]) -> Result<Self, Error> {
        if b.len() < CONTROL_HEAD {
            return Err(WireError::Payload.into());
        }
        let head = ControlHead {
            from_pair: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            n_max: u16_at(b, 4),
            pitch: u16_at(b, 6),
            cols: u16_at(b, 12),
            tile: u16_at(b, 14),
        };
        let nodes = usize::from(u16_at(b, 8));
        let caps = usize::from(u16_at(b, 10));
        let velocities = nodes * usize::from(head.cols);
        if velocities > MAX_NODES
            || caps > MAX_CAPS
            || (nodes > 0 && !grid_ok(&head))
            || b.len() != CONTROL_HEAD + 4 * velocities + 2 * caps
        {
            return Err(WireError::Payload.into());
        }
        let (nodes, caps) = b[CONTROL_HEAD..].split_at(4 * velocities);
        Ok(ControlView { head, nodes, caps })
    }

    /// Node rows.
    pub fn nodes(&self) -> usize {
        self.nodes.len() / 4 / usize::from(self.head.cols.max(1))
    }

    /// Velocity `i` (node row `i / cols`, column `i % cols`): `(vx, vy)`,
    /// 1/4096 px per tick ((0, 0) past the end).
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

    /// The velocity of every stored row and column into `vx`, `vy` (laid
    /// out `rows × cols`, as many rows as the shorter holds): per column
    /// linear between node rows, rounded half up, the last node row's
    /// beyond it. Nothing is written when there are no nodes.
    pub fn rows_into(&self, vx: &mut [i16], vy: &mut [i16]) {
        let n = self.nodes();
        if n == 0 {
            return;
        }
        let cols = usize::from(self.head.cols.max(1));
        let pitch = i32::from(self.head.pitch.max(1));
        let lerp = |a: i16, b: i16, f: i32| -> i16 {
            let d = (i32::from(b) - i32::from(a)) * f;
            let v = i32::from(a) + (2 * d + pitch).div_euclid(2 * pitch);
            v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
        };
        for (e, (x, y)) in vx.iter_mut().zip(vy.iter_mut()).enumerate() {
            let (r, c) = (e / cols, e % cols);
            let i = r / pitch as usize;
            let f = (r % pitch as usize) as i32;
            let (ax, ay) = self.node(i.min(n - 1) * cols + c);
            if i + 1 >= n {
                (*x, *y) = (ax, ay);
            } else {
                let (bx, by) = self.node((i + 1) * cols + c);
                (*x, *y) = (lerp(ax, bx, f), lerp(ay, by, f));
            }
        }
    }
}

/// Whether a head with nodes describes a grid the sidecar can hold.
fn grid_ok(h: &ControlHead) -> bool {
    h.pitch > 0
        && (1..=crate::motion::MAX_COLS).contains(&h.cols)
        && h.tile > 0
        && h.tile.is_multiple_of(64)
}

/// Writes a control payload into `out` from velocities `vx`, `vy` (node
/// rows × `head.cols`, as many as the shorter, a whole number of rows; at
/// most [`MAX_NODES`]) and `caps` (at most [`MAX_CAPS`]); returns its
/// length.
pub fn encode_control(
    head: &ControlHead,
    vx: &[i16],
    vy: &[i16],
    caps: &[u16],
    out: &mut [u8],
) -> Result<usize, Error> {
    let velocities = vx.len().min(vy.len());
    let cols = usize::from(head.cols.max(1));
    if velocities > MAX_NODES
        || caps.len() > MAX_CAPS
        || (velocities > 0 && (!grid_ok(head) || !velocities.is_multiple_of(cols)))
    {
        return Err(WireError::Payload.into());
    }
    let nodes = velocities / cols;
    let len = CONTROL_HEAD + 4 * velocities + 2 * caps.len();
    let out = out.get_mut(..len).ok_or(WireError::TooLarge)?;
    out[0..4].copy_from_slice(&head.from_pair.to_le_bytes());
    out[4..6].copy_from_slice(&head.n_max.to_le_bytes());
    out[6..8].copy_from_slice(&head.pitch.to_le_bytes());
    out[8..10].copy_from_slice(&(nodes as u16).to_le_bytes());
    out[10..12].copy_from_slice(&(caps.len() as u16).to_le_bytes());
    out[12..14].copy_from_slice(&head.cols.to_le_bytes());
    out[14..16].copy_from_slice(&head.tile.to_le_bytes());
    let (node_bytes, cap_bytes) = out[CONTROL_HEAD..].split_at_mut(4 * velocities);
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
    /// `Mc` frames: x and y velocity of each stored row and tile column
    /// (`rows × cols`, row-major), 1/4096 px per tick (empty: none).
    pub motion: (std::vec::Vec<i16>, std::vec::Vec<i16>),
    /// Tile columns of `motion` (0 or 1: one velocity per row).
    pub cols: u16,
    /// Tile width, px, a multiple of 64 (ignored for one column).
    pub tile: u16,
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
    /// applying from pair `from_pair`. Velocities beyond [`MAX_NODES`] are
    /// sent as every `⌈rows·cols / MAX_NODES⌉`-th row (the sidecar
    /// interpolates).
    pub fn message(
        &self,
        from_pair: u32,
        seq: u32,
        width: u16,
        height: u16,
    ) -> Result<std::vec::Vec<u8>, Error> {
        let (vx, vy) = &self.motion;
        let cols = usize::from(self.cols.max(1));
        let rows = vx.len().min(vy.len()) / cols;
        let pitch = (rows * cols).div_ceil(MAX_NODES).max(1);
        let every = |v: &[i16]| -> std::vec::Vec<i16> {
            v.chunks_exact(cols)
                .take(rows)
                .step_by(pitch)
                .flatten()
                .copied()
                .collect()
        };
        let (nx, ny) = (every(vx), every(vy));
        let head = ControlHead {
            from_pair,
            n_max: self.n_max,
            pitch: u16::try_from(pitch).map_err(|_| WireError::Payload)?,
            cols: cols as u16,
            tile: if cols == 1 {
                crate::motion::ROW_TILE
            } else {
                self.tile
            },
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
        assert_eq!(MAX_CONTROL_PAYLOAD, 8720);
        assert_eq!(MAX_CONTROL_ENCODED, 8790);
    }

    #[test]
    fn round_trip_and_interpolation() {
        let head = ControlHead {
            from_pair: 7,
            n_max: 96,
            pitch: 4,
            cols: 1,
            tile: 64,
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
            cols: 1,
            tile: 64,
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
            Err(WireError::Payload.into())
        );
        // Columns and tiles: none, too many, a tile off the word grid, and
        // velocities that are not whole node rows.
        for bad in [
            ControlHead { cols: 0, ..head },
            ControlHead {
                cols: crate::motion::MAX_COLS + 1,
                ..head
            },
            ControlHead { tile: 0, ..head },
            ControlHead { tile: 96, ..head },
        ] {
            assert_eq!(
                encode_control(&bad, &[1], &[1], &[], &mut buf),
                Err(WireError::Payload.into()),
                "{bad:?}"
            );
            let mut b = buf;
            b[12..14].copy_from_slice(&bad.cols.to_le_bytes());
            b[14..16].copy_from_slice(&bad.tile.to_le_bytes());
            assert!(ControlView::parse(&b[..n]).is_err(), "{bad:?}");
        }
        let two = ControlHead { cols: 2, ..head };
        assert_eq!(
            encode_control(&two, &[1, 2, 3], &[1, 2, 3], &[], &mut buf),
            Err(WireError::Payload.into())
        );
    }

    /// A grid of three node rows in two columns: each column is
    /// interpolated on its own, and the payload states its columns and
    /// tile.
    #[test]
    fn grid_round_trip() {
        let head = ControlHead {
            from_pair: 1,
            n_max: 0,
            pitch: 2,
            cols: 2,
            tile: 128,
        };
        let vx = [0i16, 100, 20, 100, 40, -100];
        let vy = [1i16, 2, 3, 4, 5, 6];
        let mut buf = [0u8; 64];
        let n = encode_control(&head, &vx, &vy, &[], &mut buf).unwrap();
        assert_eq!(n, CONTROL_HEAD + 4 * 6);
        let v = ControlView::parse(&buf[..n]).unwrap();
        assert_eq!((v.head, v.nodes()), (head, 3));
        let (mut x, mut y) = ([0i16; 12], [0i16; 12]);
        v.rows_into(&mut x, &mut y);
        // Rows 0..6 × columns 0, 1.
        assert_eq!(x, [0, 100, 10, 100, 20, 100, 30, 0, 40, -100, 40, -100]);
        assert_eq!(y, [1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 5, 6]);
    }
}
