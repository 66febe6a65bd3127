//! The binary range coder of the context-modelled modes, and its adaptive
//! models. Hand-written for the no_std core: the coder is LZMA's (a 32-bit
//! range, carry propagation through a cached byte, probabilities of 1/4096)
//! with a faster adaptation (a shift of 4, not LZMA's 5: tiles of the
//! paper's frames measured about 1 % smaller). It costs a few instructions
//! per coded bit on a Cortex-M4 and is small enough for FPGA logic.
//!
//! The stream is `1 + normalisations + 4` bytes and its first byte is
//! always 0; the decoder checks both, so a truncated, extended or altered
//! payload is [`WireError::Payload`] wherever it shows.

use crate::wire::WireError;

/// Probability precision, bits.
const PROB_BITS: u32 = 12;
/// Probability of 1 in [`PROB_BITS`] units.
const PROB_ONE: u16 = 1 << PROB_BITS;
/// Adaptation shift: each coded bit moves its model 1/16 of the way.
const MOVE: u32 = 4;
/// The range is renormalised below this.
const TOP: u32 = 1 << 24;

/// An adaptive binary model: the probability that the next bit is 0, in
/// 1/4096 (always within `15..=4081`, so no bit ever costs nothing or
/// everything).
#[derive(Clone, Copy)]
pub(super) struct Bit(u16);

impl Bit {
    pub(super) const NEW: Bit = Bit(PROB_ONE / 2);
}

/// Range encoder writing into a caller's buffer.
pub(super) struct Encoder<'a> {
    out: &'a mut [u8],
    pos: usize,
    low: u64,
    range: u32,
    cache: u8,
    /// Bytes held back: the cache and the 0xFF bytes after it that a carry
    /// may still change.
    held: u32,
}

impl<'a> Encoder<'a> {
    pub(super) fn new(out: &'a mut [u8]) -> Self {
        Encoder {
            out,
            pos: 0,
            low: 0,
            range: u32::MAX,
            cache: 0,
            held: 1,
        }
    }

    fn write(&mut self, b: u8) -> Result<(), WireError> {
        let o = self.out.get_mut(self.pos).ok_or(WireError::TooLarge)?;
        *o = b;
        self.pos += 1;
        Ok(())
    }

    fn shift_low(&mut self) -> Result<(), WireError> {
        if self.low < 0xFF00_0000 || self.low >= 1 << 32 {
            let carry = (self.low >> 32) as u8;
            let mut b = self.cache;
            while self.held > 0 {
                self.write(b.wrapping_add(carry))?;
                b = 0xFF;
                self.held -= 1;
            }
            self.cache = (self.low >> 24) as u8;
        }
        self.held += 1;
        self.low = (self.low & 0x00FF_FFFF) << 8;
        Ok(())
    }

    #[inline]
    fn normalise(&mut self) -> Result<(), WireError> {
        while self.range < TOP {
            self.range <<= 8;
            self.shift_low()?;
        }
        Ok(())
    }

    /// Codes `bit` with the adaptive model `m`.
    #[inline]
    pub(super) fn bit(&mut self, m: &mut Bit, bit: bool) -> Result<(), WireError> {
        let bound = (self.range >> PROB_BITS) * u32::from(m.0);
        if bit {
            self.low += u64::from(bound);
            self.range -= bound;
            m.0 -= m.0 >> MOVE;
        } else {
            self.range = bound;
            m.0 += (PROB_ONE - m.0) >> MOVE;
        }
        self.normalise()
    }

    /// Codes the low `n` (≤ 24) bits of `v` at probability 1/2, most
    /// significant first.
    pub(super) fn direct(&mut self, v: u32, n: u32) -> Result<(), WireError> {
        for i in (0..n).rev() {
            self.range >>= 1;
            if (v >> i) & 1 == 1 {
                self.low += u64::from(self.range);
            }
            self.normalise()?;
        }
        Ok(())
    }

    /// Flushes the coder; returns the bytes written.
    pub(super) fn finish(mut self) -> Result<usize, WireError> {
        for _ in 0..5 {
            self.shift_low()?;
        }
        Ok(self.pos)
    }
}

/// Range decoder over a payload.
pub(super) struct Decoder<'a> {
    input: &'a [u8],
    pos: usize,
    range: u32,
    code: u32,
}

