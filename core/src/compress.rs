//! Tile codecs: how a band of rows of an integrated frame becomes a payload
//! ([`crate::wire::Encoding`]) and back. No allocation, bounded work per
//! pixel (at most two passes), every decoder input checked.
//!
//! | encoding | kind | payload |
//! |---|---|---|
//! | `Raw8` | lossless | one byte per sample, row by row |
//! | `Raw16` | lossless | two bytes per sample, little-endian |
//! | `Rice` | lossless | bitstream: per sample the zigzag residual of the LOCO-I median predictor, adaptive Rice code |
//! | `Sparse` | lossy | `block u8, 0u8`, bitstream: background grid (block means of the darker half, Rice-coded deltas), then per row alternating runs: background (decoded as the bilinear upsampling of the grid) and exact samples (Rice-coded left-neighbour residuals) |
//!
//! `Sparse` sends a sample exactly when it differs from the upsampled
//! background by more than its block's tolerance, so every decoded sample is
//! within `tolerance` gray levels of the original; particles (far above the
//! flattened background) arrive exact. The block's tolerance is at most its
//! contrast (brightest sample minus background) over `contrast`: a block of
//! dim particles a few levels above a suppressed background — what an
//! adaptive frame shows where short windows leave particles unsegmented —
//! goes exact, while noise around bright segmented particles is flattened.
//! This is an encoder decision only; the payload format does not change.
//!
//! Bitstreams are MSB first. The Rice parameter adapts as in LOCO-I: k is
//! the smallest with `N·2^k ≥ A`, `A` the running sum of coded values and
//! `N` their count, both halved every 64 values; a quotient of 24 or more is
//! an escape followed by the value in 18 bits.
//!
//! The encoder falls back to a lossless mode when a compressed payload would
//! not fit the buffer or would be larger than raw.

use crate::gray::Gray;
use crate::wire::{Encoding, WireError};

const ESCAPE: u32 = 24;
const ESCAPE_BITS: u32 = 18;

/// Settings of the lossy [`Encoding::Sparse`] mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Lossy {
    /// Background block edge, px, `2..=64`.
    pub block: u8,
    /// Largest error of a sample sent as background, gray levels.
    pub tolerance: u16,
    /// Contrast rule: in a block whose brightest sample stands `r` levels
    /// above its background, the tolerance is at most `r / contrast` (0:
    /// `tolerance` everywhere). Dim blocks — particles a few levels above a
    /// suppressed background — then go exact, bright ones are flattened.
    pub contrast: u16,
}

impl Default for Lossy {
    fn default() -> Self {
        Lossy {
            block: 8,
            tolerance: 12,
            contrast: 4,
        }
    }
}

/// Scratch samples the sparse codec needs for a tile: its background grid
/// and, when encoding, a tolerance per block.
pub fn sparse_scratch(width: u16, rows: u16, block: u8) -> usize {
    let b = usize::from(block.max(1));
    2 * usize::from(width).div_ceil(b) * usize::from(rows).div_ceil(b)
}

/// MSB-first bit writer. Hand-written for the no_std core: bits gather in a
/// 64-bit accumulator and leave a whole byte at a time (a per-bit loop cost
/// the Cortex-M4 about 10 instructions per bit).
struct BitWriter<'a> {
    out: &'a mut [u8],
    /// Bytes written.
    pos: usize,
    /// Pending bits, the newest lowest; only the low `n` are meaningful.
    acc: u64,
    /// Pending bit count, below 8 between calls.
    n: u32,
}

impl<'a> BitWriter<'a> {
    fn new(out: &'a mut [u8]) -> Self {
        BitWriter {
            out,
            pos: 0,
            acc: 0,
            n: 0,
        }
    }

