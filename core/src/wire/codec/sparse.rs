//! The lossy `Sparse` mode: `block u8, 0u8`, then a bitstream of the
//! background grid (block means of the darker half, Rice-coded deltas) and,
//! per row, alternating runs of background (decoded as the bilinear
//! upsampling of the grid) and exact samples (Rice-coded left-neighbour
//! residuals). See the [module above](super) for the tolerance rule.
//!
//! `SparseContext` makes the same decisions and decodes to the same
//! samples, and codes them with the range coder instead: the grid's
//! deltas, then per sample whether it is exact (a model per pattern of its
//! five causal neighbours' flags) and, if it is, its residual against the median predictor of the
//! decoded neighbours (the `Context` mode's models).

use super::bits::{BitReader, BitWriter};
use super::context::{causal, neighbourhood, CONTEXTS};
use super::range::{Bit, Decoder, Encoder, Signed};
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
/// of the upper one, out of `2·block`. 32-bit arithmetic (positions are
/// below 2¹⁶, blocks at most 64): a 64-bit division is a library call of
/// dozens of instructions on a Cortex-M4, a 32-bit one is `udiv`.
#[inline]
fn axis(x: usize, block: usize, cells: usize) -> (usize, u32) {
    let (twice, b) = (2 * x as u32 + 1, block as u32);
    if twice <= b || cells < 2 {
        return (0, 0);
    }
    let (num, den) = (twice - b, 2 * b);
    let j = (num / den) as usize;
    if j >= cells - 1 {
        (cells - 1, 0)
    } else {
        (j, num - j as u32 * den)
    }
}

/// The upsampled background at (x, y) of a tile, from its grid `g`
/// (`gw` cells per row). In `u32`: levels below 2¹⁶ times weights of at
/// most 128 per axis stay below 2³¹.
#[inline]
fn background(g: &[u16], gw: usize, gh: usize, block: usize, x: usize, y: usize) -> i32 {
    let (jx, fx) = axis(x, block, gw);
    let (jy, fy) = axis(y, block, gh);
    let den = 2 * block as u32;
    let at = |r: usize, c: usize| u32::from(g.get(r * gw + c).copied().unwrap_or(0));
    let (jx1, jy1) = ((jx + 1).min(gw - 1), (jy + 1).min(gh - 1));
    let top = at(jy, jx) * (den - fx) + at(jy, jx1) * fx;
    let bot = at(jy1, jx) * (den - fx) + at(jy1, jx1) * fx;
    let v = top * (den - fy) + bot * fy;
    ((v + den * den / 2) / (den * den)) as i32
}

/// The background grid (block means of the darker half) and each block's
/// tolerance, into the first `2 × cells` samples of `scratch`; returns
/// `(grid, tolerances, rest of scratch, (gw, gh))`.
#[allow(clippy::type_complexity)]
fn plan<'s, G: Gray>(
    samples: &[G],
    width: u16,
    rows: u16,
    lossy: &Lossy,
    scratch: &'s mut [u16],
) -> Result<(&'s mut [u16], &'s mut [u16], &'s mut [u16], (usize, usize)), WireError> {
    let block = lossy.block;
    if !(2..=64).contains(&block) {
        return Err(WireError::Field);
    }
    let (w, h, b) = (usize::from(width), usize::from(rows), usize::from(block));
    let (gw, gh) = (w.div_ceil(b), h.div_ceil(b));
    let cells = gw * gh;
    if scratch.len() < 2 * cells {
        return Err(WireError::TooLarge);
    }
    let (g, rest) = scratch.split_at_mut(cells);
    let (tols, rest) = rest.split_at_mut(cells);
    for (j, (cell, tol)) in g.iter_mut().zip(tols.iter_mut()).enumerate() {
        let (y0, x0) = ((j / gw) * b, (j % gw) * b);
        let (level, max) = block_level(samples, w, x0, (x0 + b).min(w), y0, (y0 + b).min(h));
        *cell = level;
        *tol = match lossy.contrast {
            0 => lossy.tolerance,
            c => lossy.tolerance.min(max.saturating_sub(level) / c),
        };
    }
    Ok((g, tols, rest, (gw, gh)))
}

/// The sparse modes' payload head, `block u8, 0u8`, before `body`.
fn write_head(out: &mut [u8], block: u8) -> Result<&mut [u8], WireError> {
    let (head, body) = out.split_at_mut_checked(2).ok_or(WireError::TooLarge)?;
    head.copy_from_slice(&[block, 0]);
    Ok(body)
}

