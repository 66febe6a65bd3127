//! The lossy `Sparse` mode: `block u8, 0u8`, then a bitstream of the
//! background grid (block means of the darker half, Rice-coded deltas) and,
//! per row, alternating runs of background (decoded as the bilinear
//! upsampling of the grid) and exact samples (Rice-coded left-neighbour
//! residuals). See the [module above](super) for the tolerance rule.

use super::bits::{BitReader, BitWriter};
use super::rice::{unzigzag, zigzag, Adapt};
use super::{level, Lossy};
use crate::gray::Gray;
use crate::wire::WireError;

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

/// Codes `samples` in the sparse mode; returns the bytes.
pub(super) fn encode<G: Gray>(
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

/// Decodes a sparse payload into `out` (`rows × width` samples).
pub(super) fn decode<G: Gray>(
    payload: &[u8],
    width: u16,
    rows: u16,
    scratch: &mut [u16],
    out: &mut [G],
) -> Result<(), WireError> {
    let (&block, body) = payload.split_first().ok_or(WireError::Payload)?;
    let body = body.get(1..).ok_or(WireError::Payload)?;
    if !(2..=64).contains(&block) {
        return Err(WireError::Payload);
    }
    let (w, h, b) = (usize::from(width), usize::from(rows), usize::from(block));
    let (gw, gh) = (w.div_ceil(b), h.div_ceil(b));
    let g = scratch.get_mut(..gw * gh).ok_or(WireError::TooLarge)?;
    let mut br = BitReader::new(body);
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
    br.finished()
}