    /// Appends the low `n` (≤ 32) bits of `value`, most significant first.
    #[inline]
    fn put(&mut self, value: u32, n: u32) -> Result<(), WireError> {
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
    fn rice(&mut self, z: u32, k: u32) -> Result<(), WireError> {
        let q = z >> k;
        if q < ESCAPE {
            // q ones and a zero, then the k low bits.
            self.put(((1u32 << q) - 1) << 1, q + 1)?;
            self.put(z & ((1u32 << k) - 1), k)
        } else {
            self.put((1u32 << ESCAPE) - 1, ESCAPE)?;
            self.put(z, ESCAPE_BITS)
        }
    }

    /// Pads the last byte with zeros; returns the bytes written.
    fn finish(mut self) -> Result<usize, WireError> {
        if self.n > 0 {
            let b = self.out.get_mut(self.pos).ok_or(WireError::TooLarge)?;
            *b = (self.acc << (8 - self.n)) as u8;
            self.pos += 1;
            self.n = 0;
        }
        Ok(self.pos)
    }
}

struct BitReader<'a> {
    data: &'a [u8],
    bit: usize,
}

impl BitReader<'_> {
    /// The next `n` (≤ 32) bits, most significant first, taken up to a
    /// byte at a time.
    #[inline]
    fn get(&mut self, n: u32) -> Result<u32, WireError> {
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
    fn rice(&mut self, k: u32) -> Result<u32, WireError> {
        let mut q = 0;
        while self.get(1)? == 1 {
            q += 1;
            if q == ESCAPE {
                return self.get(ESCAPE_BITS);
            }
        }
        Ok((q << k) | self.get(k)?)
    }
}

/// The adaptive Rice parameter (LOCO-I style).
#[derive(Clone, Copy)]
struct Adapt {
    a: u32,
    n: u32,
}