impl<'a> Decoder<'a> {
    pub(super) fn new(input: &'a [u8]) -> Result<Self, WireError> {
        if input.first() != Some(&0) {
            return Err(WireError::Payload);
        }
        let mut d = Decoder {
            input,
            pos: 1,
            range: u32::MAX,
            code: 0,
        };
        for _ in 0..4 {
            d.code = (d.code << 8) | u32::from(d.byte()?);
        }
        if d.code == u32::MAX {
            return Err(WireError::Payload);
        }
        Ok(d)
    }

    #[inline]
    fn byte(&mut self) -> Result<u8, WireError> {
        let b = *self.input.get(self.pos).ok_or(WireError::Payload)?;
        self.pos += 1;
        Ok(b)
    }

    #[inline]
    fn normalise(&mut self) -> Result<(), WireError> {
        while self.range < TOP {
            self.range <<= 8;
            self.code = (self.code << 8) | u32::from(self.byte()?);
        }
        Ok(())
    }

    /// Decodes a bit with the adaptive model `m`.
    #[inline]
    pub(super) fn bit(&mut self, m: &mut Bit) -> Result<bool, WireError> {
        let bound = (self.range >> PROB_BITS) * u32::from(m.0);
        let bit = if self.code < bound {
            self.range = bound;
            m.0 += (PROB_ONE - m.0) >> MOVE;
            false
        } else {
            self.code -= bound;
            self.range -= bound;
            m.0 -= m.0 >> MOVE;
            true
        };
        self.normalise()?;
        Ok(bit)
    }

    /// Decodes `n` (≤ 24) bits coded by [`Encoder::direct`].
    pub(super) fn direct(&mut self, n: u32) -> Result<u32, WireError> {
        let mut v = 0u32;
        for _ in 0..n {
            self.range >>= 1;
            let bit = self.code >= self.range;
            if bit {
                self.code -= self.range;
            }
            v = (v << 1) | u32::from(bit);
            self.normalise()?;
        }
        Ok(v)
    }

    /// Ok when every byte of the payload was read: a valid stream ends
    /// exactly where its coder flushed.
    pub(super) fn finished(&self) -> Result<(), WireError> {
        if self.pos == self.input.len() {
            Ok(())
        } else {
            Err(WireError::Payload)
        }
    }
}

/// Bit lengths a [`Mag`] codes: values below `2^MAG_BITS`.
pub(super) const MAG_BITS: usize = 18;

/// An adaptive model of an unsigned value below `2^18`: whether it is 0,
/// its bit length in unary (one model per length), the bit below its
/// leading one (one model per length), the rest at probability 1/2 — an
/// Elias-gamma code whose every decision adapts, so the model follows any
/// scale, from run lengths to residuals at particle edges.
#[derive(Clone, Copy)]
pub(super) struct Mag {
    zero: Bit,
    len: [Bit; MAG_BITS],
    top: [Bit; MAG_BITS],
}

impl Mag {
    pub(super) const NEW: Mag = Mag {
        zero: Bit::NEW,
        len: [Bit::NEW; MAG_BITS],
        top: [Bit::NEW; MAG_BITS],
    };

    /// Codes `v`; values of `2^18` or more are [`WireError::TooLarge`].
    pub(super) fn put(&mut self, e: &mut Encoder<'_>, v: u32) -> Result<(), WireError> {
        e.bit(&mut self.zero, v != 0)?;
        if v == 0 {
            return Ok(());
        }
        let n = (32 - v.leading_zeros()) as usize;
        if n > MAG_BITS {
            return Err(WireError::TooLarge);
        }
        for i in 1..MAG_BITS {
            e.bit(&mut self.len[i], i < n)?;
            if i >= n {
                break;
            }
        }
        if n >= 2 {
            e.bit(&mut self.top[n - 1], (v >> (n - 2)) & 1 == 1)?;
            e.direct(v, (n - 2) as u32)?;
        }
        Ok(())
    }

    /// Decodes a value coded by [`Mag::put`].
    pub(super) fn get(&mut self, d: &mut Decoder<'_>) -> Result<u32, WireError> {
        if !d.bit(&mut self.zero)? {
            return Ok(0);
        }
        let mut n = 1;
        while n < MAG_BITS && d.bit(&mut self.len[n])? {
            n += 1;
        }
        if n < 2 {
            return Ok(1);
        }
        let top = u32::from(d.bit(&mut self.top[n - 1])?);
        let rest = d.direct((n - 2) as u32)?;
        Ok((1 << (n - 1)) | (top << (n - 2)) | rest)
    }
}

