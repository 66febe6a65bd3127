//! The lossless `Rice` mode: per sample the zigzag residual of the LOCO-I
//! median edge predictor, coded with an adaptive Rice parameter (k the
//! smallest with `N·2^k ≥ A`, `A` the running sum of coded values and `N`
//! their count, both halved every 64 values). The sparse mode reuses the
//! adaptive parameter and the zigzag map.

use super::bits::{BitReader, BitWriter};
use super::context::med;
use super::level;
use crate::gray::Gray;
use crate::wire::WireError;

/// The adaptive Rice parameter (LOCO-I style).
#[derive(Clone, Copy)]
pub(super) struct Adapt {
    a: u32,
    n: u32,
}

impl Adapt {
    pub(super) fn new() -> Self {
        Adapt { a: 4, n: 1 }
    }

    /// The smallest `k` ≤ 16 with `N·2^k ≥ A` (16 if none): from the
    /// two top bits' distance, one step up where that falls short.
    #[inline]
    fn k(&self) -> u32 {
        if self.n >= self.a {
            return 0;
        }
        // A > N ≥ 1 (N starts at 1 and halves from 64 to 32): the
        // distance k0 is at most 31, and N·2^k0 has A's top bit, so it
        // fits 32 bits (a 64-bit shift costs the M4 a dozen instructions).
        let k0 = self.n.leading_zeros() - self.a.leading_zeros();
        let k = k0 + u32::from((self.n << k0) < self.a);
        k.min(16)
    }

    #[inline]
    fn update(&mut self, z: u32) {
        // No overflow: every value the code can carry is below 2^21 (a
        // quotient under ESCAPE with k ≤ 16, or an ESCAPE_BITS escape;
        // the decoder reads nothing larger), and A is halved every 64
        // values, so A < 2^28. Were it ever to wrap, encoder and decoder
        // update with the same values and stay in step, without the
        // saturating add's cost per sample.
        self.a = self.a.wrapping_add(z);
        self.n += 1;
        if self.n >= 64 {
            self.a >>= 1;
            self.n >>= 1;
        }
    }

    #[inline(always)]
    pub(super) fn put(&mut self, w: &mut BitWriter<'_>, z: u32) -> Result<(), WireError> {
        // k is 0 exactly when N ≥ A (`k`): that case without the shifts.
        if self.n >= self.a {
            w.rice0(z)?;
        } else {
            w.rice(z, self.k())?;
        }
        self.update(z);
        Ok(())
    }

    #[inline]
    pub(super) fn get(&mut self, r: &mut BitReader<'_>) -> Result<u32, WireError> {
        let z = r.rice(self.k())?;
        self.update(z);
        Ok(z)
    }
}

#[inline]
pub(super) fn zigzag(d: i32) -> u32 {
    ((d << 1) ^ (d >> 31)) as u32
}

#[inline]
pub(super) fn unzigzag(z: u32) -> i32 {
    ((z >> 1) as i32) ^ -((z & 1) as i32)
}

#[inline]
fn predict(get: impl Fn(usize) -> i32, r: usize, c: usize, w: usize) -> i32 {
    match (r, c) {
        (0, 0) => 0,
        (0, _) => get(c - 1),
        (_, 0) => get((r - 1) * w),
        _ => med(
            get(r * w + c - 1),
            get((r - 1) * w + c),
            get((r - 1) * w + c - 1),
        ),
    }
}

