//! Adaptive integration (paper section 2.3; docs/spec.md §5): for each particle
//! region, `S(n)` = mean count per region pixel and `B(n)` = mean count per
//! pixel of its 2-px ring, over the centred windows n = 1, 2, 4, …, n_max,
//! then every integer in `[n/2, 2n]` around the best;
//! `SNR(n) = (S − B)/sqrt(var(B))` with `var(B) = 1/4 + (σ_fpn·B)² + B/g`.
//! The maximising n* (the smallest on a tie) is the region's integration
//! time, ≈ its pixel dwell time.
//!
//! Cost: one pass over the region's bounding box (plus 2 px) for each tick
//! of the n_max span builds per-tick spike sums of region and ring; every
//! window is then two prefix-sum lookups (offsets from a per-frame table),
//! and SNRs are compared exactly as rationals (no square root, no
//! division), so the choice of n* is exact. The integer search skips runs
//! of windows whose SNR bound is below a score already seen (`search`):
//! on the default scene it scores about 11 of the 71 integer windows per
//! region, and finds the same n* as scoring all of them (tested).
//! Memory: two 256-entry `u32` tables on the stack (2 KiB).

use core::cmp::Ordering;

use crate::motion::{shift, shifted_word};
use crate::params::Params;
use crate::region::Region;
use crate::slices::{self, Counter};
use crate::state::Workspace;
use crate::window::{Span, Window};

/// The two integers that fix a region's SNR at one window, up to a positive
/// factor shared by all windows of that region:
/// `SNR ∝ d / sqrt(v)`, `d = S_sum·N_r − B_sum·N_p`,
/// `v = var(B)·4·g·2^32·N_r²`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SnrTerms {
    /// Signed contrast numerator.
    pub d: i128,
    /// Scaled variance (saturating).
    pub v: u128,
}

/// SNR terms of a region of `np` pixels with ring of `nr` pixels (0 is
/// read as an empty ring with B = 0), given their spike sums over one window.
pub fn snr_terms(s_sum: u64, b_sum: u64, np: u32, nr: u32, p: &Params) -> SnrTerms {
    let nr = u128::from(nr.max(1));
    let (s, b, np) = (i128::from(s_sum), u128::from(b_sum), i128::from(np));
    let d = s * nr as i128 - b as i128 * np;
    let g = u128::from(p.electrons_per_spike.max(1));
    let sig = u128::from(p.sigma_fpn.to_bits());
    let v = (g << 32)
        .saturating_mul(nr * nr)
        .saturating_add((4 * g * sig * sig).saturating_mul(b.saturating_mul(b)))
        .saturating_add((b << 34).saturating_mul(nr));
    SnrTerms { d, v }
}

/// `a·b` as a 256-bit number `(high, low)`.
fn mul_wide(a: u128, b: u128) -> (u128, u128) {
    let mask = u128::from(u64::MAX);
    let (a0, a1) = (a & mask, a >> 64);
    let (b0, b1) = (b & mask, b >> 64);
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let p11 = a1 * b1;
    let mid = (p00 >> 64) + (p01 & mask) + (p10 & mask);
    let lo = (p00 & mask) | (mid << 64);
    let hi = p11 + (p01 >> 64) + (p10 >> 64) + (mid >> 64);
    (hi, lo)
}

/// Compares two SNRs of the same region exactly.
pub fn cmp_snr(a: &SnrTerms, b: &SnrTerms) -> Ordering {
    let sa = a.d.signum();
    let sb = b.d.signum();
    if sa != sb {
        return sa.cmp(&sb);
    }
    if sa == 0 {
        return Ordering::Equal;
    }
    let da = a.d.unsigned_abs();
    let db = b.d.unsigned_abs();
    // |SNR_a| vs |SNR_b|  <=>  da²·vb vs db²·va
    let lhs = mul_wide(da.saturating_mul(da), b.v);
    let rhs = mul_wide(db.saturating_mul(db), a.v);
    let mag = lhs.cmp(&rhs);
    if sa > 0 {
        mag
    } else {
        mag.reverse()
    }
}

/// Cells (row, word) of a region's neighbourhood summed per tick at once.
const CELLS: usize = 32;

/// One word of a region's neighbourhood: strip row, word index, and the
/// ring's and the region's pixels in it.
#[derive(Debug, Clone, Copy, Default)]
struct Cell {
    /// The word's index in a band plane.
    at: usize,
    ring: u64,
    reg: u64,
    /// The word's predicted velocity (1/4096 px per tick; 0 without a
    /// motion).
    v: (i16, i16),
    /// Strip row and word of the row.
    r: u16,
    j: u16,
    /// A narrow half ([`parts`]): its masks span at most 8 bits, stored
    /// shifted down by `sh`, so a tick's count is a [`POP8`] lookup.
    narrow: bool,
    sh: u8,
}

/// `POP8[b]`: the set bits of byte `b`. Narrow cells' popcounts on
/// 32-bit targets (the Cortex-M4 has no popcount instruction, and a
/// software one is about twelve; hand-written because `count_ones`
/// does not know the value is a byte).
const POP8: [u8; 256] = {
    let mut t = [0u8; 256];
    let mut b = 0;
    while b < 256 {
        t[b] = (b as u32).count_ones() as u8;
        b += 1;
    }
    t
};

/// A window's SNR, ready to compare: its spike sums, and the SNR's square
/// with its sign in `f32` (`d·|d|/v` of [`snr_terms`], from the same
/// integers). Two windows whose approximations differ by more than
/// 10⁻⁵ of the larger are ordered by them — the `f32` error of a handful
/// of roundings is below 10⁻⁶, so the order is the exact one — and all
/// others by [`cmp_snr`], so the choice of n* is exact and the 256-bit
/// products, a large share of a frame's cost were they run for every
/// comparison, run only for near ties.
#[derive(Debug, Clone, Copy)]
struct Scored {
    s: u64,
    b: u64,
    /// NaN where there is none: every comparison with it is false, so it
    /// goes to the exact test (an `Option` cost the search a tag to store
    /// and test per window).
    approx: f32,
}

impl Scored {
    fn new(s: u64, b: u64, np: u32, nr: u32, p: &Params) -> Scored {
        let nrf = nr.max(1) as f32;
        let d = contrast(s, b, np, nr);
        let v = variance_approx(b, nrf, p);
        // Past 10^37 the exact terms may saturate: no approximation.
        // `d` is always finite (a rounded integer below 2^127); `v < 1e37`
        // is false for an infinite or NaN `v`.
        let approx = if v < 1e37 { d * d.abs() / v } else { f32::NAN };
        Scored { s, b, approx }
    }

    /// Whether this SNR is certainly above that of every window whose
    /// region sum is at most `s_hi` and whose ring sum is at least `b_lo`
    /// (the contrast is at most `s_hi·N_r − b_lo·N_p`, the variance, which
    /// grows with the ring sum, at least that of `b_lo`). Decided in `f32`
    /// with a margin of 10⁻⁴, a hundred times the approximations' error,
    /// so `true` is exact; anything in doubt (a non-positive SNR here, no
    /// approximation) is `false`.
    fn bounds_above(&self, s_hi: u64, b_lo: u64, np: u32, nr: u32, p: &Params) -> bool {
        let x = self.approx;
        if x.is_nan() || x <= 0.0 {
            return false;
        }
        let d = contrast(s_hi, b_lo, np, nr);
        if d <= 0.0 {
            // Every window of the block has a non-positive SNR.
            return true;
        }
        let v = variance_approx(b_lo, nr.max(1) as f32, p);
        let bound = d * d / v;
        bound.is_finite() && v.is_finite() && bound < x * (1.0 - 1e-4)
    }

