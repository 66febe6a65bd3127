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

    #[inline]
    fn k(&self) -> u32 {
        let mut k = 0;
        while (self.n << k) < self.a && k < 16 {
            k += 1;
        }
        k
    }

    #[inline]
    fn update(&mut self, z: u32) {
        self.a = self.a.saturating_add(z);
        self.n += 1;
        if self.n >= 64 {
            self.a >>= 1;
            self.n >>= 1;
        }
    }

    #[inline]
    pub(super) fn put(&mut self, w: &mut BitWriter<'_>, z: u32) -> Result<(), WireError> {
        w.rice(z, self.k())?;
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
    let get = |i: usize| i32::from(samples[i].level());
    for i in 0..samples.len() {
        let pred = predict(get, i / w, i % w, w);
        ad.put(&mut bw, zigzag(get(i) - pred))?;
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
