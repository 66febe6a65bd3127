//! The lossless `Context` mode: per sample the residual of the LOCO-I
//! median edge predictor, range-coded (`range`) with a model chosen by the
//! sample's causal neighbourhood — how much the four decoded neighbours
//! (left, upper-left, above, upper-right) vary, and how bright they are.
//! A flat suppressed background then costs a few hundredths of a bit per
//! sample, where the Rice code spends at least one; particle edges get
//! models of their own scale. The context rule is the same in encoder and
//! decoder and reads decoded samples only.

use super::level;
use super::range::{Decoder, Encoder, Signed};
use crate::gray::Gray;
use crate::wire::WireError;

/// Activity classes (the sum of the three gradient magnitudes).
const ACTIVITY: [i32; 11] = [0, 1, 2, 4, 6, 9, 14, 21, 32, 48, 72];
/// Brightness classes (the brightest neighbour).
const BRIGHT: [i32; 2] = [3, 24];
/// Contexts: activity × brightness.
pub(super) const CONTEXTS: usize = (ACTIVITY.len() + 1) * (BRIGHT.len() + 1);

/// The class of `v` among the ascending upper bounds `t`.
#[inline]
fn class(v: i32, t: &[i32]) -> usize {
    t.iter().take_while(|&&b| v > b).count()
}

/// LOCO-I median edge predictor from left `a`, above `b`, upper-left `c`:
/// `min(a, b)` when `c ≥ max(a, b)`, `max(a, b)` when `c ≤ min(a, b)`,
/// else `a + b − c` — which is `a + b − c` clamped to `[min, max]`, the
/// form computed here (no branches: the branchy form mispredicted on
/// noisy backgrounds).
#[inline]
pub(super) fn med(a: i32, b: i32, c: i32) -> i32 {
    (a + b - c).max(a.min(b)).min(a.max(b))
}

/// The causal neighbours of column `x` — left `a`, above `b`, upper-left
/// `c`, upper-right `d` — read by `cur` (this row) and `up` (the row above,
/// `None` on the tile's first row) from decoded samples. Outside the tile
/// the left neighbour stands for the missing above row and the above one
/// for the missing left column, as in LOCO-I.
#[inline]
pub(super) fn causal(
    cur: impl Fn(usize) -> i32,
    up: Option<impl Fn(usize) -> i32>,
    x: usize,
    w: usize,
) -> [i32; 4] {
    match up {
        None if x == 0 => [0; 4],
        None => [cur(x - 1); 4],
        Some(up) => {
            let b = up(x);
            let (a, c) = if x == 0 {
                (b, b)
            } else {
                (cur(x - 1), up(x - 1))
            };
            let d = if x + 1 < w { up(x + 1) } else { b };
            [a, b, c, d]
        }
    }
}

/// Prediction and context of a sample from its causal neighbours.
#[inline]
pub(super) fn neighbourhood([a, b, c, d]: [i32; 4]) -> (i32, usize) {
    let act = (d - b).abs() + (b - c).abs() + (c - a).abs();
    let bright = a.max(b).max(c).max(d);
    let ctx = class(act, &ACTIVITY) * (BRIGHT.len() + 1) + class(bright, &BRIGHT);
    (med(a, b, c), ctx)
}

/// Codes `samples` (rows of `w`); returns the bytes.
pub(super) fn encode<G: Gray>(samples: &[G], w: usize, out: &mut [u8]) -> Result<usize, WireError> {
    let mut e = Encoder::new(out);
    let mut models = [Signed::NEW; CONTEXTS];
    for (y, row) in samples.chunks_exact(w.max(1)).enumerate() {
        let up = y
            .checked_sub(1)
            .map(|u| move |j: usize| i32::from(samples[u * w + j].level()));
        for (x, s) in row.iter().enumerate() {
            let n = causal(|j| i32::from(row[j].level()), up, x, w);
            let (pred, ctx) = neighbourhood(n);
            models[ctx].put(&mut e, i32::from(s.level()) - pred)?;
        }
    }
    e.finish()
}

/// Decodes a `Context` payload into `out` (rows of `width`).
pub(super) fn decode<G: Gray>(payload: &[u8], width: u16, out: &mut [G]) -> Result<(), WireError> {
    let w = usize::from(width);
    let mut d = Decoder::new(payload)?;
    let mut models = [Signed::NEW; CONTEXTS];
    for y in 0..out.len() / w.max(1) {
        let (done, rest) = out.split_at_mut(y * w);
        let row = &mut rest[..w];
        let up = y.checked_sub(1).map(|u| &done[u * w..(u + 1) * w]);
        for x in 0..w {
            let up = up.map(|r| |j: usize| i32::from(r[j].level()));
            let (pred, ctx) = neighbourhood(causal(|j| i32::from(row[j].level()), up, x, w));
            row[x] = level(pred.saturating_add(models[ctx].get(&mut d)?))?;
        }
    }
    d.finished()
}