    /// Whether this window's SNR beats `o`'s (exactly): by the
    /// approximations where they are far enough apart (inlined: the search
    /// compares about twenty windows per region), else exactly.
    #[inline(always)]
    fn greater(&self, o: &Scored, np: u32, nr: u32, p: &Params) -> bool {
        let (x, y) = (self.approx, o.approx);
        // False where either is NaN (`x - y` is).
        if (x - y).abs() > 1e-5 * x.abs().max(y.abs()) {
            return x > y;
        }
        self.greater_exact(o, np, nr, p)
    }

    /// [`Scored::greater`] by the 256-bit comparison (near ties, or no
    /// approximation).
    #[cold]
    #[inline(never)]
    fn greater_exact(&self, o: &Scored, np: u32, nr: u32, p: &Params) -> bool {
        // The same sums (a tick without spikes between two windows): the
        // same SNR. The usual near tie, settled without the products.
        if (self.s, self.b) == (o.s, o.b) {
            return false;
        }
        let (a, b) = (
            snr_terms(self.s, self.b, np, nr, p),
            snr_terms(o.s, o.b, np, nr, p),
        );
        cmp_snr(&a, &b) == Ordering::Greater
    }
}

/// `d` of [`snr_terms`], exact and then rounded once to `f32` (its sign
/// exact). In `i64` where it fits (a 128-bit conversion is a library call).
fn contrast(s: u64, b: u64, np: u32, nr: u32) -> f32 {
    let narrow = || {
        let a = i64::try_from(s).ok()?.checked_mul(i64::from(nr.max(1)))?;
        a.checked_sub(i64::try_from(b).ok()?.checked_mul(i64::from(np))?)
    };
    match narrow() {
        Some(x) => f32_of(x),
        None => (i128::from(s) * i128::from(nr.max(1)) - i128::from(b) * i128::from(np)) as f32,
    }
}

/// `x` rounded to `f32`. On 32-bit targets through a 32-bit conversion
/// where it fits: a 64-bit one is a library call there (about 40
/// Thumb-2 instructions), a 32-bit one a single instruction, and both
/// round the same value.
#[inline]
fn f32_of(x: i64) -> f32 {
    match i32::try_from(x) {
        Ok(v) if cfg!(target_pointer_width = "32") => v as f32,
        _ => x as f32,
    }
}

/// `v` of [`snr_terms`] in `f32`: `g·2^32·nr² + 4g·σ²·b² + b·2^34·nr`
/// (σ in bits), growing with `b`.
fn variance_approx(b: u64, nrf: f32, p: &Params) -> f32 {
    let g = f32::from(p.electrons_per_spike.max(1));
    let sig = f32::from(p.sigma_fpn.to_bits());
    let bf = i64::try_from(b).map_or(b as f32, f32_of);
    g * 4_294_967_296.0 * nrf * nrf + 4.0 * g * sig * sig * bf * bf + bf * 17_179_869_184.0 * nrf
}

/// Adds to `pt[i + 1]` ([`put`]) the spikes of plane `i` (tick
/// `start + i`) under the region and ring masks of the `N` cells `cells`,
/// `word(plane, tick, cell)` reading a cell's word. With `plain` (the
/// word is the plane's word `at`) and cells within [`NEAR`] words of the
/// first (a region's rows, a few words each), each tick's words are read
/// from one `NEAR`-word window of the plane: one bounds check per tick
/// instead of one per cell (the per-tick sums are the region stage's
/// main cost).
///
/// `HALF` (plain cells only, [`HALVES`]): each cell is one `u32` half of
/// a plane word — `at` indexes the plane read as `u32`s, the masks are in
/// its low 32 bits. `NARROW` (with `HALF` only): every cell is a narrow
/// half ([`narrowed`]), counted by [`POP8`] lookups.
#[inline(always)]
fn sum_cells<const N: usize, const RING_ONLY: bool, const HALF: bool, const NARROW: bool>(
    span: &Span<'_>,
    (word, plain): (&impl Fn(&[u64], u32, &Cell) -> u64, bool),
    cells: &[Cell],
    pt: &mut [Tick; 256],
) {
    let Ok(cells) = <&[Cell; N]>::try_from(cells) else {
        return;
    };
    // One loop bound (the planes and their sums cut to the same length),
    // and the choice between the windowed and the per-cell reads made once
    // per batch, not per tick: the per-tick overhead was half the work of
    // a small batch.
    let start = span.start;
    let planes = span.planes();
    let n = planes.len().min(255);
    let planes = &planes[..n];
    if plain {
        let runs = span.runs();
        if runs.stride > 0 {
            // A plane's lanes; one window of `NEAR` of them, within a
            // plane, that holds every cell of the batch (moved back from
            // the first cell where that would pass the plane's end), or
            // none: the batch is then read cell by cell.
            let words = runs.stride.max(1);
            let stride = if HALF { 2 * words } else { words };
            let base = cells[0].at;
            let near = stride >= NEAR
                && cells
                    .iter()
                    .all(|c| c.at < stride && c.at.checked_sub(base).is_some_and(|o| o < NEAR));
            let wb = base.min(stride.saturating_sub(NEAR));
            let offs: [usize; N] = core::array::from_fn(|q| cells[q].at.wrapping_sub(wb) % NEAR);
            let window = near.then_some((wb, wb + NEAR, &offs));
            // The held planes run by run, stepping a pointer (the ticks
            // not held add nothing).
            for &(o, run) in &runs.runs {
                let Some(sums) = pt.get_mut(1 + o..=n) else {
                    continue;
                };
                let sums = sums.iter_mut();
                if HALF {
                    let lanes: &[u32] = bytemuck::cast_slice(run);
                    let planes = lanes.chunks_exact(stride);
                    run_sums::<u32, N, RING_ONLY, NARROW>(planes, stride, cells, window, sums);
                } else {
                    let planes = run.chunks_exact(words);
                    run_sums::<u64, N, RING_ONLY, false>(planes, stride, cells, window, sums);
                }
            }
            return;
        }
        // A span without runs (built from slices, in tests): plane by
        // plane, cell by cell.
        let sums = pt[1..=n].iter_mut();
        if HALF {
            plain_sums::<u32, RING_ONLY, NARROW>(planes, cells, sums);
        } else {
            plain_sums::<u64, RING_ONLY, false>(planes, cells, sums);
        }
        return;
    }
    for (i, (plane, sb)) in planes.iter().zip(&mut pt[1..=n]).enumerate() {
        let t = start + i as u32;
        let (mut hs, mut hb) = (0u32, 0u32);
        for c in cells {
            let w = word(plane, t, c);
            hb += (w & c.ring).count_ones();
            if !RING_ONLY {
                hs += (w & c.reg).count_ones();
            }
        }
        put::<RING_ONLY>(sb, (hs, hb));
    }
}

/// What the plain sums ([`run_sums`], [`plain_sums`]) read a plane as: its `u64` words, or their `u32`
/// halves ([`HALVES`]).
trait Lane: bytemuck::Pod + core::ops::BitAnd<Output = Self> {
    /// A cell's mask as a lane (a half's mask is in the low 32 bits).
    fn mask(m: u64) -> Self;
    fn ones(self) -> u32;
    /// The low 32 bits.
    fn low32(self) -> u32;
}

impl Lane for u64 {
    fn mask(m: u64) -> u64 {
        m
    }
    fn ones(self) -> u32 {
        self.count_ones()
    }
    fn low32(self) -> u32 {
        self as u32
    }
}

impl Lane for u32 {
    fn mask(m: u64) -> u32 {
        m as u32
    }
    fn ones(self) -> u32 {
        self.count_ones()
    }
    fn low32(self) -> u32 {
        self
    }
}

