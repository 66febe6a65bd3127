//! MSB-first bit I/O of the coded payloads, with the Rice code and its
//! escape: a quotient of [`ESCAPE`] or more is sent as `ESCAPE` ones
//! followed by the value in [`ESCAPE_BITS`] bits.

use crate::wire::WireError;

/// Quotients from this on are escaped.
pub(super) const ESCAPE: u32 = 24;
/// Bits of an escaped value.
pub(super) const ESCAPE_BITS: u32 = 18;

/// MSB-first bit writer. Hand-written for the no_std core: bits gather in a
/// 64-bit accumulator and leave a whole byte at a time (a per-bit loop cost
/// the Cortex-M4 about 10 instructions per bit).
pub(super) struct BitWriter<'a> {
    out: &'a mut [u8],
    /// Bytes written.
    pos: usize,
    /// Pending bits, the newest lowest; only the low `n` are meaningful.
    acc: u64,
    /// Pending bit count, below 8 between calls.
    n: u32,
}

impl<'a> BitWriter<'a> {
    pub(super) fn new(out: &'a mut [u8]) -> Self {
        BitWriter {
            out,
            pos: 0,
            acc: 0,
            n: 0,
        }
    }

    /// Appends the low `n` (≤ 32) bits of `value`, most significant first.
    #[inline]
    pub(super) fn put(&mut self, value: u32, n: u32) -> Result<(), WireError> {
        let mask = if n >= 32 { u64::MAX } else { (1u64 << n) - 1 };
        self.acc = (self.acc << n) | (u64::from(value) & mask);
        self.n += n;
        while self.n >= 8 {
            self.n -= 8;
            let b = self.out.get_mut(self.pos).ok_or(WireError::TooLarge)?;
            *b = (self.acc >> self.n) as u8;
            self.pos += 1;
        }
        Ok(())
    }

    #[inline]
    pub(super) fn rice(&mut self, z: u32, k: u32) -> Result<(), WireError> {
        let q = z >> k;
        if q < ESCAPE {
            // q ones and a zero, then the k low bits: in one 32-bit put
            // where they fit (almost always; wider words cost a 32-bit
            // core more than a second put).
            let low = z & ((1u32 << k) - 1);
            if q + 1 + k <= 32 {
                self.put(((((1u32 << q) - 1) << 1) << k) | low, q + 1 + k)
            } else {
                self.put(((1u32 << q) - 1) << 1, q + 1)?;
                self.put(low, k)
            }
        } else {
            self.put((1u32 << ESCAPE) - 1, ESCAPE)?;
            self.put(z, ESCAPE_BITS)
        }
    }

    /// Pads the last byte with zeros; returns the bytes written.
    pub(super) fn finish(mut self) -> Result<usize, WireError> {
        if self.n > 0 {
            let b = self.out.get_mut(self.pos).ok_or(WireError::TooLarge)?;
            *b = (self.acc << (8 - self.n)) as u8;
            self.pos += 1;
            self.n = 0;
        }
        Ok(self.pos)
    }
}

/// MSB-first bit reader over a payload.
pub(super) struct BitReader<'a> {
    data: &'a [u8],
    bit: usize,
}

impl<'a> BitReader<'a> {
    pub(super) fn new(data: &'a [u8]) -> Self {
        BitReader { data, bit: 0 }
    }

    /// The next `n` (≤ 32) bits, most significant first, taken up to a
    /// byte at a time.
    #[inline]
    pub(super) fn get(&mut self, n: u32) -> Result<u32, WireError> {
        let (mut v, mut left) = (0u64, n);
        while left > 0 {
            let b = *self.data.get(self.bit / 8).ok_or(WireError::Payload)?;
            let avail = 8 - (self.bit % 8) as u32;
            let take = avail.min(left);
            let bits = (u32::from(b) >> (avail - take)) & ((1u32 << take) - 1);
            v = (v << take) | u64::from(bits);
            self.bit += take as usize;
            left -= take;
        }
        Ok(v as u32)
    }

    #[inline]
    pub(super) fn rice(&mut self, k: u32) -> Result<u32, WireError> {
        let mut q = 0;
        while self.get(1)? == 1 {
            q += 1;
            if q == ESCAPE {
                return self.get(ESCAPE_BITS);
            }
        }
        Ok((q << k) | self.get(k)?)
    }

    /// A bitstream must end within its last byte.
    pub(super) fn finished(&self) -> Result<(), WireError> {
        if self.bit.div_ceil(8) == self.data.len() {
            Ok(())
        } else {
            Err(WireError::Payload)
        }
    }
}