/// Codes `samples` (rows of `w`) as a Rice bitstream; returns the bytes.
pub(super) fn encode<G: Gray>(samples: &[G], w: usize, out: &mut [u8]) -> Result<usize, WireError> {
    let mut bw = BitWriter::new(out);
    let mut ad = Adapt::new();
    if w == 0 {
        return bw.finish();
    }
    let lv = |g: &G| i32::from(g.level());
    // `predict`'s prediction, written out row by row: the first row from
    // the left, a row's first sample from above, the rest by the median
    // edge predictor, whose residuals are computed for up to `CHUNK`
    // columns at once (on the host a loop the compiler vectorises: the
    // encoder's cost fell 11 %) before the serial coding of them; on a
    // 32-bit MCU without vectors one column at a time (the buffer's
    // round trip cost the Cortex-M4 8 % more). Through `predict` and its
    // index closure, with the per-sample division, sending cost 10 % more
    // on the host; per sample with a match on the row's kind, the loop
    // kept the writer's state on the stack. The decoder, which reads what
    // it writes, keeps `predict`, and the round-trip tests hold the two
    // to the same prediction.
    #[cfg(target_pointer_width = "64")]
    const CHUNK: usize = 32;
    #[cfg(not(target_pointer_width = "64"))]
    const CHUNK: usize = 1;
    let mut z = [0u32; CHUNK];
    let mut rows = samples.chunks(w);
    let Some(first) = rows.next() else {
        return bw.finish();
    };
    let mut left = 0i32;
    for g in first {
        let x = lv(g);
        ad.put(&mut bw, zigzag(x - left))?;
        left = x;
    }
    let mut up = first;
    for row in rows {
        let (Some(x0), Some(u0)) = (row.first(), up.first()) else {
            break;
        };
        ad.put(&mut bw, zigzag(lv(x0) - lv(u0)))?;
        // Columns 1.. of this row with their left, above and upper-left
        // neighbours (a short last row stops at its end).
        let n = row.len().min(up.len());
        let mut c = 1;
        while c < n {
            let m = (n - c).min(CHUNK);
            let (xs, ls) = (&row[c..c + m], &row[c - 1..c - 1 + m]);
            let (bs, cs) = (&up[c..c + m], &up[c - 1..c - 1 + m]);
            for ((((zi, x), l), b), cc) in z.iter_mut().zip(xs).zip(ls).zip(bs).zip(cs) {
                *zi = zigzag(lv(x) - med(lv(l), lv(b), lv(cc)));
            }
            for &zi in &z[..m] {
                ad.put(&mut bw, zi)?;
            }
            c += m;
        }
        up = row;
    }
    bw.finish()
}

/// Decodes a Rice bitstream into `out` (`n` samples, rows of `width`).
pub(super) fn decode<G: Gray>(payload: &[u8], width: u16, out: &mut [G]) -> Result<(), WireError> {
    let n = out.len();
    let w = usize::from(width);
    let mut br = BitReader::new(payload);
    let mut ad = Adapt::new();
    for i in 0..n {
        let pred = predict(|j| i32::from(out[j].level()), i / w, i % w, w);
        let v = pred.saturating_add(unzigzag(ad.get(&mut br)?));
        out[i] = level(v)?;
    }
    br.finished()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The clamped form of the median edge predictor is LOCO-I's case
    /// rule, ties included, over every neighbourhood of levels 0..=40
    /// and the extremes of 16-bit levels.
    #[test]
    fn med_is_the_loco_i_case_rule() {
        let rule = |a: i32, b: i32, c: i32| {
            if c >= a.max(b) {
                a.min(b)
            } else if c <= a.min(b) {
                a.max(b)
            } else {
                a + b - c
            }
        };
        let mut levels: Vec<i32> = (0..=40).collect();
        levels.extend([255, 256, 65_534, 65_535]);
        for &a in &levels {
            for &b in &levels {
                for &c in &levels {
                    assert_eq!(med(a, b, c), rule(a, b, c), "a {a} b {b} c {c}");
                }
            }
        }
    }

    /// The closed-form parameter is the loop's: the smallest k ≤ 16 with
    /// N·2^k ≥ A, for every N the coder reaches (1..64) and A up to past
    /// 2^22 (where the loop stops at 16), and the saturated A.
    #[test]
    fn rice_parameter_is_the_smallest_k() {
        let by_loop = |a: u32, n: u32| {
            let mut k = 0;
            while (n << k) < a && k < 16 {
                k += 1;
            }
            k
        };
        for n in 1..64u32 {
            let mut a = 0u32;
            while a < (1 << 23) {
                assert_eq!(Adapt { a, n }.k(), by_loop(a, n), "a {a} n {n}");
                a += 1 + a / 64;
            }
            assert_eq!(Adapt { a: u32::MAX, n }.k(), 16);
        }
    }
}