/// Adds a cell's spikes in lane `w` to the tick's sums `(region, ring)`.
#[inline(always)]
fn add_cell<W: Lane, const RING_ONLY: bool, const NARROW: bool>(
    (hs, hb): &mut (u32, u32),
    w: W,
    c: &Cell,
) {
    if NARROW {
        // The cell's byte of the half, looked up.
        let x = w.low32() >> (c.sh & 31);
        *hb += u32::from(POP8[usize::from(x as u8 & c.ring as u8)]);
        if !RING_ONLY {
            *hs += u32::from(POP8[usize::from(x as u8 & c.reg as u8)]);
        }
        return;
    }
    *hb += (w & W::mask(c.ring)).ones();
    if !RING_ONLY {
        *hs += (w & W::mask(c.reg)).ones();
    }
}

/// A tick's spikes under a region and under its ring. On 64-bit targets
/// one `u64`, the region's in the low 32 bits and the ring's in the high
/// ones: one add per tick and batch, one prefix pass. Neither
/// half carries into the other: a strip's pixels (≤ 2^19) times 255 ticks
/// is below 2^32, so every prefix and difference fits its half. On 32-bit
/// targets, where a `u64` add is two, the pair side by side (the packed
/// form cost the Cortex-M4 1.5 % of the frame).
#[cfg(target_pointer_width = "64")]
type Tick = u64;
#[cfg(not(target_pointer_width = "64"))]
type Tick = [u32; 2];

/// Adds a tick's sums `h` (region, ring) to its entry `sb`.
#[inline(always)]
fn put<const RING_ONLY: bool>(sb: &mut Tick, h: (u32, u32)) {
    #[cfg(target_pointer_width = "64")]
    {
        let ring = u64::from(h.1) << 32;
        *sb += if RING_ONLY {
            ring
        } else {
            ring | u64::from(h.0)
        };
    }
    #[cfg(not(target_pointer_width = "64"))]
    {
        if !RING_ONLY {
            sb[0] += h.0;
        }
        sb[1] += h.1;
    }
}

/// The region's and the ring's spikes of a tick entry (or of the
/// difference of two prefix entries, [`tick_diff`]).
#[inline(always)]
fn tick_split(t: Tick) -> (u32, u32) {
    #[cfg(target_pointer_width = "64")]
    return (t as u32, (t >> 32) as u32);
    #[cfg(not(target_pointer_width = "64"))]
    return (t[0], t[1]);
}

/// `pt` made prefix sums in place (both halves).
fn tick_prefix(pt: &mut [Tick]) {
    let mut run = Tick::default();
    for x in pt {
        #[cfg(target_pointer_width = "64")]
        {
            run += *x;
        }
        #[cfg(not(target_pointer_width = "64"))]
        {
            run = [run[0] + x[0], run[1] + x[1]];
        }
        *x = run;
    }
}

/// The region's and the ring's spikes between prefix entries `a` ≤ `e`.
#[inline(always)]
fn tick_diff(e: Tick, a: Tick) -> (u64, u64) {
    #[cfg(target_pointer_width = "64")]
    let (s, b) = tick_split(e - a);
    #[cfg(not(target_pointer_width = "64"))]
    let (s, b) = {
        let (e, a) = (tick_split(e), tick_split(a));
        (e.0 - a.0, e.1 - a.1)
    };
    (u64::from(s), u64::from(b))
}

/// [`sum_cells`] of plain cells, the planes read as lanes `W` (`at`
/// indexes them), cell by cell: a span without runs (built from slices,
/// in tests). [`run_cells`]' loop over slices of `u64`s: that function
/// taking these planes through a cast too cost the Cortex-M4 15 kB of
/// code.
#[inline(never)]
fn plain_sums<'a, W: Lane, const RING_ONLY: bool, const NARROW: bool>(
    planes: &[&[u64]],
    cells: &[Cell],
    sums: impl Iterator<Item = &'a mut Tick>,
) {
    for (plane, sb) in planes.iter().zip(sums) {
        let plane: &[W] = bytemuck::cast_slice(plane);
        let mut h = (0, 0);
        for c in cells {
            let w = plane.get(c.at).copied().unwrap_or_else(W::zeroed);
            add_cell::<W, RING_ONLY, NARROW>(&mut h, w, c);
        }
        put::<RING_ONLY>(sb, h);
    }
}

/// [`sum_cells`] of plain cells over `planes` of runs of planes side by
/// side ([`crate::window::Runs`]), `stride` lanes `W` each: through the
/// batch's `window` (first lane, end and each cell's offset) when it has
/// one within a plane, else cell by cell. The loop steps a pointer
/// instead of reading each plane's slice, and the window's bounds are
/// checked once, not per tick.
///
/// Inlined on 64-bit targets; on 32-bit ones called once per run, since
/// inlined the loop over the two runs holds its body twice: 40 kB more of
/// the Cortex-M4's code for 1 % fewer instructions (one loop over both runs chained cost it 5 %
/// more).
#[cfg_attr(target_pointer_width = "64", inline(always))]
#[cfg_attr(not(target_pointer_width = "64"), inline(never))]
fn run_sums<'a, 'p, W: Lane, const N: usize, const RING_ONLY: bool, const NARROW: bool>(
    planes: impl Iterator<Item = &'p [W]>,
    stride: usize,
    cells: &[Cell; N],
    window: Option<(usize, usize, &[usize; N])>,
    sums: impl Iterator<Item = &'a mut Tick>,
) {
    match window.filter(|&(_, end, _)| end <= stride) {
        Some((base, end, offs)) => {
            for (plane, sb) in planes.zip(sums) {
                let mut h = (0, 0);
                // Always there: every plane of a run is `stride` long.
                if let Some(win) = plane
                    .get(base..end)
                    .and_then(|s| <&[W; NEAR]>::try_from(s).ok())
                {
                    for (c, &o) in cells.iter().zip(offs) {
                        add_cell::<W, RING_ONLY, NARROW>(&mut h, win[o % NEAR], c);
                    }
                }
                put::<RING_ONLY>(sb, h);
            }
        }
        None => run_cells::<W, RING_ONLY, NARROW>(planes, cells, sums),
    }
}

/// [`run_sums`] cell by cell (a batch without a window within a plane:
/// rare, so not generic over the batch size, which keeps the Cortex-M4's
/// code small).
#[inline(never)]
fn run_cells<'a, 'p, W: Lane, const RING_ONLY: bool, const NARROW: bool>(
    planes: impl Iterator<Item = &'p [W]>,
    cells: &[Cell],
    sums: impl Iterator<Item = &'a mut Tick>,
) {
    for (plane, sb) in planes.zip(sums) {
        let mut h = (0, 0);
        for c in cells {
            let w = plane.get(c.at).copied().unwrap_or_else(W::zeroed);
            add_cell::<W, RING_ONLY, NARROW>(&mut h, w, c);
        }
        put::<RING_ONLY>(sb, h);
    }
}

/// [`sum_cells`] for any number of cells: eight at a time through every
/// tick (a tick's sums are added once per eight cells), the rest in sixes,
/// fours, twos and ones. `RING_ONLY`: the cells have no region pixels, so
/// only the ring's sums are taken (one popcount per cell and tick).
fn sum_all<const RING_ONLY: bool, const HALF: bool>(
    span: &Span<'_>,
    word: (&impl Fn(&[u64], u32, &Cell) -> u64, bool),
    cells: &mut [Cell],
    pt: &mut [Tick; 256],
) {
    if !(HALF && word.1) {
        return sum_kind::<RING_ONLY, HALF, false>(span, word, cells, pt);
    }
    // Narrow halves first, then the others (the sums do not depend on
    // the cells' order).
    let mut k = 0;
    for i in 0..cells.len() {
        if cells[i].narrow {
            cells.swap(i, k);
            k += 1;
        }
    }
    let (narrow, wide) = cells.split_at(k);
    sum_kind::<RING_ONLY, true, true>(span, word, narrow, pt);
    sum_kind::<RING_ONLY, true, false>(span, word, wide, pt);
}

