//! The live loop's uplink head ([`super::Kind::PairHead`]): what one pair
//! of the time ladder carries, sent before its parts. The parts follow as
//! frames (tiles and a frame end each, [`super::sender::Sender::send_frame`])
//! whose frame end names the pair and the part (`member`): first the rung
//! frames, A then B of each separation (whole spikes: levels of one spike
//! above the head's offset, which is in 1/64 spike),
//! then one plane per tick of events (0 none, 1 a `−1`, 2 a `+1`, stored
//! order), then, after any events, the static rates of every stored pixel
//! (1/65536 spike per tick).
//!
//! ```text
//! payload = pair u32 | mid u32 | from_pair u32 | count u8 | reserved u8 |
//!           ev_ticks u16 | ev_first u32 | separations 8 × u16 |
//!           offsets 16 × i16 | parts u16 | dt u16              (72 bytes)
//! ```

use super::WireError;
use crate::error::Error;

/// Most rungs a pair carries (the head's slots; what an ask asks for at
/// most, [`crate::rungs::Rungs`]).
pub const MAX_RUNGS: usize = 8;

/// Most ticks of events a pair carries, so that every part's number fits
/// the frame end's `member` byte.
pub const MAX_EVENT_TICKS: u16 = 224;

/// No ask followed (a pair of events made before any ask was heard).
pub const NO_ASK: u32 = u32::MAX;

/// Payload of [`super::Kind::PairHead`].
///
/// ```
/// use spiv_core::wire::pair::{PairHead, NO_ASK};
/// let h = PairHead { pair: 3, mid: 120, from_pair: NO_ASK, ev_first: 88, ev_ticks: 64, ..PairHead::default() };
/// assert_eq!(h.parts(), 65); // 64 event planes and the rates
/// assert_eq!(PairHead::parse(&h.to_bytes()), Ok(h));
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PairHead {
    /// Pair counter.
    pub pair: u32,
    /// The pair's midpoint, ticks.
    pub mid: u32,
    /// `from_pair` of the ask its rung frames followed ([`NO_ASK`]: none).
    pub from_pair: u32,
    /// Rung separations sent (`count` of them), ticks.
    pub separations: [u16; MAX_RUNGS],
    /// Separations in use.
    pub count: u8,
    /// First tick of the events.
    pub ev_first: u32,
    /// Ticks of events (0: none), at most [`MAX_EVENT_TICKS`].
    pub ev_ticks: u16,
    /// Each rung frame's offset: sample = level + offset (A and B of rung
    /// 0, then of rung 1, …).
    pub offsets: [i16; 2 * MAX_RUNGS],
    /// Ticks between the two frames of the pair the host reports (the
    /// unit of its field, px per `dt` ticks; 0: not given).
    pub dt: u16,
}

impl PairHead {
    /// Payload bytes.
    pub const LEN: usize = 72;

    /// Frames that follow: two per rung, one per tick of events, and the
    /// rates when there are events.
    pub fn parts(&self) -> u16 {
        2 * u16::from(self.count) + self.ev_ticks + u16::from(self.ev_ticks > 0)
    }

    /// The separations in use.
    pub fn separations(&self) -> &[u16] {
        &self.separations[..usize::from(self.count).min(MAX_RUNGS)]
    }

    /// Whether the fields are in range: at most [`MAX_RUNGS`] separations,
    /// each at least 1 tick, at most [`MAX_EVENT_TICKS`] of events.
    pub fn check(&self) -> Result<(), Error> {
        let count = usize::from(self.count);
        if count > MAX_RUNGS
            || self.separations[..count].contains(&0)
            || self.ev_ticks > MAX_EVENT_TICKS
        {
            return Err(WireError::Payload.into());
        }
        Ok(())
    }

    /// The payload.
    pub fn to_bytes(&self) -> [u8; Self::LEN] {
        let mut b = [0u8; Self::LEN];
        b[0..4].copy_from_slice(&self.pair.to_le_bytes());
        b[4..8].copy_from_slice(&self.mid.to_le_bytes());
        b[8..12].copy_from_slice(&self.from_pair.to_le_bytes());
        b[12] = self.count;
        b[14..16].copy_from_slice(&self.ev_ticks.to_le_bytes());
        b[16..20].copy_from_slice(&self.ev_first.to_le_bytes());
        for (k, s) in self.separations.iter().enumerate() {
            b[20 + 2 * k..22 + 2 * k].copy_from_slice(&s.to_le_bytes());
        }
        for (k, o) in self.offsets.iter().enumerate() {
            b[36 + 2 * k..38 + 2 * k].copy_from_slice(&o.to_le_bytes());
        }
        b[68..70].copy_from_slice(&self.parts().to_le_bytes());
        b[70..72].copy_from_slice(&self.dt.to_le_bytes());
        b
    }

    /// Parses and checks a payload (its `parts` must be what the rest
    /// says).
    pub fn parse(b: &[u8]) -> Result<PairHead, Error> {
        let b: &[u8; Self::LEN] = b.try_into().map_err(|_| WireError::Payload)?;
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let mut h = PairHead {
            pair: u32_at(0),
            mid: u32_at(4),
            from_pair: u32_at(8),
            count: b[12],
            ev_ticks: u16_at(14),
            ev_first: u32_at(16),
            dt: u16_at(70),
            ..PairHead::default()
        };
        for k in 0..MAX_RUNGS {
            h.separations[k] = u16_at(20 + 2 * k);
        }
        for k in 0..2 * MAX_RUNGS {
            h.offsets[k] = u16_at(36 + 2 * k) as i16;
        }
        h.check()?;
        if u16_at(68) != h.parts() {
            return Err(WireError::Payload.into());
        }
        Ok(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_head_round_trips_and_bad_ones_are_refused() {
        let mut h = PairHead {
            pair: 9,
            mid: 1234,
            from_pair: 8,
            count: 2,
            ev_first: 1200,
            ev_ticks: 40,
            dt: 10,
            ..PairHead::default()
        };
        h.separations[..2].copy_from_slice(&[16, 32]);
        h.offsets[..4].copy_from_slice(&[-5, 0, -700, 3]);
        let b = h.to_bytes();
        assert_eq!(PairHead::parse(&b), Ok(h));
        assert_eq!(h.parts(), 4 + 40 + 1);
        assert!(PairHead::parse(&b[..71]).is_err());
        let mut bad = b;
        bad[68] ^= 1;
        assert!(PairHead::parse(&bad).is_err());
        let mut bad = h;
        bad.ev_ticks = MAX_EVENT_TICKS + 1;
        assert!(PairHead::parse(&bad.to_bytes()).is_err());
        let mut bad = h;
        bad.separations[1] = 0;
        assert!(PairHead::parse(&bad.to_bytes()).is_err());
        assert!(2 * MAX_RUNGS + usize::from(MAX_EVENT_TICKS) < 256);
    }
}