impl Adapt {
    fn new() -> Self {
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
    fn put(&mut self, w: &mut BitWriter<'_>, z: u32) -> Result<(), WireError> {
        w.rice(z, self.k())?;
        self.update(z);
        Ok(())
    }

    #[inline]
    fn get(&mut self, r: &mut BitReader<'_>) -> Result<u32, WireError> {
        let z = r.rice(self.k())?;
        self.update(z);
        Ok(z)
    }
}

#[inline]
fn zigzag(d: i32) -> u32 {
    ((d << 1) ^ (d >> 31)) as u32
}

#[inline]
fn unzigzag(z: u32) -> i32 {
    ((z >> 1) as i32) ^ -((z & 1) as i32)
}

/// LOCO-I median edge predictor from left `a`, above `b`, upper-left `c`.
#[inline]
fn med(a: i32, b: i32, c: i32) -> i32 {
    if c >= a.max(b) {
        a.min(b)
    } else if c <= a.min(b) {
        a.max(b)
    } else {
        a + b - c
    }
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

/// Codes the band `samples` (`rows × width`, row by row) as `want` into
/// `out`; returns the encoding actually used (a lossless fallback when the
/// wanted one does not fit or is larger than raw, `Raw16` when levels
/// exceed 255) and the payload bytes. `scratch` holds
/// [`sparse_scratch`] samples for `Sparse` (otherwise unused).
pub fn encode_tile<G: Gray>(
    want: Encoding,
    samples: &[G],
    width: u16,
    rows: u16,
    lossy: &Lossy,
    scratch: &mut [u16],
    out: &mut [u8],
) -> Result<(Encoding, usize), WireError> {
    let n = usize::from(width) * usize::from(rows);
    let samples = samples.get(..n).ok_or(WireError::Payload)?;
    let wide = samples.iter().any(|s| s.level() > 255);
    let raw = if wide {
        Encoding::Raw16
    } else {
        Encoding::Raw8
    };
    let raw_len = if wide { 2 * n } else { n };
    let tried = match want {
        Encoding::Rice => encode_rice(samples, usize::from(width), out),
        Encoding::Sparse => encode_sparse(samples, width, rows, lossy, scratch, out),
        _ => Err(WireError::TooLarge),
    };
    match tried {
        Ok(len) if len < raw_len => Ok((want, len)),
        // Sparse that does not pay: try lossless compression.
        _ if want == Encoding::Sparse => match encode_rice(samples, usize::from(width), out) {
            Ok(len) if len < raw_len => Ok((Encoding::Rice, len)),
            _ => encode_raw(samples, wide, out).map(|l| (raw, l)),
        },
        _ => encode_raw(samples, wide, out).map(|l| (raw, l)),
    }
}

fn encode_raw<G: Gray>(samples: &[G], wide: bool, out: &mut [u8]) -> Result<usize, WireError> {
    if wide {
        let dst = out
            .get_mut(..2 * samples.len())
            .ok_or(WireError::TooLarge)?;
        for (d, s) in dst.chunks_exact_mut(2).zip(samples) {
            d.copy_from_slice(&s.level().to_le_bytes());
        }
        Ok(2 * samples.len())
    } else {
        let dst = out.get_mut(..samples.len()).ok_or(WireError::TooLarge)?;
        for (d, s) in dst.iter_mut().zip(samples) {
            *d = s.level() as u8;
        }
        Ok(samples.len())
    }
}

fn encode_rice<G: Gray>(samples: &[G], w: usize, out: &mut [u8]) -> Result<usize, WireError> {
    let mut bw = BitWriter::new(out);
    let mut ad = Adapt::new();
    let get = |i: usize| i32::from(samples[i].level());
    for i in 0..samples.len() {
        let pred = predict(get, i / w, i % w, w);
        ad.put(&mut bw, zigzag(get(i) - pred))?;
    }
    bw.finish()
}

/// Background of a block — the mean of its samples at or below its mean —
/// and its brightest sample.
fn block_level<G: Gray>(
    samples: &[G],
    w: usize,
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
) -> (u16, u16) {
    let (mut sum, mut n, mut max) = (0u64, 0u64, 0u16);
    for y in y0..y1 {
        for &s in &samples[y * w + x0..y * w + x1] {
            sum += u64::from(s.level());
            n += 1;
            max = max.max(s.level());
        }
    }
    let m1 = sum / n.max(1);
    let (mut s2, mut n2) = (0u64, 0u64);
    for y in y0..y1 {
        for &s in &samples[y * w + x0..y * w + x1] {
            if u64::from(s.level()) <= m1 {
                s2 += u64::from(s.level());
                n2 += 1;
            }
        }
    }
    ((s2 / n2.max(1)) as u16, max)
}

/// Bilinear weights along one axis: the lower grid index and the weight
/// of the upper one, out of `2·block`.
#[inline]
fn axis(x: usize, block: usize, cells: usize) -> (usize, u32) {
    let den = 2 * block as i64;
    let num = 2 * x as i64 + 1 - block as i64;
    if num <= 0 || cells < 2 {
        return (0, 0);
    }
    let j = (num / den) as usize;
    if j >= cells - 1 {
        (cells - 1, 0)
    } else {
        (j, (num - j as i64 * den) as u32)
    }
}

/// The upsampled background at (x, y) of a tile, from its grid `g`
/// (`gw` cells per row).
#[inline]
fn background(g: &[u16], gw: usize, gh: usize, block: usize, x: usize, y: usize) -> i32 {
    let (jx, fx) = axis(x, block, gw);
    let (jy, fy) = axis(y, block, gh);
    let den = 2 * block as u64;
    let at = |r: usize, c: usize| u64::from(g.get(r * gw + c).copied().unwrap_or(0));
    let (jx1, jy1) = ((jx + 1).min(gw - 1), (jy + 1).min(gh - 1));
    let (fx, fy) = (u64::from(fx), u64::from(fy));
    let top = at(jy, jx) * (den - fx) + at(jy, jx1) * fx;
    let bot = at(jy1, jx) * (den - fx) + at(jy1, jx1) * fx;
    let v = top * (den - fy) + bot * fy;
    ((v + den * den / 2) / (den * den)) as i32
}

fn encode_sparse<G: Gray>(
    samples: &[G],
    width: u16,
    rows: u16,
    lossy: &Lossy,
    scratch: &mut [u16],
    out: &mut [u8],
) -> Result<usize, WireError> {
    let block = lossy.block;
    if !(2..=64).contains(&block) {
        return Err(WireError::Field);
    }
    let (w, h, b) = (usize::from(width), usize::from(rows), usize::from(block));
    let (gw, gh) = (w.div_ceil(b), h.div_ceil(b));
    let cells = gw * gh;
    let (g, tols) = scratch
        .get_mut(..2 * cells)
        .ok_or(WireError::TooLarge)?
        .split_at_mut(cells);
    for (j, (cell, tol)) in g.iter_mut().zip(tols.iter_mut()).enumerate() {
        let (y0, x0) = ((j / gw) * b, (j % gw) * b);
        let (level, max) = block_level(samples, w, x0, (x0 + b).min(w), y0, (y0 + b).min(h));
        *cell = level;
        *tol = match lossy.contrast {
            0 => lossy.tolerance,
            c => lossy.tolerance.min(max.saturating_sub(level) / c),
        };
    }
    let (head, body) = out.split_at_mut_checked(2).ok_or(WireError::TooLarge)?;
    head[0] = block;
    head[1] = 0;
    let mut bw = BitWriter::new(body);
    let mut ad_grid = Adapt::new();
    let mut prev = 0i32;
    for &v in g.iter() {
        ad_grid.put(&mut bw, zigzag(i32::from(v) - prev))?;
        prev = i32::from(v);
    }
    let (g, tols) = (&*g, &*tols);
    let (mut ad_bg, mut ad_ex, mut ad_val) = (Adapt::new(), Adapt::new(), Adapt::new());
    for y in 0..h {
        let row = &samples[y * w..(y + 1) * w];
        let tol_row = &tols[(y / b) * gw..(y / b + 1) * gw];
        let exact = |x: usize| {
            (i32::from(row[x].level()) - background(g, gw, gh, b, x, y)).abs()
                > i32::from(tol_row[x / b])
        };
        let mut x = 0;
        while x < w {
            let start = x;
            while x < w && !exact(x) {
                x += 1;
            }
            ad_bg.put(&mut bw, (x - start) as u32)?;
            if x == w {
                break;
            }
            let start = x;
            while x < w && exact(x) {
                x += 1;
            }
            ad_ex.put(&mut bw, (x - start - 1) as u32)?;
            let mut pred = background(g, gw, gh, b, start, y);
            for s in &row[start..x] {
                let v = i32::from(s.level());
                ad_val.put(&mut bw, zigzag(v - pred))?;
                pred = v;
            }
        }
    }
    Ok(2 + bw.finish()?)
}

/// Decodes a tile payload into `out` (`rows × width` samples). `scratch`
/// holds [`sparse_scratch`] samples for `Sparse`. Malformed payloads (too
/// short, trailing garbage that does not fit, levels above `G::MAX`) are
/// [`WireError::Payload`]; nothing panics.
pub fn decode_tile<G: Gray>(
    enc: Encoding,
    payload: &[u8],
    width: u16,
    rows: u16,
    scratch: &mut [u16],
    out: &mut [G],
) -> Result<(), WireError> {
    let n = usize::from(width) * usize::from(rows);
    let out = out.get_mut(..n).ok_or(WireError::TooLarge)?;
    let level = |v: i32| -> Result<G, WireError> {
        if (0..=i32::from(G::MAX)).contains(&v) {
            Ok(G::from_level(v as u16))
        } else {
            Err(WireError::Payload)
        }
    };
    match enc {
        Encoding::None => Err(WireError::Payload),
        Encoding::Raw8 => {
            if payload.len() != n {
                return Err(WireError::Payload);
            }
            for (o, &b) in out.iter_mut().zip(payload) {
                *o = level(i32::from(b))?;
            }
            Ok(())
        }
        Encoding::Raw16 => {
            if payload.len() != 2 * n {
                return Err(WireError::Payload);
            }
            for (o, b) in out.iter_mut().zip(payload.chunks_exact(2)) {
                *o = level(i32::from(u16::from_le_bytes([b[0], b[1]])))?;
            }
            Ok(())
        }
        Encoding::Rice => {
            let w = usize::from(width);
            let mut br = BitReader {
                data: payload,
                bit: 0,
            };
            let mut ad = Adapt::new();
            for i in 0..n {
                let pred = predict(|j| i32::from(out[j].level()), i / w, i % w, w);
                let v = pred.saturating_add(unzigzag(ad.get(&mut br)?));
                out[i] = level(v)?;
            }
            finished(&br)
        }
        Encoding::Sparse => {
            let (&block, body) = payload.split_first().ok_or(WireError::Payload)?;
            let body = body.get(1..).ok_or(WireError::Payload)?;
            if !(2..=64).contains(&block) {
                return Err(WireError::Payload);
            }
            let (w, h, b) = (usize::from(width), usize::from(rows), usize::from(block));
            let (gw, gh) = (w.div_ceil(b), h.div_ceil(b));
            let g = scratch.get_mut(..gw * gh).ok_or(WireError::TooLarge)?;
            let mut br = BitReader { data: body, bit: 0 };
            let mut ad_grid = Adapt::new();
            let mut prev = 0i32;
            for cell in g.iter_mut() {
                let v = prev.saturating_add(unzigzag(ad_grid.get(&mut br)?));
                if !(0..=i32::from(u16::MAX)).contains(&v) {
                    return Err(WireError::Payload);
                }
                *cell = v as u16;
                prev = v;
            }
            let g = &*g;
            let (mut ad_bg, mut ad_ex, mut ad_val) = (Adapt::new(), Adapt::new(), Adapt::new());
            for y in 0..h {
                let row = &mut out[y * w..(y + 1) * w];
                let mut x = 0usize;
                loop {
                    let run = ad_bg.get(&mut br)? as usize;
                    let end = x
                        .checked_add(run)
                        .filter(|&e| e <= w)
                        .ok_or(WireError::Payload)?;
                    for (xi, o) in row.iter_mut().enumerate().take(end).skip(x) {
                        *o = level(background(g, gw, gh, b, xi, y))?;
                    }
                    x = end;
                    if x == w {
                        break;
                    }
                    let run = ad_ex.get(&mut br)? as usize + 1;
                    let end = x
                        .checked_add(run)
                        .filter(|&e| e <= w)
                        .ok_or(WireError::Payload)?;
                    let mut pred = background(g, gw, gh, b, x, y);
                    for o in &mut row[x..end] {
                        let v = pred.saturating_add(unzigzag(ad_val.get(&mut br)?));
                        *o = level(v)?;
                        pred = v;
                    }
                    x = end;
                    if x == w {
                        break;
                    }
                }
            }
            finished(&br)
        }
    }
}

/// A bitstream must end within its last byte.
fn finished(br: &BitReader<'_>) -> Result<(), WireError> {
    if br.bit.div_ceil(8) == br.data.len() {
        Ok(())
    } else {
        Err(WireError::Payload)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(w: usize, h: usize) -> [u8; 64 * 24] {
        let mut s = [0u8; 64 * 24];
        for y in 0..h {
            for x in 0..w {
                let mut v = 30 + ((x * 7 + y * 13) % 5) as i32;
                for &(px, py) in &[(10i32, 5i32), (40, 12), (55, 20)] {
                    let d2 = (x as i32 - px).pow(2) + (y as i32 - py).pow(2);
                    if d2 < 9 {
                        v += 200 - 20 * d2;
                    }
                }
                s[y * w + x] = v.clamp(0, 255) as u8;
            }
        }
        s
    }

    #[test]
    fn lossless_modes_are_exact() {
        let (w, h) = (64u16, 24u16);
        let s = scene(64, 24);
        let mut scratch = [0u16; 64];
        for want in [Encoding::Raw8, Encoding::Rice] {
            let mut buf = [0u8; 4096];
            let (enc, len) = encode_tile(
                want,
                &s[..],
                w,
                h,
                &Lossy::default(),
                &mut scratch,
                &mut buf,
            )
            .unwrap();
            assert_eq!(enc, want);
            let mut back = [0u8; 64 * 24];
            decode_tile(enc, &buf[..len], w, h, &mut scratch, &mut back).unwrap();
            assert_eq!(back, s);
        }
    }

    #[test]
    fn sparse_is_within_tolerance_and_particles_exact() {
        let (w, h) = (64u16, 24u16);
        let s = scene(64, 24);
        // A fixed tolerance everywhere (the contrast rule has its own test).
        let lossy = Lossy {
            contrast: 0,
            ..Lossy::default()
        };
        let mut scratch = [0u16; 64];
        let mut buf = [0u8; 4096];
        let (enc, len) = encode_tile(
            Encoding::Sparse,
            &s[..],
            w,
            h,
            &lossy,
            &mut scratch,
            &mut buf,
        )
        .unwrap();
        assert_eq!(enc, Encoding::Sparse);
        assert!(len < 64 * 24 / 4, "sparse {len} bytes");
        let mut back = [0u8; 64 * 24];
        decode_tile(enc, &buf[..len], w, h, &mut scratch, &mut back).unwrap();
        for (a, b) in s.iter().zip(back.iter()) {
            assert!((i32::from(*a) - i32::from(*b)).abs() <= i32::from(lossy.tolerance));
            if *a > 100 {
                assert_eq!(a, b);
            }
        }
    }

    /// Dim particles (4 levels over a background of 0–1, as in a
    /// window-capped band of an adaptive frame) survive the contrast rule and
    /// are erased by a fixed tolerance.
    #[test]
    fn contrast_rule_keeps_dim_particles() {
        let (w, h) = (64usize, 24usize);
        let mut s = [0u8; 64 * 24];
        for (i, v) in s.iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            *v = u8::from((x * 5 + y * 3) % 7 == 0);
            if (x % 12 == 5 || x % 12 == 6) && (y % 8 == 3 || y % 8 == 4) {
                *v = 4;
            }
        }
        let run = |contrast: u16| {
            let lossy = Lossy {
                contrast,
                ..Lossy::default()
            };
            let mut scratch = [0u16; 64];
            let mut buf = [0u8; 4096];
            let (enc, len) = encode_tile(
                Encoding::Sparse,
                &s[..],
                w as u16,
                h as u16,
                &lossy,
                &mut scratch,
                &mut buf,
            )
            .unwrap();
            let mut back = [0u8; 64 * 24];
            decode_tile(
                enc,
                &buf[..len],
                w as u16,
                h as u16,
                &mut scratch,
                &mut back,
            )
            .unwrap();
            back
        };
        let kept = run(4);
        for (a, b) in s.iter().zip(kept.iter()) {
            // Tolerance 4/4 = 1 in a particle block: noise may go, particles stay.
            assert!(a.abs_diff(*b) <= 1);
            if *a == 4 {
                assert_eq!(*b, 4, "a dim particle sample was lost");
            }
        }
        let flat = run(0);
        assert!(
            s.iter().zip(flat.iter()).any(|(a, b)| *a == 4 && *b < 2),
            "a fixed tolerance of 12 erases 4-level particles"
        );
    }

    #[test]
    fn wide_levels_go_raw16_or_rice() {
        let s: [u16; 32] = core::array::from_fn(|i| (i as u16) * 2000);
        let mut buf = [0u8; 256];
        let (enc, len) = encode_tile(
            Encoding::Raw8,
            &s[..],
            8,
            4,
            &Lossy::default(),
            &mut [],
            &mut buf,
        )
        .unwrap();
        assert_eq!((enc, len), (Encoding::Raw16, 64));
        let mut back = [0u16; 32];
        decode_tile(enc, &buf[..len], 8, 4, &mut [], &mut back).unwrap();
        assert_eq!(back, s);
        let mut narrow = [0u8; 32];
        assert_eq!(
            decode_tile(enc, &buf[..len], 8, 4, &mut [], &mut narrow),
            Err(WireError::Payload)
        );
    }
}