/// [`sum_all`] of cells of one kind (`NARROW`: all narrow halves).
/// Kept out of line on 64-bit targets, where inlining it into [`sum_all`]
/// costs more than the call; left to the compiler on 32-bit ones, where
/// inlining is the cheaper (`docs/embedded.md`).
#[cfg_attr(target_pointer_width = "64", inline(never))]
fn sum_kind<const RING_ONLY: bool, const HALF: bool, const NARROW: bool>(
    span: &Span<'_>,
    word: (&impl Fn(&[u64], u32, &Cell) -> u64, bool),
    cells: &[Cell],
    pt: &mut [Tick; 256],
) {
    let mut rest = cells;
    // Batch sizes are const generics, so each size is its own call: the
    // largest that fits, as often as it fits (after the eights, each
    // smaller size runs at most once).
    macro_rules! batches {
        ($($n:literal),*) => {$(
            while rest.len() >= $n {
                sum_cells::<$n, RING_ONLY, HALF, NARROW>(span, word, &rest[..$n], pt);
                rest = &rest[$n..];
            }
        )*};
    }
    // Sizes measured on the default scene: plain ring-only cells (one
    // mask each) in batches up to ten, plain region cells in every size up
    // to eight (a region's last cells one batch, not several), shifted
    // words (compensated frames) as before.
    match (word.1, RING_ONLY) {
        (true, true) => {
            batches!(10, 8, 6, 4, 2, 1);
        }
        (true, false) => {
            batches!(8, 7, 6, 5, 4, 3, 2, 1);
        }
        (false, _) => {
            batches!(8, 6, 4, 2, 1);
        }
    }
}

/// Words of a plane within which [`sum_cells`] reads a batch's cells
/// through one window.
const NEAR: usize = 64;

/// Plain per-tick sums count `u32` halves of the plane words on 32-bit
/// targets: there a `u64` popcount is two software popcounts of about ten
/// instructions each, and a region's cell rarely has pixels in both
/// halves, so a cell is split into the halves it uses. On 64-bit targets a popcount is one
/// instruction and fewer, wider cells win.
const HALVES: bool = cfg!(target_pointer_width = "32");

/// The cells of one plane word `at` with ring and region masks `ring`,
/// `reg`: the word itself, or with `half` its `u32` halves that hold any
/// pixel (`at` then indexes the plane read as `u32`s, the masks shifted
/// down); `None` for a part with no pixel.
fn parts(cell: Cell, half: bool) -> [Option<Cell>; 2] {
    let keep = |c: Cell| (c.ring | c.reg != 0).then_some(c);
    if !half {
        return [keep(cell), None];
    }
    // Bits 0..32 of a word are its first u32 in memory on a
    // little-endian target, its second on a big-endian one.
    let lo = usize::from(cfg!(target_endian = "big"));
    let low = u64::from(u32::MAX);
    [
        keep(narrowed(Cell {
            at: 2 * cell.at + lo,
            ring: cell.ring & low,
            reg: cell.reg & low,
            ..cell
        })),
        keep(narrowed(Cell {
            at: 2 * cell.at + (1 - lo),
            ring: cell.ring >> 32,
            reg: cell.reg >> 32,
            ..cell
        })),
    ]
}

/// A half whose pixels span at most 8 bits, marked narrow with its masks
/// shifted down to bit 0 (half of a region's halves on the default
/// scene). Others unchanged. (Two lookups for spans up to 16 bits cost
/// the Cortex-M4 more than they saved.)
fn narrowed(c: Cell) -> Cell {
    let m = c.ring | c.reg;
    if m == 0 {
        return c;
    }
    let span = 64 - m.leading_zeros() - m.trailing_zeros();
    if span > 8 {
        return c;
    }
    let sh = m.trailing_zeros();
    Cell {
        narrow: true,
        sh: sh as u8,
        ring: c.ring >> sh,
        reg: c.reg >> sh,
        ..c
    }
}

/// Geometry of a region's neighbourhood in the strip: strip rows
/// `r0..r1` and words `j0..=j1` hold the region and its ring, rows
/// `rr.0..rr.1` the region; `width` px and `wpr` words per strip row.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    r0: usize,
    r1: usize,
    j0: usize,
    j1: usize,
    rr: (usize, usize),
    width: usize,
    wpr: usize,
}

impl Bounds {
    /// Whether strip row `r` holds region pixels.
    #[inline(always)]
    fn region_row(&self, r: usize) -> bool {
        (self.rr.0..self.rr.1).contains(&r)
    }
}

/// Finds n* of region `idx` of the strip whose row 0 is band row `s0`,
/// fills the region's window fields and leaves `c_{n*}` in `ws.c_t` for
/// each of its pixels. `ws.masks` plane 0 must hold "any region" bits.
pub(crate) fn adapt_region(
    ctx: &crate::context::Ctx<'_, '_>,
    ws: &mut Workspace<'_>,
    s0: u16,
    strip_rows: u16,
    idx: usize,
) -> Region {
    let (hist, k) = (ctx.hist, ctx.k);
    let wpr = hist.words_per_row();
    // Word j of strip row r at tick t: plain, or moved by the row's
    // predicted motion (then the region's spikes are counted where the
    // particle is at k). Chosen once, so the plain path has no branch.
    match ctx.motion {
        None => adapt_with::<HALVES>(ctx, ws, s0, strip_rows, idx, true, |plane, _t, c: &Cell| {
            plane.get(c.at).copied().unwrap_or(0)
        }),
        Some(_) => {
            adapt_with::<false>(ctx, ws, s0, strip_rows, idx, false, |plane, t, c: &Cell| {
                let dt = (i64::from(t) - i64::from(k)) as i32;
                let (sx, sy) = (shift(c.v.0, dt), shift(c.v.1, dt));
                shifted_word(plane, wpr, hist.rows(), s0 + c.r, usize::from(c.j), sx, sy)
            })
        }
    }
}

/// After [`adapt_region`]: that region's pixels in word `j` of strip row
/// `r` (mask plane 1 as the call left it; rows of the region's box).
#[inline]
pub(crate) fn own_bits(ws: &Workspace<'_>, r: usize, j: usize) -> u64 {
    let wpr = crate::plane::words_per_row(ws.sizes.width);
    let plane = usize::from(ws.sizes.rows) * wpr;
    ws.masks.get(plane + r * wpr + j).copied().unwrap_or(0)
}

