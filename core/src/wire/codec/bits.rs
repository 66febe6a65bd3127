//! MSB-first bit I/O of the coded payloads, with the Rice code and its
//! escape: a quotient of [`ESCAPE`] or more is sent as `ESCAPE` ones
//! followed by the value in [`ESCAPE_BITS`] bits.

use crate::wire::WireError;

/// Quotients from this on are escaped.
pub(super) const ESCAPE: u32 = 24;
/// Bits of an escaped value.
pub(super) const ESCAPE_BITS: u32 = 18;

/// MSB-first bit writer. Hand-written for the no_std core: bits gather in a
/// 32-bit accumulator and leave 32 at a time as four big-endian bytes. A
/// per-bit loop cost the Cortex-M4 about 10 instructions per bit; a byte at
/// a time, with its bounds check and loop, was half of the Rice coder's
/// cost on the host; a 64-bit accumulator's variable shifts are a dozen
/// instructions each on the M4.
///
/// A payload that does not fit `out` is [`WireError::TooLarge`], at the
/// latest from [`BitWriter::finish`]: the bytes are the same whenever it
/// fits, whatever the flush width.
pub(super) struct BitWriter<'a> {
    out: &'a mut [u8],
    /// Bytes written.
    pos: usize,
    /// Pending bits, the newest lowest; only the low `n` are meaningful
    /// (the bits above them are old ones, shifted out before use).
    acc: u32,
    /// Pending bit count, below 32 between calls.
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
        let mask = if n >= 32 { u32::MAX } else { (1u32 << n) - 1 };
        self.push(value & mask, n)
    }

    /// Appends `len` (≤ 32) bits that are all of `bits` (nothing above
    /// them).
    #[inline(always)]
    fn push(&mut self, bits: u32, len: u32) -> Result<(), WireError> {
        let total = self.n + len;
        if total < 32 {
            // len < 32 here.
            self.acc = (self.acc << len) | bits;
            self.n = total;
            return Ok(());
        }
        // The word fills: the pending `n` bits, then the top of `bits`;
        // `rem` (< 32) of them stay pending. Two shifts, as `n` may be 0.
        let rem = total - 32;
        let word = ((self.acc << 1) << (31 - self.n)) | (bits >> rem);
        self.acc = bits;
        self.n = rem;
        let dst = self
            .out
            .get_mut(self.pos..self.pos + 4)
            .ok_or(WireError::TooLarge)?;
        dst.copy_from_slice(&word.to_be_bytes());
        self.pos += 4;
        Ok(())
    }

    /// The Rice code of `z` with parameter `k` (≤ 16): `z >> k` ones, a
    /// zero and the low `k` bits, or the escape.
    #[inline(always)]
    pub(super) fn rice(&mut self, z: u32, k: u32) -> Result<(), WireError> {
        let q = z >> k;
        let len = q + 1 + k;
        // One compare: at most ESCAPE bits means q < ESCAPE and a single
        // 32-bit push; everything else (rare) takes `rice_long`.
        if len <= ESCAPE {
            // q ones and a zero, then the k low bits, in one push (almost
            // always; wider words cost a 32-bit core more than a second put):
            // the ones are 2^len − 2^(k+1) and the low bits z − q·2^k, so
            // the code is 2^len + z − (q + 2)·2^k (len ≤ 24, no overflow),
            // two shifts fewer than building the ones and the mask.
            self.push((1u32 << len) + z - ((q + 2) << k), len)
        } else {
            self.rice_long(z, k)
        }
    }

    /// [`BitWriter::rice`] with `k = 0`, the adaptive coder's most common
    /// parameter on suppressed frames: `z` ones and a zero, without the
    /// shifts by `k` (sending is a large share of the firmware loop's
    /// cost).
    #[inline(always)]
    pub(super) fn rice0(&mut self, z: u32) -> Result<(), WireError> {
        if z < ESCAPE {
            self.push((2u32 << z) - 2, z + 1)
        } else {
            self.rice_long(z, 0)
        }
    }

    // Inline like the fast path: an out-of-line call would keep the
    // writer's state in memory across the whole encoding loop.
    #[inline(always)]
    fn rice_long(&mut self, z: u32, k: u32) -> Result<(), WireError> {
        let q = z >> k;
        if q < ESCAPE {
            self.put(((1u32 << q) - 1) << 1, q + 1)?;
            self.put(z, k)
        } else {
            self.put((1u32 << ESCAPE) - 1, ESCAPE)?;
            self.put(z, ESCAPE_BITS)
        }
    }

    /// Writes the pending bits, the last byte padded with zeros; returns
    /// the bytes written.
    pub(super) fn finish(mut self) -> Result<usize, WireError> {
        while self.n > 0 {
            let b = self.out.get_mut(self.pos).ok_or(WireError::TooLarge)?;
            *b = if self.n >= 8 {
                self.n -= 8;
                (self.acc >> self.n) as u8
            } else {
                let v = (self.acc << (8 - self.n)) as u8;
                self.n = 0;
                v
            };
            self.pos += 1;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The plainest MSB-first writer: one bit at a time into a byte list.
    struct PerBit(Vec<bool>);

    impl PerBit {
        fn put(&mut self, value: u32, n: u32) {
            for i in (0..n).rev() {
                self.0.push((value >> i) & 1 == 1);
            }
        }

        fn rice(&mut self, z: u32, k: u32) {
            let q = z >> k;
            if q < ESCAPE {
                self.put(u32::MAX, q);
                self.put(0, 1);
                self.put(z, k);
            } else {
                self.put(u32::MAX, ESCAPE);
                self.put(z, ESCAPE_BITS);
            }
        }

        fn bytes(&self) -> Vec<u8> {
            self.0
                .chunks(8)
                .map(|c| {
                    c.iter()
                        .enumerate()
                        .fold(0u8, |b, (i, &v)| b | (u8::from(v) << (7 - i)))
                })
                .collect()
        }
    }

    /// One op of a random stream: a plain put of 0..=32 bits, or a Rice
    /// code with k 0..=16 of a value that sometimes escapes or needs two
    /// pushes.
    fn ops(seed: u64, len: usize) -> Vec<(bool, u32, u32)> {
        let mut s = seed;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        (0..len)
            .map(|_| {
                let r = next();
                if r & 1 == 0 {
                    let n = (r >> 1) as u32 % 33;
                    (false, (r >> 8) as u32, n)
                } else {
                    let k = (r >> 1) as u32 % 17;
                    let z = match (r >> 6) % 4 {
                        0 => (r >> 8) as u32 % (1 << ESCAPE_BITS),
                        _ => (r >> 8) as u32 % ((1 << k) * 30),
                    };
                    (true, z, k)
                }
            })
            .collect()
    }

    /// The writer's bytes are the per-bit writer's for random streams of
    /// puts and Rice codes; a buffer one byte short of them is
    /// `TooLarge`, not a truncated payload.
    #[test]
    fn writer_matches_a_per_bit_writer_and_refuses_short_buffers() {
        for seed in 1..200u64 {
            let stream = ops(seed, (seed as usize * 7) % 300);
            let mut reference = PerBit(Vec::new());
            for &(rice, v, n) in &stream {
                if rice {
                    reference.rice(v, n);
                } else {
                    reference.put(v, n);
                }
            }
            let want = reference.bytes();
            let write = |out: &mut [u8]| {
                let mut w = BitWriter::new(out);
                for &(rice, v, n) in &stream {
                    if rice {
                        w.rice(v, n)?;
                    } else {
                        w.put(v, n)?;
                    }
                }
                w.finish()
            };
            let mut out = vec![0xA5u8; want.len()];
            assert_eq!(write(&mut out), Ok(want.len()), "seed {seed}");
            assert_eq!(out, want, "seed {seed}");
            if !want.is_empty() {
                let mut short = vec![0u8; want.len() - 1];
                assert_eq!(write(&mut short), Err(WireError::TooLarge), "seed {seed}");
            }
        }
    }
}