/// Reads the sparse modes' payload head: the block edge (`2..=64`), the
/// grid's cells per row and rows, and the coded body.
fn read_head(
    payload: &[u8],
    w: usize,
    h: usize,
) -> Result<(usize, usize, usize, &[u8]), WireError> {
    let (&block, body) = payload.split_first().ok_or(WireError::Payload)?;
    let body = body.get(1..).ok_or(WireError::Payload)?;
    if !(2..=64).contains(&block) {
        return Err(WireError::Payload);
    }
    let b = usize::from(block);
    Ok((b, w.div_ceil(b), h.div_ceil(b), body))
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
    let (g, tols, _, (gw, gh)) = plan(samples, width, rows, lossy, scratch)?;
    let block = lossy.block;
    let (w, h, b) = (usize::from(width), usize::from(rows), usize::from(block));
    let mut bw = BitWriter::new(write_head(out, block)?);
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
    let (w, h) = (usize::from(width), usize::from(rows));
    let (b, gw, gh, body) = read_head(payload, w, h)?;
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

/// Context of a sample's exact flag: the flags of its left, left-left,
/// upper-left, above and upper-right neighbours (`cur`: this row's flags so
/// far, `up`: the row above, `None` on the first row).
#[inline]
fn flag_context(cur: &[u16], up: Option<&[u16]>, x: usize) -> usize {
    let at =
        |r: &[u16], j: Option<usize>| j.and_then(|j| r.get(j)).map_or(0, |&f| usize::from(f != 0));
    let mut c = at(cur, x.checked_sub(1)) | at(cur, x.checked_sub(2)) << 1;
    if let Some(up) = up {
        c |= at(up, x.checked_sub(1)) << 2 | at(up, Some(x)) << 3 | at(up, Some(x + 1)) << 4;
    }
    c
}

/// Context of an exact sample's residual: the `Context` mode's `ctx`
/// times how many of its four nearest causal neighbours (left, upper-left,
/// above, upper-right) were exact — none (a sample leaving the flattened
/// background: a large step from its background neighbours), one or two
/// (a particle's edge), three or four (inside a particle or a dim block).
#[inline]
fn value_context(ctx: usize, flags: usize) -> usize {
    let exact = (flags & 0b11101).count_ones();
    ctx * 3 + (exact as usize).div_ceil(2)
}

/// The models of the `SparseContext` stream.
struct Models {
    grid: Signed,
    flag: [Bit; 32],
    value: [Signed; 3 * CONTEXTS],
}

impl Models {
    const NEW: Models = Models {
        grid: Signed::NEW,
        flag: [Bit::NEW; 32],
        value: [Signed::NEW; 3 * CONTEXTS],
    };
}

/// Scratch samples of the `SparseContext` encoder besides the grid and
/// tolerances: two rows of decoded samples, two of flags.
pub(super) const fn context_rows(width: u16) -> usize {
    4 * width as usize
}

/// Codes `samples` in the `SparseContext` mode; returns the bytes.
pub(super) fn encode_context<G: Gray>(
    samples: &[G],
    width: u16,
    rows: u16,
    lossy: &Lossy,
    scratch: &mut [u16],
    out: &mut [u8],
) -> Result<usize, WireError> {
    let (g, tols, rest, (gw, gh)) = plan(samples, width, rows, lossy, scratch)?;
    let (w, h, b) = (
        usize::from(width),
        usize::from(rows),
        usize::from(lossy.block),
    );
    let rest = rest.get_mut(..4 * w).ok_or(WireError::TooLarge)?;
    let (mut dec_up, rest) = rest.split_at_mut(w);
    let (mut dec, rest) = rest.split_at_mut(w);
    let (mut flag_up, mut flag) = rest.split_at_mut(w);
    let mut e = Encoder::new(write_head(out, lossy.block)?);
    let mut m = Models::NEW;
    let mut prev = 0i32;
    for &v in g.iter() {
        m.grid.put(&mut e, i32::from(v) - prev)?;
        prev = i32::from(v);
    }
    let (g, tols) = (&*g, &*tols);
    for y in 0..h {
        let row = &samples[y * w..(y + 1) * w];
        let tol_row = &tols[(y / b) * gw..(y / b + 1) * gw];
        for x in 0..w {
            let bg = background(g, gw, gh, b, x, y);
            let v = i32::from(row[x].level());
            let tol = tol_row[x / b];
            let exact = (v - bg).abs() > i32::from(tol);
            let up = (y > 0).then_some(&*flag_up);
            let fc = flag_context(flag, up, x);
            e.bit(&mut m.flag[fc], exact)?;
            if exact {
                let up = (y > 0).then_some(|j: usize| i32::from(dec_up[j]));
                let (pred, ctx) = neighbourhood(causal(|j| i32::from(dec[j]), up, x, w));
                m.value[value_context(ctx, fc)].put(&mut e, v - pred)?;
            }
            // Levels of `bg` are those of the grid: within u16.
            dec[x] = if exact { v as u16 } else { bg as u16 };
            flag[x] = u16::from(exact);
        }
        core::mem::swap(&mut dec, &mut dec_up);
        core::mem::swap(&mut flag, &mut flag_up);
    }
    Ok(2 + e.finish()?)
}

/// Decodes a `SparseContext` payload into `out` (`rows × width` samples);
/// `scratch` holds the grid and two rows of flags.
pub(super) fn decode_context<G: Gray>(
    payload: &[u8],
    width: u16,
    rows: u16,
    scratch: &mut [u16],
    out: &mut [G],
) -> Result<(), WireError> {
    let (w, h) = (usize::from(width), usize::from(rows));
    let (b, gw, gh, body) = read_head(payload, w, h)?;
    let scratch = scratch
        .get_mut(..gw * gh + 2 * w)
        .ok_or(WireError::TooLarge)?;
    let (g, rest) = scratch.split_at_mut(gw * gh);
    let (mut flag_up, mut flag) = rest.split_at_mut(w);
    let mut d = Decoder::new(body)?;
    let mut m = Models::NEW;
    let mut prev = 0i32;
    for cell in g.iter_mut() {
        let v = prev.saturating_add(m.grid.get(&mut d)?);
        if !(0..=i32::from(u16::MAX)).contains(&v) {
            return Err(WireError::Payload);
        }
        *cell = v as u16;
        prev = v;
    }
    let g = &*g;
    for y in 0..h {
        let (done, rest) = out.split_at_mut(y * w);
        let row = &mut rest[..w];
        let above = y.checked_sub(1).map(|u| &done[u * w..(u + 1) * w]);
        for x in 0..w {
            let up = (y > 0).then_some(&*flag_up);
            let fc = flag_context(flag, up, x);
            let exact = d.bit(&mut m.flag[fc])?;
            row[x] = if exact {
                let up = above.map(|r| |j: usize| i32::from(r[j].level()));
                let (pred, ctx) = neighbourhood(causal(|j| i32::from(row[j].level()), up, x, w));
                let model = &mut m.value[value_context(ctx, fc)];
                level(pred.saturating_add(model.get(&mut d)?))?
            } else {
                level(background(g, gw, gh, b, x, y))?
            };
            flag[x] = u16::from(exact);
        }
        core::mem::swap(&mut flag, &mut flag_up);
    }
    d.finished()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 32-bit upsampling equals the formula of docs/protocol.md §2
    /// evaluated in 128-bit integers, at the largest levels and blocks
    /// (where 32 bits would overflow if the bound were wrong) and at the
    /// tile's edges.
    #[test]
    fn background_is_exact_at_the_extremes() {
        for block in [2usize, 3, 7, 8, 31, 64] {
            let (w, h) = (5 * block + 3, 3 * block + 1);
            let (gw, gh) = (w.div_ceil(block), h.div_ceil(block));
            let g: [u16; 64] = core::array::from_fn(|i| {
                if i % 3 == 0 {
                    u16::MAX
                } else {
                    (i * 977 % 65536) as u16
                }
            });
            let reference = |x: usize, y: usize| -> i32 {
                let weights = |p: usize, cells: usize| -> (usize, u128) {
                    let (num, den) = (2 * p as i128 + 1 - block as i128, 2 * block as i128);
                    if num <= 0 || cells < 2 {
                        return (0, 0);
                    }
                    let j = (num / den) as usize;
                    if j >= cells - 1 {
                        (cells - 1, 0)
                    } else {
                        (j, (num - j as i128 * den) as u128)
                    }
                };
                let ((jx, fx), (jy, fy)) = (weights(x, gw), weights(y, gh));
                let den = 2 * block as u128;
                let at = |r: usize, c: usize| u128::from(g[r * gw + c]);
                let (jx1, jy1) = ((jx + 1).min(gw - 1), (jy + 1).min(gh - 1));
                let top = at(jy, jx) * (den - fx) + at(jy, jx1) * fx;
                let bot = at(jy1, jx) * (den - fx) + at(jy1, jx1) * fx;
                ((top * (den - fy) + bot * fy + den * den / 2) / (den * den)) as i32
            };
            assert!(gw * gh <= g.len());
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(
                        background(&g, gw, gh, block, x, y),
                        reference(x, y),
                        "block {block} at ({x}, {y})"
                    );
                }
            }
        }
    }
}