/// [`adapt_region`] with `word(plane, tick, cell)`; `plain` when that is
/// the plane's word `cell.at`; `HALF` (plain only): per-tick sums over
/// `u32` halves ([`HALVES`]).
fn adapt_with<const HALF: bool>(
    ctx: &crate::context::Ctx<'_, '_>,
    ws: &mut Workspace<'_>,
    s0: u16,
    strip_rows: u16,
    idx: usize,
    plain: bool,
    word: impl Fn(&[u64], u32, &Cell) -> u64,
) -> Region {
    let (hist, p) = (ctx.hist, ctx.p);
    let mut reg = ws.regions[idx];
    let width = usize::from(ws.sizes.width);
    let wpr = crate::plane::words_per_row(ws.sizes.width);
    let plane = usize::from(ws.sizes.rows) * wpr;
    let b = Bounds {
        r0: usize::from(reg.row0.saturating_sub(2)),
        r1: (usize::from(reg.row1) + 2).min(usize::from(strip_rows)),
        j0: usize::from(reg.col0.saturating_sub(2)) / 64,
        j1: ((usize::from(reg.col1) + 2).min(width) - 1) / 64,
        rr: (usize::from(reg.row0), usize::from(reg.row1)),
        width,
        wpr,
    };
    let (any, rest) = ws.masks.split_at_mut(plane);
    let (regm, rest) = rest.split_at_mut(plane);
    let ring = &mut rest[..plane];
    region_words(ws.labels, any, regm, &b, idx as u16 + 1);
    let nr = ring_words(any, regm, ring, &b);
    // The predicted velocity of a word of a strip row.
    let vel = |r: usize, j: usize| {
        ctx.motion
            .map_or((0, 0), |m| m.at_word(s0.saturating_add(r as u16), j))
    };
    // Cells of a word in the band planes (the strip's first word is
    // `band0`).
    let band0 = usize::from(s0) * hist.words_per_row();
    let cell_at = |r: usize, j: usize| Cell {
        r: r as u16,
        j: j as u16,
        at: band0 + r * wpr + j,
        v: vel(r, j),
        ..Cell::default()
    };
    let mut pt = [Tick::default(); 256];
    tick_sums::<HALF>(
        ctx.span,
        (&word, plain),
        (regm, ring),
        &b,
        &cell_at,
        &mut pt,
    );
    // pt[i + 1] = spikes of ticks span.start .. span.start + i + 1
    let n = ctx.span.planes().len().min(255);
    tick_prefix(&mut pt[1..=n]);
    let sums = |n: u16| -> (u64, u64) {
        let (a, e) = ctx.wins.of(n);
        tick_diff(pt[e], pt[a])
    };
    let star = search(&sums, p.n_max, reg.pixels, nr, p);
    let (_, ring_sum) = sums(star);
    let win = Window::in_history(hist, ctx.k, star);
    let max_count = pixel_counts(
        ctx,
        (ws.counts, &mut *ws.c_t),
        regm,
        &b,
        win,
        (&word, &cell_at),
    );
    reg.n_star = star;
    reg.win_len = win.len;
    reg.ring_pixels = nr;
    reg.ring_sum = ring_sum as u32;
    reg.max_count = max_count;
    ws.regions[idx] = reg;
    reg
}

/// Region bits into `regm`: of the pixels some region took (`any`), those
/// labelled `id` (only they are read, not the whole bounding box). A run
/// of a row's "any" pixels is connected, so all of one region: its first
/// pixel's label answers for it.
#[inline(always)]
fn region_words(labels: &[u16], any: &[u64], regm: &mut [u64], b: &Bounds, id: u16) {
    let (width, wpr) = (b.width, b.wpr);
    for r in b.rr.0..b.rr.1 {
        for j in b.j0..=b.j1 {
            let base = r * width + 64 * j;
            regm[r * wpr + j] = slices::select_runs(any[r * wpr + j], |bit| {
                labels.get(base + bit as usize) == Some(&id)
            });
        }
    }
}

/// The ring into `ring`: the region (`regm`) dilated by 2 px (Chebyshev),
/// minus every region pixel (`any`). Returns its pixels.
#[inline(always)]
fn ring_words(any: &[u64], regm: &[u64], ring: &mut [u64], b: &Bounds) -> u32 {
    let (width, wpr) = (b.width, b.wpr);
    let last_bits = if width % 64 == 0 {
        u64::MAX
    } else {
        (1u64 << (width % 64)) - 1
    };
    let hdil = |r: usize, j: usize| -> u64 {
        let w = |jj: usize| regm[r * wpr + jj];
        let m = w(j);
        let prev = if j > b.j0 { w(j - 1) } else { 0 };
        let next = if j < b.j1 { w(j + 1) } else { 0 };
        m | m << 1 | m << 2 | m >> 1 | m >> 2 | prev >> 63 | prev >> 62 | next << 63 | next << 62
    };
    let mut nr = 0u32;
    for j in b.j0..=b.j1 {
        // Rows r − 2 ..= r + 2 dilated horizontally, each row once: the
        // vertical dilation is their OR.
        let h = |rr: usize| if b.region_row(rr) { hdil(rr, j) } else { 0 };
        let mut near = [0u64; 5];
        for (q, x) in near.iter_mut().enumerate().take(4) {
            *x = (b.r0 + q).checked_sub(2).map_or(0, h);
        }
        for r in b.r0..b.r1 {
            near[4] = h(r + 2);
            let mut d = near.iter().fold(0, |a, &x| a | x);
            near = [near[1], near[2], near[3], near[4], 0];
            if j + 1 == wpr {
                d &= last_bits;
            }
            let v = d & !any[r * wpr + j];
            ring[r * wpr + j] = v;
            nr += v.count_ones();
        }
    }
    nr
}

/// Per-tick spike sums of region and ring over the n_max span into `pt`,
/// over the (row, word) cells where either has a pixel: a bounded batch
/// of cells at a time on the stack, every tick of the span per batch.
#[inline(always)]
fn tick_sums<const HALF: bool>(
    span: &Span<'_>,
    w: (&impl Fn(&[u64], u32, &Cell) -> u64, bool),
    (regm, ring): (&[u64], &[u64]),
    b: &Bounds,
    cell_at: &impl Fn(usize, usize) -> Cell,
    pt: &mut [Tick; 256],
) {
    // Cells with region pixels, and cells of ring pixels only (the rows
    // above and below a region: one popcount per tick instead of two).
    // Not initialised until pushed: zeroing both arrays would cost more
    // than the sums of a small frame.
    let mut cells = heapless::Vec::<Cell, CELLS>::new();
    let mut rings = heapless::Vec::<Cell, CELLS>::new();
    for r in b.r0..b.r1 {
        for j in b.j0..=b.j1 {
            let rg = if b.region_row(r) {
                regm[r * b.wpr + j]
            } else {
                0
            };
            let rn = ring[r * b.wpr + j];
            if rg | rn == 0 {
                continue;
            }
            let cell = Cell {
                ring: rn,
                reg: rg,
                ..cell_at(r, j)
            };
            for cell in parts(cell, HALF).into_iter().flatten() {
                if cell.reg == 0 {
                    if rings.push(cell).is_err() {
                        sum_all::<true, HALF>(span, w, &mut rings, pt);
                        rings.clear();
                        rings.push(cell).ok();
                    }
                } else if cells.push(cell).is_err() {
                    sum_all::<false, HALF>(span, w, &mut cells, pt);
                    cells.clear();
                    cells.push(cell).ok();
                }
            }
        }
    }
    sum_all::<false, HALF>(span, w, &mut cells, pt);
    sum_all::<true, HALF>(span, w, &mut rings, pt);
}