/// An adaptive model of a signed residual: zero, sign, magnitude − 1.
#[derive(Clone, Copy)]
pub(super) struct Signed {
    zero: Bit,
    sign: Bit,
    mag: Mag,
}

impl Signed {
    pub(super) const NEW: Signed = Signed {
        zero: Bit::NEW,
        sign: Bit::NEW,
        mag: Mag::NEW,
    };

    pub(super) fn put(&mut self, e: &mut Encoder<'_>, v: i32) -> Result<(), WireError> {
        e.bit(&mut self.zero, v != 0)?;
        if v != 0 {
            e.bit(&mut self.sign, v < 0)?;
            self.mag.put(e, v.unsigned_abs() - 1)?;
        }
        Ok(())
    }

    pub(super) fn get(&mut self, d: &mut Decoder<'_>) -> Result<i32, WireError> {
        if !d.bit(&mut self.zero)? {
            return Ok(0);
        }
        let neg = d.bit(&mut self.sign)?;
        let m = self.mag.get(d)? as i32 + 1;
        Ok(if neg { -m } else { m })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_and_bits_round_trip_and_the_stream_is_exact() {
        let mut buf = [0u8; 4096];
        let mut s = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let vals: [(u32, i32, bool); 300] = core::array::from_fn(|i| {
            let r = next();
            let v = if i % 7 == 0 {
                (r as u32) % (1 << 18)
            } else {
                (r as u32) % 5
            };
            let sv = ((r >> 32) as i32) % 300;
            (v, sv, r >> 63 == 1)
        });
        let mut e = Encoder::new(&mut buf);
        let (mut m, mut sm, mut b) = (Mag::NEW, Signed::NEW, Bit::NEW);
        for &(v, sv, bit) in &vals {
            m.put(&mut e, v).unwrap();
            sm.put(&mut e, sv).unwrap();
            e.bit(&mut b, bit).unwrap();
            e.direct(v & 0x3ff, 10).unwrap();
        }
        let len = e.finish().unwrap();
        let mut d = Decoder::new(&buf[..len]).unwrap();
        let (mut m, mut sm, mut b) = (Mag::NEW, Signed::NEW, Bit::NEW);
        for &(v, sv, bit) in &vals {
            assert_eq!(m.get(&mut d).unwrap(), v);
            assert_eq!(sm.get(&mut d).unwrap(), sv);
            assert_eq!(d.bit(&mut b).unwrap(), bit);
            assert_eq!(d.direct(10).unwrap(), v & 0x3ff);
        }
        assert!(d.finished().is_ok());
        // One byte more or less is noticed.
        let mut d = Decoder::new(&buf[..len - 1]).unwrap();
        let short = (|| {
            let (mut m, mut sm, mut b) = (Mag::NEW, Signed::NEW, Bit::NEW);
            for _ in &vals {
                m.get(&mut d)?;
                sm.get(&mut d)?;
                d.bit(&mut b)?;
                d.direct(10)?;
            }
            d.finished()
        })();
        assert_eq!(short, Err(WireError::Payload));
    }

    #[test]
    fn a_skewed_bit_costs_little() {
        let mut buf = [0u8; 1024];
        let mut e = Encoder::new(&mut buf);
        let mut b = Bit::NEW;
        for i in 0..10_000 {
            e.bit(&mut b, i % 100 == 0).unwrap();
        }
        let len = e.finish().unwrap();
        // Entropy of p = 0.01: 0.081 bits a bit, 101 bytes; adaptation
        // by 1/16 costs some of it.
        assert!(len < 200, "{len} bytes");
    }

    #[test]
    fn a_full_buffer_is_too_large() {
        let mut buf = [0u8; 8];
        let mut e = Encoder::new(&mut buf);
        let mut m = Mag::NEW;
        let r = (0..100)
            .try_for_each(|i| m.put(&mut e, 1000 + i))
            .and_then(|_| e.finish());
        assert_eq!(r, Err(WireError::TooLarge));
    }
}