/// Each region pixel's count over n*'s window `win` into `c_t`:
/// bit-sliced counters per word of the region (`regm`), read back for its
/// pixels. Returns the largest.
///
/// Plain counts: the segmentation left every pixel's count over the
/// whole span in its counters (`counts`; its last window is n_max's), so
/// where n*'s window is the longer part of the span, a pixel's count is
/// that minus its spikes outside the window (fewer ticks to add).
#[inline(always)]
fn pixel_counts(
    ctx: &crate::context::Ctx<'_, '_>,
    (counts, c_t): (&[u64], &mut [u8]),
    regm: &[u64],
    b: &Bounds,
    win: Window,
    (word, cell_at): (
        &impl Fn(&[u64], u32, &Cell) -> u64,
        &impl Fn(usize, usize) -> Cell,
    ),
) -> u8 {
    let (span, p) = (ctx.span, ctx.p);
    let (width, wpr) = (b.width, b.wpr);
    let planes = span.planes();
    let wplanes = span.range(win.start, win.end());
    let t0 = win.start.max(span.start);
    let lo = (win.start.saturating_sub(span.start) as usize).min(planes.len());
    let hi = (lo + wplanes.len()).min(planes.len());
    let whole = ctx.motion.is_none()
        && ctx.levels.iter().rev().find(|&&n| n != 0) == Some(&p.n_max)
        && planes.len() - wplanes.len() < wplanes.len();
    let outside = |i: usize| if i < lo { i } else { i + (hi - lo) };
    let mut max_count = 0u8;
    for r in b.rr.0..b.rr.1 {
        for j in b.j0..=b.j1 {
            let mut m = regm[r * wpr + j];
            if m == 0 {
                continue;
            }
            let cell = cell_at(r, j);
            let mut cnt = Counter::default();
            let all = if whole {
                slices::add_fn(&mut cnt, planes.len() - wplanes.len(), |i| {
                    let i = outside(i);
                    planes
                        .get(i)
                        .map_or(0, |plane| word(plane, span.start + i as u32, &cell))
                });
                counts
                    .get(8 * (r * wpr + j)..8 * (r * wpr + j) + 8)
                    .and_then(|c| <&Counter>::try_from(c).ok())
            } else {
                slices::add_fn(&mut cnt, wplanes.len(), |i| {
                    wplanes
                        .get(i)
                        .map_or(0, |plane| word(plane, t0 + i as u32, &cell))
                });
                None
            };
            // A byte group's counts at a time, read out of the planes once.
            let mut group = (u32::MAX, [0u8; 8]);
            while m != 0 {
                let bit = m.trailing_zeros();
                m &= m - 1;
                if group.0 != bit / 8 {
                    let g = bit / 8;
                    let mut v = slices::bytes8(&cnt, g);
                    if let Some(all) = all {
                        let a = slices::bytes8(all, g);
                        for (v, a) in v.iter_mut().zip(a) {
                            *v = a.saturating_sub(*v);
                        }
                    }
                    group = (g, v);
                }
                let v = group.1[(bit % 8) as usize];
                if let Some(x) = c_t.get_mut(r * width + j * 64 + bit as usize) {
                    *x = v;
                }
                max_count = max_count.max(v);
            }
        }
    }
    max_count
}

/// n* of a region of `np` pixels with a ring of `nr`, given `sums(n)` =
/// its region and ring spike sums over the centred window of `n` ticks:
/// the SNR's maximum over the doubling windows 1, 2, 4, …, `n_max`, then
/// over every integer of `[n/2, 2n]` around the best; the smallest on a
/// tie.
fn search(sums: &impl Fn(u16) -> (u64, u64), n_max: u16, np: u32, nr: u32, p: &Params) -> u16 {
    let scored = |n: u16| {
        let (s, bsum) = sums(n);
        Scored::new(s, bsum, np, nr, p)
    };
    let better = |a: &Scored, b: &Scored| a.greater(b, np, nr, p);
    // Coarse search over doubling windows, then every integer around the best.
    let mut best_n = 1u16;
    let mut best = scored(1);
    let mut n = 1u16;
    while n < n_max {
        n = n.saturating_mul(2).min(n_max);
        let t = scored(n);
        if better(&t, &best) {
            best = t;
            best_n = n;
        }
    }
    let lo = (best_n / 2).max(1);
    let hi = best_n.saturating_mul(2).min(n_max);
    // Every integer of [lo, hi] in order, the first maximum kept, except
    // runs of windows that cannot reach the best scored so far: over a run
    // [m0, m1] the sums grow with the window (windows are nested), so no
    // window of it has more contrast than S(m1)·N_r − B(m0)·N_p nor less
    // variance than at B(m0). A run whose bound is below a score already
    // seen (so below the maximum) holds no maximum and is not scored; a
    // run that may is halved, left half first, down to pairs.
    let mut star = best_n;
    let mut star_t: Option<Scored> = None;
    let mut thr = best;
    let mut runs = [(0u16, 0u16); 16];
    runs[0] = (lo, hi);
    let mut depth = 1;
    while depth > 0 {
        depth -= 1;
        let (m0, m1) = runs[depth];
        if m1 - m0 >= 2 {
            // A run holding the coarse best cannot be below it.
            if !(m0..=m1).contains(&best_n) {
                let (s1, _) = sums(m1);
                let (_, b0) = sums(m0);
                if thr.bounds_above(s1, b0, np, nr, p) {
                    continue;
                }
            }
            if depth + 2 <= runs.len() {
                let mid = m0 + (m1 - m0) / 2;
                runs[depth] = (mid + 1, m1);
                runs[depth + 1] = (m0, mid);
                depth += 2;
                continue;
            }
        }
        for m in m0..=m1 {
            let t = scored(m);
            if star_t.as_ref().is_none_or(|s| better(&t, s)) {
                star_t = Some(t);
                star = m;
                if better(&t, &thr) {
                    thr = t;
                }
            }
        }
    }
    star
}

/// Output gray of a region pixel with count `c` over n*: linear in `c`, the
/// ring mean going to FS/β and the region maximum to FS, rounded, clamped to
/// `[0, FS]`. Evaluated exactly: with `x = (c − B)/(c_max − B)`,
/// `gray = FS·(1 − x)/β + FS·x`. A region no brighter than its ring gives FS/β.
pub fn region_gray(c: u8, reg: &Region, p: &Params, full_scale: u16) -> u16 {
    let nr = i128::from(reg.ring_pixels.max(1));
    let bsum = i128::from(reg.ring_sum);
    let num = i128::from(c) * nr - bsum;
    let den = i128::from(reg.max_count) * nr - bsum;
    let fs = i128::from(full_scale);
    let bq = i128::from(p.beta.to_bits().max(1));
    let (n, d) = if den <= 0 {
        (fs * 256, bq)
    } else {
        (fs * (256 * (den - num) + num * bq), bq * den)
    };
    let v = (2 * n + d).div_euclid(2 * d);
    v.clamp(0, fs) as u16
}

/// [`region_gray`] of every count `0..=reg.max_count` into `out` (the
/// rest untouched). Over one region the rounded value is
/// `⌊(A + B·c)/D⌋` with integers `A`, `B`, `D > 0`, so it is stepped from
/// count to count with a running remainder: one 128-bit division per
/// region instead of one per pixel (a library call of hundreds of
/// instructions on a Cortex-M4). The same values.
pub fn region_table(reg: &Region, p: &Params, full_scale: u16, out: &mut [u16; 256]) {
    let nr = i128::from(reg.ring_pixels.max(1));
    let bsum = i128::from(reg.ring_sum);
    let den = i128::from(reg.max_count) * nr - bsum;
    let fs = i128::from(full_scale);
    let bq = i128::from(p.beta.to_bits().max(1));
    let last = usize::from(reg.max_count);
    if den <= 0 {
        out[..=last].fill(region_gray(0, reg, p, full_scale));
        return;
    }
    // 2n + d with n = fs·(256·(den − num) + num·bq), num = c·nr − bsum:
    // A + B·c over D = 2·bq·den.
    let d = 2 * bq * den;
    let b = 2 * fs * nr * (bq - 256);
    let a = 2 * fs * (256 * den - (bq - 256) * bsum) + bq * den;
    let (q, r) = (b.div_euclid(d), b.rem_euclid(d));
    let (mut v, mut rem) = (a.div_euclid(d), a.rem_euclid(d));
    for o in out.iter_mut().take(last + 1) {
        *o = v.clamp(0, fs) as u16;
        v += q;
        rem += r;
        if rem >= d {
            v += 1;
            rem -= d;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::History;

    /// The search as docs/spec.md §5 reads it: every doubling window, then every
    /// integer of [n/2, 2n] in order, by the exact comparison alone.
    fn search_every(
        sums: &impl Fn(u16) -> (u64, u64),
        n_max: u16,
        np: u32,
        nr: u32,
        p: &Params,
    ) -> u16 {
        let snr = |n: u16| {
            let (s, b) = sums(n);
            snr_terms(s, b, np, nr, p)
        };
        let (mut best_n, mut n) = (1u16, 1u16);
        while n < n_max {
            n = n.saturating_mul(2).min(n_max);
            if cmp_snr(&snr(n), &snr(best_n)) == Ordering::Greater {
                best_n = n;
            }
        }
        let (lo, hi) = ((best_n / 2).max(1), best_n.saturating_mul(2).min(n_max));
        let mut star = lo;
        for m in lo + 1..=hi {
            if cmp_snr(&snr(m), &snr(star)) == Ordering::Greater {
                star = m;
            }
        }
        star
    }

    /// The pruned search finds the exhaustive one's n*, ties included:
    /// random nested windows (per-tick sums, dense, sparse and flat, so
    /// that exact ties are common), region and ring sizes, and noise
    /// parameters.
    #[test]
    fn pruned_search_finds_every_windows_maximum() {
        let mut rnd = crate::testing::rng(0x2545_f491_4f6c_dd1du64);
        let params = [
            Params::default(),
            Params {
                sigma_fpn: crate::q::Sigma::from_bits(u16::MAX),
                electrons_per_spike: 1,
                ..Params::default()
            },
        ];
        let cases = std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|v| v.parse::<u32>().ok())
            .unwrap_or(256)
            .max(64)
            * 16;
        for i in 0..cases {
            let p = &params[(i % 2) as usize];
            let n_max = [128u16, 255, 64, 1, 2, 3, 100][(i / 2 % 7) as usize];
            let np = 1 + rnd(40) as u32;
            let nr = rnd(120) as u32;
            // Per-tick spikes of region and ring over the n_max span:
            // a particle passing (a bump), a steady background, or nothing.
            let centre = rnd(u64::from(n_max)) as i64;
            let width = 1 + rnd(40) as i64;
            let (amp, bg) = (rnd(8 * u64::from(np)), rnd(3 * u64::from(nr) + 1));
            let kind = rnd(4);
            let mut ps = [0u64; 257];
            let mut pb = [0u64; 257];
            for t in 0..usize::from(n_max) {
                let inside = (t as i64 - centre).abs() < width;
                let (s, b) = match kind {
                    0 => (0, 0),
                    1 => (u64::from(inside) * amp, bg),
                    2 => (rnd(2), rnd(2)),
                    _ => (
                        u64::from(inside) * amp + rnd(np.into()),
                        bg + rnd(nr.into()),
                    ),
                };
                ps[t + 1] = ps[t] + s;
                pb[t + 1] = pb[t] + b;
            }
            let k = u32::from(n_max / 2);
            let sums = |n: u16| {
                let a = (k - u32::from(n / 2)) as usize;
                let e = (a + usize::from(n)).min(usize::from(n_max));
                (ps[e] - ps[a], pb[e] - pb[a])
            };
            assert_eq!(
                search(&sums, n_max, np, nr, p),
                search_every(&sums, n_max, np, nr, p),
                "case {i}: n_max {n_max} np {np} nr {nr} kind {kind}"
            );
        }
    }

    #[test]
    fn wide_multiply() {
        assert_eq!(mul_wide(u128::MAX, 2), (1, u128::MAX - 1));
        assert_eq!(mul_wide(1 << 100, 1 << 100), (1 << 72, 0));
        assert_eq!(mul_wide(12345, 678), (0, 12345 * 678));
    }

    #[test]
    fn snr_order_matches_f64() {
        let p = Params::default();
        let snr = |s: u64, b: u64, np: u32, nr: u32| {
            let (s, b) = (s as f64 / np as f64, b as f64 / nr.max(1) as f64);
            let sig = p.sigma_fpn.to_num::<f64>();
            (s - b) / (0.25 + (sig * b).powi(2) + b / 1000.0).sqrt()
        };
        let cases = [
            (40, 30, 20, 40),
            (80, 100, 20, 40),
            (10, 90, 20, 40),
            (0, 0, 20, 0),
            (5, 0, 3, 0),
            (200, 380, 20, 40),
        ];
        for a in cases {
            for b in cases {
                if (a.2, a.3) != (b.2, b.3) {
                    continue;
                }
                let ta = snr_terms(a.0, a.1, a.2, a.3, &p);
                let tb = snr_terms(b.0, b.1, b.2, b.3, &p);
                let fa = snr(a.0, a.1, a.2, a.3);
                let fb = snr(b.0, b.1, b.2, b.3);
                assert_eq!(
                    cmp_snr(&ta, &tb),
                    fa.partial_cmp(&fb).unwrap(),
                    "{a:?} {b:?}"
                );
            }
        }
    }

    #[test]
    fn region_tables_equal_the_formula() {
        let mut t = [0u16; 256];
        let mut rnd = crate::testing::rng(12345u64);
        for i in 0..20_000 {
            let p = Params {
                beta: crate::q::Beta::from_bits(
                    1 + rnd(if i % 2 == 0 { 4000 } else { 65535 }) as u16,
                ),
                ..Params::default()
            };
            let reg = Region {
                ring_pixels: rnd(3000) as u32,
                ring_sum: rnd(300_000) as u32,
                max_count: rnd(256) as u8,
                ..Region::default()
            };
            let fs = [1u16, 255, 4095, 65535][i % 4];
            region_table(&reg, &p, fs, &mut t);
            for c in 0..=reg.max_count {
                assert_eq!(
                    t[usize::from(c)],
                    region_gray(c, &reg, &p, fs),
                    "{reg:?} {c}"
                );
            }
        }
    }

    /// The f32 shortcut orders windows exactly as the 256-bit comparison:
    /// random sums over the whole ranges, near ties (sums one apart) and
    /// extreme parameters.
    #[test]
    fn scored_windows_order_exactly() {
        let mut rnd = crate::testing::rng(0x9e37_79b9_7f4a_7c15u64);
        let params = [
            Params::default(),
            Params {
                sigma_fpn: crate::q::Sigma::from_bits(u16::MAX),
                electrons_per_spike: u16::MAX,
                ..Params::default()
            },
            Params {
                sigma_fpn: crate::q::Sigma::from_bits(0),
                electrons_per_spike: 1,
                ..Params::default()
            },
        ];
        for i in 0..200_000u32 {
            let p = &params[(i % 3) as usize];
            let scale = [30u64, 3_000, 300_000, 1 << 40][(i / 3 % 4) as usize];
            let np = 1 + rnd(if scale > 1000 { 65_535 } else { 60 }) as u32;
            let nr = rnd(if scale > 1000 { 1 << 20 } else { 200 }) as u32;
            let (s1, b1) = (rnd(scale), rnd(scale));
            let (s2, b2) = if i % 2 == 0 {
                (s1 + rnd(3), b1 + rnd(3))
            } else {
                (rnd(scale), rnd(scale))
            };
            let a = Scored::new(s1, b1, np, nr, p);
            let b = Scored::new(s2, b2, np, nr, p);
            let exact = cmp_snr(&snr_terms(s1, b1, np, nr, p), &snr_terms(s2, b2, np, nr, p));
            assert_eq!(
                a.greater(&b, np, nr, p),
                exact == Ordering::Greater,
                "{s1} {b1} vs {s2} {b2}, np {np} nr {nr}"
            );
        }
    }

    /// A window whose variance is past the approximation's range (no
    /// `f32` score) against one within it: ordered exactly, both ways,
    /// not by the one score there is.
    #[test]
    fn windows_without_approximation_order_exactly() {
        let p = Params {
            sigma_fpn: crate::q::Sigma::from_bits(u16::MAX),
            electrons_per_spike: u16::MAX,
            ..Params::default()
        };
        let (np, nr) = (1, 1);
        // (s, b): a small negative SNR, a huge ring sum (v ≈ 2^140),
        // a positive one and a zero one.
        let windows = [
            (0u64, 1u64),
            (0, 1 << 45),
            (5, 1),
            (3, 3),
            (1 << 44, 1 << 45),
        ];
        for &(s1, b1) in &windows {
            for &(s2, b2) in &windows {
                let a = Scored::new(s1, b1, np, nr, &p);
                let b = Scored::new(s2, b2, np, nr, &p);
                let exact = cmp_snr(
                    &snr_terms(s1, b1, np, nr, &p),
                    &snr_terms(s2, b2, np, nr, &p),
                );
                assert_eq!(
                    a.greater(&b, np, nr, &p),
                    exact == Ordering::Greater,
                    "{s1} {b1} vs {s2} {b2}"
                );
            }
        }
        assert!(Scored::new(0, 1 << 45, np, nr, &p).approx.is_nan());
        assert!(Scored::new(0, 1, np, nr, &p).approx.is_finite());
    }

    #[test]
    fn region_gray_maps_ring_to_fs_over_beta_and_max_to_fs() {
        let p = Params::default();
        let reg = Region {
            ring_pixels: 10,
            ring_sum: 20,
            max_count: 12,
            ..Region::default()
        };
        assert_eq!(region_gray(12, &reg, &p, 255), 255);
        assert_eq!(region_gray(2, &reg, &p, 255), 26); // 25.5 rounds up
        assert_eq!(region_gray(0, &reg, &p, 255), 0); // below the ring: clamped
        assert_eq!(region_gray(7, &reg, &p, 255), 140); // 25.5 + 0.5·229.5 = 140.25
        let flat = Region {
            ring_pixels: 10,
            ring_sum: 50,
            max_count: 4,
            ..Region::default()
        };
        assert_eq!(region_gray(4, &flat, &p, 255), 26);
    }

    /// Up to 40 cells `spread` words apart at most over `words` words,
    /// each with a ring and a region mask: narrow masks (a byte's span
    /// anywhere, across the halves' boundary too) as often as wide ones.
    fn random_cells(
        rnd: &mut impl FnMut(u64) -> u64,
        words: usize,
        spread: u64,
    ) -> std::vec::Vec<Cell> {
        let n = 1 + rnd(40) as usize;
        let mask = |rnd: &mut dyn FnMut(u64) -> u64, sh: u32| match rnd(6) {
            0 => 0,
            1 => rnd(u64::MAX) & 0xffff_ffff,
            2 => rnd(u64::MAX) << 32,
            3 => rnd(u64::MAX) ^ rnd(u64::MAX) << 21,
            _ => rnd(256) << sh,
        };
        let mut at = rnd(words as u64 - spread.min(40)) as usize;
        (0..n)
            .map(|_| {
                at = (at + rnd(spread / 4 + 1) as usize) % words;
                let sh = rnd(57) as u32;
                let ring = mask(rnd, sh);
                Cell {
                    at,
                    ring,
                    reg: mask(rnd, sh) & !ring,
                    ..Cell::default()
                }
            })
            .collect()
    }

    /// The region and ring sums of `cells` per plane (plane `i` at
    /// `i + 1`), pixel by pixel.
    fn pixel_sums(planes: &[std::vec::Vec<u64>], cells: &[Cell]) -> ([u32; 256], [u32; 256]) {
        let (mut es, mut eb) = ([0u32; 256], [0u32; 256]);
        for (i, plane) in planes.iter().enumerate() {
            for c in cells {
                for bit in 0..64 {
                    if (plane[c.at] >> bit) & 1 == 1 {
                        es[i + 1] += u32::from((c.reg >> bit) & 1 == 1);
                        eb[i + 1] += u32::from((c.ring >> bit) & 1 == 1);
                    }
                }
            }
        }
        (es, eb)
    }

    /// The per-tick sums over whole words and over their `u32` halves
    /// (the 32-bit targets' cells, [`parts`], narrow ones included) both
    /// equal a pixel-by-pixel count: random planes (sparse and dense),
    /// random cells near each other and far apart (the windowed and the
    /// per-cell reads), masks in one half, the other or both, narrow or
    /// wide, every batch size.
    #[test]
    fn halves_and_words_sum_like_pixels() {
        let mut rnd = crate::testing::rng(0x9e37_79b9_7f4a_7c15);
        let words = 400;
        let mut narrow = 0;
        for case in 0..64u64 {
            let ticks = 1 + rnd(40) as usize;
            let density = 1 + rnd(8);
            let planes: std::vec::Vec<std::vec::Vec<u64>> = (0..ticks)
                .map(|_| {
                    (0..words)
                        .map(|_| {
                            (0..density)
                                .fold(u64::MAX, |a, _| a & (rnd(u64::MAX) | rnd(u64::MAX) << 32))
                        })
                        .collect()
                })
                .collect();
            let refs: std::vec::Vec<&[u64]> = planes.iter().map(|p| p.as_slice()).collect();
            // The planes also in a history's ring (512 x 50 px, 400 words
            // a plane) of their number's depth, after `extra` empty ones
            // so that the ring wraps.
            let extra = rnd(ticks as u64) as usize;
            let (wd, ht, depth) = (512u16, 50u16, ticks as u16);
            let mut hbuf = std::vec![0u64; History::words_needed(wd, ht, depth).unwrap()];
            let mut hist = History::new(&mut hbuf, wd, ht, 0, ht, depth).unwrap();
            let empty = std::vec![0u64; words];
            for p in std::iter::repeat_n(&empty, extra).chain(&planes) {
                let bytes: std::vec::Vec<u8> = p.iter().flat_map(|w| w.to_le_bytes()).collect();
                hist.push(&crate::plane::PlaneView::new(&bytes, wd, ht).unwrap())
                    .unwrap();
            }
            let held = Window {
                start: extra as u32,
                len: depth,
                nominal: depth,
            };
            assert_eq!(Span::new(&hist, held).planes(), &refs[..]);
            let spread = if case % 2 == 0 { 40 } else { words as u64 };
            let cells = random_cells(&mut rnd, words, spread);
            let (es, eb) = pixel_sums(&planes, &cells);
            let word = |plane: &[u64], _t: u32, c: &Cell| plane.get(c.at).copied().unwrap_or(0);
            for half in [false, true] {
                let parts: std::vec::Vec<Cell> = cells
                    .iter()
                    .flat_map(|&c| parts(c, half))
                    .flatten()
                    .collect();
                if half {
                    narrow += parts.iter().filter(|c| c.narrow).count();
                }
                let (mut regs, mut rings): (std::vec::Vec<Cell>, std::vec::Vec<Cell>) =
                    parts.iter().partition(|c| c.reg != 0);
                let w = (&word, true);
                // The planes as slices, and as a history's ring (runs of
                // slots, wrapping where `extra` planes came first).
                for span in [Span::from_planes(0, &refs), Span::new(&hist, held)] {
                    let mut pt = [Tick::default(); 256];
                    if half {
                        sum_all::<false, true>(&span, w, &mut regs, &mut pt);
                        sum_all::<true, true>(&span, w, &mut rings, &mut pt);
                    } else {
                        sum_all::<false, false>(&span, w, &mut regs, &mut pt);
                        sum_all::<true, false>(&span, w, &mut rings, &mut pt);
                    }
                    let kind = if span.runs().stride > 0 {
                        "runs"
                    } else {
                        "slices"
                    };
                    let ps = pt.map(|x| tick_split(x).0);
                    let pb = pt.map(|x| tick_split(x).1);
                    assert_eq!((ps, pb), (es, eb), "case {case}, halves {half}, {kind}");
                }
            }
        }
        // The halves took the narrow path often.
        assert!(narrow > 300, "{narrow}");
    }
}
