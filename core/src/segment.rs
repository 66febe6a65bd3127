//! Saturation time `t_bgmax` and iterative particle/background segmentation
//! (paper section 2.2; docs/spec.md §5).
//!
//! Starting at n = n0 and doubling up to n_max, for every pixel still
//! *active* (neither particle nor saturated):
//! 1. `b` = robust local background: the lower median of the non-particle
//!    counts of each 16×16 tile, interpolated bilinearly between tile
//!    centres (exact, in 1/1024 counts);
//! 2. particle when `c > b` and `(c − b)² > k_sig²·var(b)`, with the count
//!    noise of an integrate-and-fire pixel `var(b) = 1/4 + (σ_fpn·b)² + b/g`
//!    (of the `S` pixels a motion-compensated count sums:
//!    [`crate::particle::is_particle_compensated`]);
//! 3. otherwise saturated when `c_n ≥ N_fs` (over a clipped window: when the
//!    rate reaches `N_fs/n`); its saturation time `t_bgmax` is n.
//!
//! Pixels still active after n_max are background with `t_bgmax = n_max`.
//! Memory: the workspace's per-pixel bytes; one 512-byte histogram on the stack.

use crate::history::History;
use crate::motion::{add_compensated, positions, travel, Motion, MIN_TRAVEL};
use crate::params::Params;
use crate::particle::{is_particle_compensated, Thresholds};
use crate::q::B_FRAC_BITS;
use crate::slices::{self, low_bits, Counter};
use crate::state::Workspace;
use crate::window::{add_counts, Window};

/// Side of the square tiles whose background medians the particle test
/// blends, px. The bit-sliced medians ([`tile_medians_sliced`]) read a
/// tile row as the 16-bit lanes of 64-px words, and tile geometry is
/// computed in 1/32-tile units (`tile_pos`, [`padded_tile`]): both hold
/// for 16 px only.
pub(crate) const TILE: usize = 16;

/// Tile columns a row can have: a row is at most 65535 px.
const MAX_TILE_COLUMNS: usize = 65536 / TILE;

/// What a pixel is, stored in the high bits of its class byte; the low 4 bits
/// hold the index of the level (window) at which it was decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Class {
    /// Not decided yet.
    Active,
    /// Particle pixel, found at the level in the low bits.
    Particle,
    /// Background: saturated at the level in the low bits, or never (last level).
    Background,
}

const KIND_SHIFT: u32 = 4;
pub(crate) const LEVEL_MASK: u8 = 0x0f;

/// Encodes a class byte.
#[inline]
pub fn encode(class: Class, level: u8) -> u8 {
    let kind = match class {
        Class::Active => 0,
        Class::Particle => 1,
        Class::Background => 2,
    };
    (kind << KIND_SHIFT) | (level & LEVEL_MASK)
}

/// Decodes a class byte into its class and level index.
#[inline]
pub fn decode(b: u8) -> (Class, u8) {
    let class = match b >> KIND_SHIFT {
        0 => Class::Active,
        1 => Class::Particle,
        _ => Class::Background,
    };
    (class, b & LEVEL_MASK)
}

/// Counts of one segmentation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SegmentStats {
    /// Pixels found to be particle.
    pub particle_pixels: u32,
    /// Pixels saturated before n_max.
    pub saturated_pixels: u32,
}

/// Saturation: `c` spikes over `len` of `n` ticks reach `N_fs` spikes per n.
#[inline]
pub fn is_saturated(c: u8, win: &Window, n_fs: u16) -> bool {
    win.len > 0 && u32::from(c) * u32::from(win.nominal) >= u32::from(n_fs) * u32::from(win.len)
}

/// The saturation time of one pixel (band row `row`, column `col`) by its
/// own spikes: the first level whose window count reaches `N_fs` (rate-scaled
/// when clipped), else the last. Returns `(count, t_bgmax, window length)`,
/// the inputs of [`crate::suppress::background_gray`].
///
/// For particle pixels that no region took (noise regions under 3 px,
/// regions past a full table, pixels past a full label table): their
/// segmentation stopped at detection, so they never got a `t_bgmax`; shown
/// with their detection window they would be dark pits in a suppressed
/// background. They are background, so they are suppressed like it. Cost:
/// one word read per tick of the deciding window (at most n_max), paid only
/// for such pixels, and with `known` only for the ticks past the level the
/// segmentation stopped at; none when `at_last` shows that no level can
/// saturate.
///
/// `known`: the pixel's level index and its plain count over that level's
/// window, when the segmentation decided it there on plain counts (it was
/// then not saturated at any earlier level), so the search starts there.
/// `at_last`: its plain count over the last level's window (the
/// segmentation's counters end there for every pixel). Windows are nested,
/// so that count bounds every level's; when no level from the first one
/// searched could reach `N_fs` with it, the answer is the last level at
/// that count, without reading a tick (on the default scene, every such
/// pixel).
pub(crate) fn pixel_saturation(
    ctx: &crate::context::Ctx<'_, '_>,
    levels: &[u16],
    row: u16,
    col: u16,
    known: Option<(usize, u8)>,
    at_last: u8,
) -> (u8, u16, u16) {
    let (hist, span, p) = (ctx.hist, ctx.span, ctx.p);
    let from = known.map_or(0, |(j, _)| j);
    if let Some(&n_last) = levels.last() {
        let searched = levels.get(from..).unwrap_or_default();
        let can_saturate = searched
            .iter()
            .any(|&n| is_saturated(at_last, &Window::in_history(hist, ctx.k, n), p.n_fs));
        if !can_saturate {
            let len = Window::in_history(hist, ctx.k, n_last).len;
            return (at_last, n_last, len);
        }
    }
    let word = usize::from(row) * hist.words_per_row() + usize::from(col) / 64;
    let shift = col % 64;
    let bits = |a: u32, e: u32| -> u8 {
        let n = span
            .range(a, e)
            .iter()
            .filter(|pl| pl.get(word).is_some_and(|w| (w >> shift) & 1 == 1))
            .count();
        n.min(255) as u8
    };
    // Windows are nested: each level adds the ticks its window has beyond
    // the previous one (as `saturation_times` counts).
    let mut last = (0u8, p.n_max, 0u16);
    let mut prev: Option<Window> = None;
    for &n in levels.iter().skip(from) {
        let win = Window::in_history(hist, ctx.k, n);
        let c = match (prev, known) {
            (None, Some((_, c))) => c,
            (None, None) => bits(win.start, win.end()),
            (Some(pw), _) => last
                .0
                .saturating_add(bits(win.start, pw.start))
                .saturating_add(bits(pw.end(), win.end())),
        };
        last = (c, n, win.len);
        prev = Some(win);
        if is_saturated(c, &win, p.n_fs) {
            break;
        }
    }
    last
}

/// Tile geometry of a strip: tiles are 16×16 and aligned to band row 0.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Tiles {
    pub x: usize,
    pub y0: usize,
    pub y1: usize,
}

impl Tiles {
    pub(crate) fn for_strip(width: u16, s0: u16, s1: u16) -> Tiles {
        Tiles {
            x: usize::from(width).div_ceil(TILE),
            y0: usize::from(s0) / TILE,
            y1: usize::from(s1.saturating_sub(1)) / TILE,
        }
    }
}

/// Lower median of the non-particle counts (`part` clear) of each tile of
/// tile row `ty` (of all counts where a tile has only particle pixels),
/// from byte counts: the motion-compensated ones.
fn tile_medians_bytes(
    counts: &[u8],
    part: &[u64],
    tiles_out: &mut [u8],
    (width, wpr): (usize, usize),
    s0: u16,
    (r_lo, r_hi): (usize, usize),
) {
    for (tx, out) in tiles_out.iter_mut().enumerate() {
        let c_lo = tx * TILE;
        let c_hi = (tx * TILE + TILE).min(width);
        let mut hist = [0u16; 256];
        let mut n = 0u32;
        for r in r_lo..r_hi {
            let sr = r - usize::from(s0);
            let base = sr * width;
            for c in c_lo..c_hi {
                if (part[sr * wpr + c / 64] >> (c % 64)) & 1 == 0 {
                    hist[usize::from(counts[base + c])] += 1;
                    n += 1;
                }
            }
        }
        if n == 0 {
            // A tile of particle pixels only: the median of all its counts.
            for r in r_lo..r_hi {
                let base = (r - usize::from(s0)) * width;
                for &c in &counts[base + c_lo..base + c_hi] {
                    hist[usize::from(c)] += 1;
                    n += 1;
                }
            }
        }
        let rank = n.saturating_sub(1) / 2;
        let mut seen = 0u32;
        for (v, &cnt) in hist.iter().enumerate() {
            seen += u32::from(cnt);
            if seen > rank {
                *out = v as u8;
                break;
            }
        }
    }
}

/// The same medians from the bit-sliced plain counts: four tiles (the
/// 16-bit lanes of a 64-px word) at once, by radix selection from the top
/// bit down — per bit, the lanes' candidates with that bit set are
/// counted and each lane keeps the half that holds its rank. Only the
/// `live` low planes can be set ([`slices::live_planes`]).
fn tile_medians_sliced(
    counts: &[u64],
    live: usize,
    part: &[u64],
    tiles_out: &mut [u8],
    (width, wpr): (usize, usize),
    s0: u16,
    (r_lo, r_hi): (usize, usize),
) {
    let lane = |x: u64, q: usize| ((x >> (16 * q)) & 0xffff).count_ones();
    // Set bits of each 16-bit lane over rows: byte-wise population counts
    // summed over the rows (at most 16 rows of 8 per byte), then byte
    // pairs added — a few operations per row for all four lanes.
    let lanes = |xs: &[u64; 16]| -> [u32; 4] {
        let acc = byte_counts(xs);
        let acc = (acc & 0x00ff_00ff_00ff_00ff) + ((acc >> 8) & 0x00ff_00ff_00ff_00ff);
        core::array::from_fn(|q| ((acc >> (16 * q)) & 0xffff) as u32)
    };
    let nr = r_hi - r_lo;
    for j in 0..wpr {
        let valid = low_bits(width - 64 * j);
        // Rows past `nr` stay zero throughout (no candidates, no bits), so
        // every row loop below runs all 16 without bounds (vectorised);
        // the rows' bit planes are copied side by side first (read in
        // place, strided, with a bounds check per row and bit, they took
        // half the medians' time).
        let mut cand = [0u64; 16];
        let mut planes = [[0u64; 16]; 8];
        let mut n = [0u32; 4];
        for (k, cw) in cand.iter_mut().enumerate().take(nr) {
            let sr = r_lo + k - usize::from(s0);
            *cw = !part[sr * wpr + j] & valid;
            let at = (sr * wpr + j) * 8;
            if let Some(c) = counts.get(at..at + 8) {
                for (pl, &cb) in planes.iter_mut().zip(c) {
                    pl[k] = cb;
                }
            }
        }
        for (nq, c) in n.iter_mut().zip(lanes(&cand)) {
            *nq += c;
        }
        // A lane of particle pixels only: all its pixels.
        let mut refill = 0u64;
        for (q, nq) in n.iter_mut().enumerate() {
            if *nq == 0 {
                refill |= 0xffff << (16 * q);
                *nq = lane(valid, q) * nr as u32;
            }
        }
        if refill != 0 {
            for cw in cand.iter_mut().take(nr) {
                *cw |= valid & refill;
            }
        }
        let mut rank = n.map(|x| x.saturating_sub(1) / 2);
        let mut left = n;
        let mut med = [0u8; 4];
        for b in (0..live.min(8)).rev() {
            let x: [u64; 16] = core::array::from_fn(|k| cand[k] & planes[b][k]);
            if x.iter().fold(0, |a, &v| a | v) == 0 {
                // No candidate has this bit: every lane's median has 0.
                continue;
            }
            let ones = lanes(&x);
            let mut take1 = 0u64;
            for q in 0..4 {
                let zeros = left[q] - ones[q];
                if rank[q] < zeros {
                    left[q] = zeros;
                } else {
                    rank[q] -= zeros;
                    left[q] = ones[q];
                    med[q] |= 1 << b;
                    take1 |= 0xffff << (16 * q);
                }
            }
            for (cw, &xk) in cand.iter_mut().zip(&x) {
                // Lanes that took 1 keep the set ones, the others the clear.
                *cw = (xk & take1) | ((*cw ^ xk) & !take1);
            }
        }
        for (q, &m) in med.iter().enumerate() {
            if let Some(t) = tiles_out.get_mut(4 * j + q) {
                *t = m;
            }
        }
    }
}

/// Per byte, the set bits of that byte over the 16 words `xs` (at most
/// 128). Two words per SSE2 operation on the host: the halves' counts (at
/// most 64 each) are added at the end.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn byte_counts(xs: &[u64; 16]) -> u64 {
    use wide::u64x2;
    let k = u64x2::splat;
    let mut acc = u64x2::ZERO;
    for pair in xs.chunks_exact(2) {
        let x = u64x2::new([pair[0], pair[1]]);
        let x = x - ((x >> 1) & k(0x5555_5555_5555_5555));
        let x = (x & k(0x3333_3333_3333_3333)) + ((x >> 2) & k(0x3333_3333_3333_3333));
        acc += (x + (x >> 4)) & k(0x0f0f_0f0f_0f0f_0f0f);
    }
    let [a0, a1] = acc.to_array();
    a0 + a1
}

/// [`byte_counts`] one word at a time (no vector unit).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn byte_counts(xs: &[u64; 16]) -> u64 {
    let mut acc = 0u64;
    for &x in xs {
        let x = x - ((x >> 1) & 0x5555_5555_5555_5555);
        let x = (x & 0x3333_3333_3333_3333) + ((x >> 2) & 0x3333_3333_3333_3333);
        acc += (x + (x >> 4)) & 0x0f0f_0f0f_0f0f_0f0f;
    }
    acc
}

/// Bilinear position between tile centres: the lower tile index (clamped)
/// and the weight of the upper one in 1/32, for pixel index `i` (0-based).
#[inline]
pub(crate) fn tile_pos(i: usize, lo: usize, hi: usize) -> (usize, usize, u32) {
    // Pixel centre i + 0.5, tile centre 16·t + 8: u = (2i − 15) / 32 tiles.
    let v = 2 * i as i64 - 15;
    let t0 = v.div_euclid(32);
    let f = v.rem_euclid(32) as u32;
    let clamp = |t: i64| (t.max(lo as i64) as usize).min(hi);
    (clamp(t0), clamp(t0 + 1), f)
}

/// Adds the spikes of the planes of both `runs` (each plane the band,
/// `wpr` words per row) of band rows `s0..s0 + rows` to the bit-sliced
/// counters `counts`. The strip's rows are consecutive words of every
/// plane and their counters consecutive cells, so the planes are taken 15
/// at a time (trimmed to the strip) and summed into carry-save nibbles
/// block by block along the whole strip (`crate::slices`): one simple loop
/// over the group's planes per block, its partials in registers — the two
/// annuli a level adds share their nibbles. With `fresh` the counters
/// start from zero (their old contents are not read, so they need no
/// clearing first).
fn add_sliced<'a>(
    runs: [&[&'a [u64]]; 2],
    wpr: usize,
    s0: u16,
    rows: usize,
    counts: &mut [u64],
    mut fresh: bool,
) {
    let off = usize::from(s0) * wpr;
    let words = rows * wpr;
    let Some(counts) = counts.get_mut(..8 * words) else {
        return;
    };
    // A plane not held (or short) counts nothing where it has no words.
    let trim = |pl: &&'a [u64]| -> &'a [u64] {
        pl.get(off..)
            .map_or(&[][..], |s| s.get(..words).unwrap_or(s))
    };
    let mut planes = runs[0].iter().chain(runs[1]).map(trim);
    loop {
        let mut group: [&[u64]; 15] = [&[]; 15];
        let mut m = 0;
        for (slot, pl) in group.iter_mut().zip(planes.by_ref()) {
            *slot = pl;
            m += 1;
        }
        if m == 0 {
            if fresh {
                counts.fill(0);
            }
            return;
        }
        add_group(&group[..m], counts, fresh);
        fresh = false;
    }
}

/// Words side by side in [`add_group`]'s blocks.
#[cfg(target_arch = "x86_64")]
const BLOCK: usize = 4;

/// Adds the ≤ 15 planes of `group` (each a strip's words, or shorter) to
/// their counters `counts` (8 per word): [`BLOCK`] words at a time, two per
/// vector, so a plane costs two loads and fourteen vector operations per
/// block; the strip's last words (and short planes) one at a time.
/// `fresh`: the counters are set, not added to.
#[cfg(target_arch = "x86_64")]
fn add_group(group: &[&[u64]], counts: &mut [u64], fresh: bool) {
    use wide::u64x2;
    let blocks = counts.len() / (8 * BLOCK);
    let (full, rest) = counts.split_at_mut(blocks * 8 * BLOCK);
    for (q, out) in full.chunks_exact_mut(8 * BLOCK).enumerate() {
        let j0 = q * BLOCK;
        let (mut a, mut b) = ([u64x2::ZERO; 4], [u64x2::ZERO; 4]);
        let load = |pl: &[u64]| -> (u64x2, u64x2) {
            let [w0, w1, w2, w3] = match pl.get(j0..j0 + BLOCK) {
                Some(&[w0, w1, w2, w3]) => [w0, w1, w2, w3],
                _ => core::array::from_fn(|i| pl.get(j0 + i).copied().unwrap_or(0)),
            };
            (u64x2::new([w0, w1]), u64x2::new([w2, w3]))
        };
        // Four planes per iteration: with two, the loop-carried partials
        // were copied between registers every time round.
        let mut quads = group.chunks_exact(4);
        for q4 in quads.by_ref() {
            let (x0, x1) = load(q4[0]);
            let (y0, y1) = load(q4[1]);
            slices::csa2(&mut a, x0, y0);
            slices::csa2(&mut b, x1, y1);
            let (x0, x1) = load(q4[2]);
            let (y0, y1) = load(q4[3]);
            slices::csa2(&mut a, x0, y0);
            slices::csa2(&mut b, x1, y1);
        }
        let mut pairs = quads.remainder().chunks_exact(2);
        for pr in pairs.by_ref() {
            let (x0, x1) = load(pr[0]);
            let (y0, y1) = load(pr[1]);
            slices::csa2(&mut a, x0, y0);
            slices::csa2(&mut b, x1, y1);
        }
        if let [pl] = pairs.remainder() {
            let (x0, x1) = load(pl);
            slices::csa(&mut a, x0);
            slices::csa(&mut b, x1);
        }
        // Words 0, 1 are `a`'s lanes, 2, 3 `b`'s.
        const _: () = assert!(BLOCK == 4);
        let (lo, hi) = out.split_at_mut(16);
        flush_pair(lo, a, fresh);
        flush_pair(hi, b, fresh);
    }
    add_words(group, blocks * BLOCK, rest, fresh);
}

/// [`flush`] of two neighbouring words' counters (`c`: 16 words, the
/// first word's 8 planes then the second's) from a vector nibble whose
/// lanes are the two words: one vector full adder per plane instead of
/// two scalar ones (the flushes were two fifths of the counting).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn flush_pair(c: &mut [u64], s: [wide::u64x2; 4], fresh: bool) {
    use wide::u64x2;
    let Ok(c) = <&mut [u64; 16]>::try_from(c) else {
        return;
    };
    let put = |c: &mut [u64; 16], p: usize, v: u64x2| {
        let [x, y] = v.to_array();
        c[p] = x;
        c[8 + p] = y;
    };
    if fresh {
        for (p, &v) in s.iter().enumerate() {
            put(c, p, v);
        }
        for p in 4..8 {
            put(c, p, u64x2::ZERO);
        }
        return;
    }
    let any = (s[0] | s[1] | s[2] | s[3]).to_array();
    if any[0] | any[1] == 0 {
        return;
    }
    let mut carry = u64x2::ZERO;
    for (p, &v) in s.iter().enumerate() {
        let cb = u64x2::new([c[p], c[8 + p]]);
        let x = cb ^ v;
        put(c, p, x ^ carry);
        carry = (cb & v) | (carry & x);
    }
    for p in 4..8 {
        let k = carry.to_array();
        if k[0] | k[1] == 0 {
            break;
        }
        let cb = u64x2::new([c[p], c[8 + p]]);
        put(c, p, cb ^ carry);
        carry &= cb;
    }
}

/// Adds a carry-save nibble to a word's counter (`c`, 8 words), or sets
/// the counter to it when `fresh`.
#[inline(always)]
fn flush(c: &mut [u64], s: [u64; 4], fresh: bool) {
    if let Ok(c) = <&mut Counter>::try_from(c) {
        if fresh {
            *c = [s[0], s[1], s[2], s[3], 0, 0, 0, 0];
        } else {
            slices::add_nibble(c, s);
        }
    }
}

/// [`add_group`] in plain `u64`s, one word at a time: without a 128-bit
/// vector unit (a Cortex-M4 splits every `u64` operation in two) the
/// partials of more words than one do not stay in registers. The planes
/// are taken [`RUN`] words at a time, each run checked once as an array,
/// so a word is read without a bounds check of its own (those were a
/// third of the Cortex-M4's counting); a run some plane does not hold
/// whole is read word by word.
#[cfg(not(target_arch = "x86_64"))]
fn add_group(group: &[&[u64]], counts: &mut [u64], fresh: bool) {
    add_runs(group, counts, fresh);
}

/// [`add_group`] without a vector unit (built on every target for the
/// tests).
#[cfg(any(test, not(target_arch = "x86_64")))]
fn add_runs(group: &[&[u64]], counts: &mut [u64], fresh: bool) {
    const ZERO: [u64; RUN] = [0; RUN];
    let runs = counts.len() / (8 * RUN);
    let (full, rest) = counts.split_at_mut(runs * 8 * RUN);
    for (q, out) in full.chunks_exact_mut(8 * RUN).enumerate() {
        let j0 = q * RUN;
        let mut arrays: [&[u64; RUN]; 15] = [&ZERO; 15];
        let mut whole = true;
        for (a, pl) in arrays.iter_mut().zip(group) {
            match pl
                .get(j0..j0 + RUN)
                .and_then(|s| <&[u64; RUN]>::try_from(s).ok())
            {
                Some(x) => *a = x,
                None => whole = false,
            }
        }
        if !whole {
            add_words(group, j0, out, fresh);
            continue;
        }
        let arrays = &arrays[..group.len().min(15)];
        for (jj, c) in out.chunks_exact_mut(8).enumerate() {
            let s = slices::nibble(0..arrays.len(), |i| {
                arrays.get(i).map_or(0, |a| a[jj % RUN])
            });
            flush(c, s, fresh);
        }
    }
    add_words(group, runs * RUN, rest, fresh);
}

/// Words per run of [`add_runs`]: the cheapest of 2, 3, 4, 8 and 16 on the
/// Cortex-M4 (`firmware-sim/cost.sh`).
#[cfg(any(test, not(target_arch = "x86_64")))]
const RUN: usize = 4;

/// The planes of `group` from word `j0` on into their counters `counts`,
/// one word at a time (`fresh`: set, not added to).
#[inline(always)]
fn add_words(group: &[&[u64]], j0: usize, counts: &mut [u64], fresh: bool) {
    for (q, c) in counts.chunks_exact_mut(8).enumerate() {
        let j = j0 + q;
        let s = slices::nibble(0..group.len(), |i| {
            group.get(i).and_then(|pl| pl.get(j)).copied().unwrap_or(0)
        });
        flush(c, s, fresh);
    }
}

/// Where column `x`'s centre lies among the padded tile columns of
/// [`Level::bg`], 1/32 tile from the first pad's centre: `tile_pos` one
/// tile to the right, (2x + 17)/32.
#[inline(always)]
fn padded_tile_32(x: usize) -> usize {
    2 * x + 17
}

/// The padded tile column whose centre is at or left of column `x`'s: the
/// first of the two tiles its background blends.
#[inline(always)]
fn padded_tile(x: usize) -> usize {
    padded_tile_32(x) >> 5
}

/// One level's test of one strip row: what its pixels are tested against.
struct Level<'a> {
    /// Row background of each tile column, 1/32 count (bilinear between
    /// the row's two tile rows), padded with a copy of the first and the
    /// last column on either side (entry `t + 1` is tile column `t`), so
    /// the blend between tile centres needs no clamping at the edges.
    bg: &'a [u32],
    sat_c: u32,
    /// Bit planes the level's counts can set ([`slices::live_planes`] of
    /// the window's length): the ones above are zero and not read.
    live: usize,
    last: bool,
    /// Class bytes of a particle and a background decided at this level.
    decided: (u8, u8),
}

impl Level<'_> {
    /// The background at column `x`, 1/1024 count: linear between the two
    /// nearest tile centres of the row.
    #[inline]
    fn b_at(&self, x: usize) -> u32 {
        let v = padded_tile_32(x);
        let (t, f) = (v >> 5, (v & 31) as u32);
        // Both tiles at once, one bounds check: with the padding, t + 1 is
        // within the row for every column (a past-the-end read is 0, as
        // it was tile by tile).
        match self.bg.get(t..t + 2) {
            Some(&[a, b]) => (32 - f) * a + f * b,
            _ => (32 - f) * self.bg.get(t).copied().unwrap_or(0),
        }
    }

    /// The lowest and the highest background of the columns of word `j`
    /// (`width` px in all), 1/1024 count: the background is piecewise
    /// linear between the tile centres, so its extremes are those of the
    /// tiles it blends, and every [`Level::b_at`] of the word lies between
    /// them. `(0, u32::MAX)` if the row does not hold the word's tiles.
    #[inline]
    fn b_range(&self, j: usize, width: usize) -> (u32, u32) {
        let a = padded_tile(64 * j);
        let e = padded_tile((64 * j + 63).min(width - 1)) + 1;
        // A whole word blends tiles 4j ..= 4j + 5: a fixed six, compared
        // without a loop.
        if e == a + 5 {
            if let Some(t) = self.bg.get(a..a + 6) {
                if let Ok(&[t0, t1, t2, t3, t4, t5]) = <&[u32; 6]>::try_from(t) {
                    let lo = t0.min(t1).min(t2).min(t3).min(t4).min(t5);
                    let hi = t0.max(t1).max(t2).max(t3).max(t4).max(t5);
                    return (32 * lo, 32 * hi);
                }
            }
        }
        match self.bg.get(a..=e) {
            Some(tiles) if !tiles.is_empty() => {
                let lo = tiles.iter().copied().min().unwrap_or(0);
                let hi = tiles.iter().copied().max().unwrap_or(0);
                (32 * lo, 32 * hi)
            }
            _ => (0, u32::MAX),
        }
    }
}

/// Runs the segmentation over strip rows `s0..s1` (band rows) for a frame at
/// tick `k`. Leaves every pixel's class and `c_t` (count at its deciding
/// window); `span` holds the planes of the n_max window. With a predicted
/// motion the particle test (and the tile backgrounds it compares with)
/// runs on motion-compensated counts, kept in `ws.mc`, and saturation on
/// the plain counts; a particle's `c_t` is then its compensated count.
/// Compensated, wherever the row's motion moves anything within the
/// level's window ([`travel`] ≥ [`MIN_TRAVEL`]), a pixel's background is
/// the larger of the tile background and its own plain count: static light (glare whose gradient the 16-px
/// tiles cannot follow, a hot pixel) counts the same with and without
/// compensation, while a particle piles its spikes up only along its path
/// (on the paper's scenes this took the glare-row RMAE of `spiv bench
/// paper` from 0.280 to 0.063 on the linear profile).
///
/// Plain counts are bit-sliced ([`crate::slices`]) and undecided pixels
/// are bits of a mask (`ws.masks` plane 0; plane 1 marks particles). A
/// plain frame asks each 64-px word which undecided pixels could be
/// particle or saturated at all — a count of at least the particle
/// test's threshold at the word's lowest background, or of the
/// saturation count — and reads counts and tests exactly only those; a
/// word's pixels that cannot change stay undecided without a byte read,
/// and tile medians are computed only for the rows that have such
/// pixels. The result is the exact test's for every pixel (the host's
/// `reference_parity` tests hold the frames to the f64 reference, which
/// tests every pixel at every level).
pub(crate) fn segment(
    ctx: &crate::context::Ctx<'_, '_>,
    ws: &mut Workspace<'_>,
    s0: u16,
    s1: u16,
) -> SegmentStats {
    let crate::context::Ctx {
        hist,
        k,
        p,
        th,
        motion,
        ..
    } = *ctx;
    let g = StripGeometry::new(ws.sizes.width, s0, s1);
    let mc = motion.is_some() && ws.mc.len() >= g.px;
    let (levels, nlev) = p.levels();
    let mut stats = SegmentStats::default();
    let (act, rest) = ws.masks.split_at_mut(g.words);
    for (i, a) in act.iter_mut().enumerate() {
        *a = low_bits(g.width - 64 * (i % g.wpr));
    }
    rest[..g.words].fill(0);
    if mc {
        ws.mc[..g.px].fill(0);
    }
    // Row backgrounds per tile column (1/32 count), on the stack, with a
    // column past each end.
    let mut bg_row = [0u32; MAX_TILE_COLUMNS + 2];
    let bg_row = &mut bg_row[..g.tiles.x.min(MAX_TILE_COLUMNS) + 2];
    let mut prev: Option<Window> = None;
    for (j, &n) in levels.iter().enumerate().take(nlev) {
        let win = Window::in_history(hist, k, n);
        add_level_counts(ctx, ws, &g, (prev, win), j == 0, mc);
        prev = Some(win);
        // c ≥ sat_c ⟺ c·n ≥ N_fs·len (the rate reaches N_fs/n).
        let sat_c = if win.len == 0 {
            u32::MAX
        } else {
            (u32::from(p.n_fs) * u32::from(win.len)).div_ceil(u32::from(n))
        };
        let live = slices::live_planes(u32::from(win.len));
        let last = j + 1 == nlev;
        let decided = (
            encode(Class::Particle, j as u8),
            encode(Class::Background, j as u8),
        );
        // Tile rows whose medians this level has computed (rows ask for at
        // most two, in order).
        let mut have: [Option<usize>; 2] = [None, None];
        if mc {
            compensated_tile_medians(ws, &g);
        }
        // No particle counts below this, whatever the background.
        let t_any = sat_c.min(u32::from(th.min_count(0)));
        for r in 0..g.rows {
            let br = s0 + r as u16;
            let tp = tile_pos(usize::from(br), g.tiles.y0, g.tiles.y1);
            if !mc {
                let bg_class = (decided.1, last);
                if !plain_candidates(ws, &g, r, (t_any, live), bg_class) {
                    continue;
                }
                plain_tile_medians(ws, &g, (tp.0, tp.1), live, &mut have);
            }
            row_backgrounds(ws.tiles, &g.tiles, tp, bg_row);
            let lv = Level {
                bg: bg_row,
                sat_c,
                live,
                last,
                decided,
            };
            if let (true, Some(m)) = (mc, &motion) {
                let rm = RowMotion { m, r: br, win, k };
                words_compensated(ws, &lv, (th, p, &rm), r, &g, &mut stats);
            } else {
                words_plain(ws, &lv, (th, p), r, (g.width, g.wpr, g.words), &mut stats);
            }
        }
    }
    stats
}

/// The geometry of a strip's buffers: `rows` band rows from `s0` of
/// `width` px, `wpr` words per row, `words` and `px` in all, and its tiles.
struct StripGeometry {
    s0: u16,
    s1: u16,
    width: usize,
    wpr: usize,
    rows: usize,
    px: usize,
    words: usize,
    tiles: Tiles,
}

impl StripGeometry {
    fn new(width: u16, s0: u16, s1: u16) -> StripGeometry {
        let wpr = crate::plane::words_per_row(width);
        let rows = usize::from(s1 - s0);
        StripGeometry {
            s0,
            s1,
            width: usize::from(width),
            wpr,
            rows,
            px: usize::from(width) * rows,
            words: rows * wpr,
            tiles: Tiles::for_strip(width, s0, s1),
        }
    }

    /// Tile row `ty`: its first entry in the tile buffer and the band rows
    /// of the strip it covers.
    fn tile_rows(&self, ty: usize) -> (usize, (usize, usize)) {
        let rows = (
            (ty * TILE).max(usize::from(self.s0)),
            (ty * TILE + TILE).min(usize::from(self.s1)),
        );
        ((ty - self.tiles.y0) * self.tiles.x, rows)
    }
}

/// The tile medians of every tile row of the strip from the compensated
/// byte counts (`ws.mc`), particles left out.
#[inline(always)]
fn compensated_tile_medians(ws: &mut Workspace<'_>, g: &StripGeometry) {
    for ty in g.tiles.y0..=g.tiles.y1 {
        let (row0, rr) = g.tile_rows(ty);
        tile_medians_bytes(
            &ws.mc[..g.px],
            &ws.masks[g.words..2 * g.words],
            &mut ws.tiles[row0..row0 + g.tiles.x],
            (g.width, g.wpr),
            g.s0,
            rr,
        );
    }
}

/// The tile medians of tile rows `ty0` and `ty1` from the bit-sliced
/// plain counts (`live` planes), unless this level has them (`have`: the
/// last two computed; rows ask for them in order).
#[inline(always)]
fn plain_tile_medians(
    ws: &mut Workspace<'_>,
    g: &StripGeometry,
    (ty0, ty1): (usize, usize),
    live: usize,
    have: &mut [Option<usize>; 2],
) {
    for ty in [ty0, ty1] {
        if !have.contains(&Some(ty)) {
            let (row0, rr) = g.tile_rows(ty);
            tile_medians_sliced(
                &ws.counts[..8 * g.words],
                live,
                &ws.masks[g.words..2 * g.words],
                &mut ws.tiles[row0..row0 + g.tiles.x],
                (g.width, g.wpr),
                g.s0,
                rr,
            );
            *have = [have[1], Some(ty)];
        }
    }
}

/// Adds the ticks of level window `win` that the previous level's window
/// (nested in it) lacked to the bit-sliced plain counts (`fresh`: the
/// first level, which starts them), and, compensated (`mc`), to the
/// motion-compensated byte counts.
#[inline(always)]
fn add_level_counts(
    ctx: &crate::context::Ctx<'_, '_>,
    ws: &mut Workspace<'_>,
    g: &StripGeometry,
    (prev, win): (Option<Window>, Window),
    fresh: bool,
    mc: bool,
) {
    let (hist, span) = (ctx.hist, ctx.span);
    let added = match prev {
        None => [(win.start, win.end()), (win.end(), win.end())],
        Some(pw) => [(win.start, pw.start), (pw.end(), win.end())],
    };
    let [(a0, e0), (a1, e1)] = added;
    add_sliced(
        [span.range(a0, e0), span.range(a1, e1)],
        g.wpr,
        g.s0,
        g.rows,
        &mut ws.counts[..8 * g.words],
        fresh,
    );
    let Some(m) = ctx.motion.filter(|_| mc) else {
        return;
    };
    for (a, e) in added {
        add_compensated(
            span.range(a, e),
            a.max(span.start),
            ctx.k,
            hist.width(),
            hist.rows(),
            (g.s0, g.s1),
            &m,
            &mut ws.mc[..g.px],
        );
    }
}

/// Plain counts: which active pixels of strip row `r` could change at all
/// (a count of at least `t_any`, with `live` bit planes), kept in mask
/// plane 2. On the last level (`bg.1`) the others are decided here:
/// background (class byte `bg.0`) at their count. Whether any could.
#[inline(always)]
fn plain_candidates(
    ws: &mut Workspace<'_>,
    g: &StripGeometry,
    r: usize,
    (t_any, live): (u32, usize),
    bg: (u8, bool),
) -> bool {
    let words = g.words;
    let mut any = 0u64;
    for w in r * g.wpr..(r + 1) * g.wpr {
        let a = ws.masks[w];
        if a == 0 {
            ws.masks[2 * words + w] = 0;
            continue;
        }
        let c = counter(ws.counts, w);
        let a0 = a & slices::at_least_live(c, t_any, live);
        ws.masks[2 * words + w] = a0;
        any |= a0;
        if bg.1 && a0 != a {
            let base = r * g.width + 64 * (w - r * g.wpr);
            background_rest(c, a & !a0, base, bg.0, ws.class, ws.c_t);
            ws.masks[w] = a0;
        }
    }
    any != 0
}

/// The row background per tile column of the band row whose [`tile_pos`]
/// is `(ty0, ty1, fy)`, 1/32 count: bilinear between its two tile rows' medians (`tiles`, in the strip's
/// tile buffer), with a copy of the first and the last column on either
/// side ([`Level::bg`]).
#[inline(always)]
fn row_backgrounds(
    tiles_buf: &[u8],
    tiles: &Tiles,
    (ty0, ty1, fy): (usize, usize, u32),
    bg_row: &mut [u32],
) {
    let (wy0, wy1) = (32 - fy, fy);
    let (row_t0, row_t1) = ((ty0 - tiles.y0) * tiles.x, (ty1 - tiles.y0) * tiles.x);
    let n_bg = bg_row.len();
    let cols = n_bg - 2;
    // The two tile rows as slices: a loop without bounds checks, which the
    // compiler vectorises.
    let t0 = tiles_buf.get(row_t0..row_t0 + cols).unwrap_or_default();
    let t1 = tiles_buf.get(row_t1..row_t1 + cols).unwrap_or_default();
    for ((b, &a), &c) in bg_row[1..n_bg - 1].iter_mut().zip(t0).zip(t1) {
        *b = wy0 * u32::from(a) + wy1 * u32::from(c);
    }
    bg_row[0] = bg_row[1];
    bg_row[n_bg - 1] = bg_row[n_bg - 2];
}

/// The motion of one compensated row at one level: band row `r` of
/// motion `m`, level window `win` of the frame at `k`.
struct RowMotion<'m, 'a> {
    m: &'m Motion<'a>,
    r: u16,
    win: Window,
    k: u32,
}

impl RowMotion<'_, '_> {
    /// The test of the row's tile column `c`: the floor mask (all ones
    /// where the motion moves anything within the window, [`travel`] ≥
    /// [`MIN_TRAVEL`]: the pixel's own plain count floors its background;
    /// else 0) and the pixels a compensated count sums ([`positions`], its
    /// noise model; 1 is the plain test).
    #[inline(always)]
    fn test(&self, c: u16) -> (u32, u32) {
        let (win, v) = (self.win, self.m.at(self.r, c));
        let floor = if travel(v, win.start, win.end(), self.k) >= MIN_TRAVEL {
            u32::MAX
        } else {
            0
        };
        (floor, positions(v, win.start, win.end(), self.k))
    }
}

/// One level's compensated test of strip row `r`'s words: a particle
/// needs a tested (compensated) count above the background (so above the
/// word's lowest; the floor only raises it), with the noise of the pixels
/// its tile column's compensated count sums ([`RowMotion::test`], worked
/// out once per column that has candidates); saturation reads the plain
/// counts. Only those pixels are read and tested; on the last level the
/// rest are background at their count.
#[inline(always)]
fn words_compensated(
    ws: &mut Workspace<'_>,
    lv: &Level<'_>,
    (th, p, rm): (&Thresholds, &Params, &RowMotion<'_, '_>),
    r: usize,
    g: &StripGeometry,
    stats: &mut SegmentStats,
) {
    let (width, words) = (g.width, g.words);
    // The last tile column tested and its test.
    let mut test: Option<(u16, (u32, u32))> = None;
    for w in r * g.wpr..(r + 1) * g.wpr {
        let a = ws.masks[w];
        if a == 0 {
            continue;
        }
        let c = counter(ws.counts, w);
        let jw = w - r * g.wpr;
        let base = r * width + 64 * jw;
        let mut done = 0u64;
        let t = lv.b_range(jw, width).0 >> B_FRAC_BITS;
        let row = &ws.mc[base..(base + 64).min(r * width + width)];
        let mut above = 0u64;
        for (q, &v) in row.iter().enumerate() {
            above |= u64::from(u32::from(v) > t) << q;
        }
        let cand = a & (above | slices::at_least_live(c, lv.sat_c, lv.live));
        let (floor, segs) = if cand == 0 {
            (0, 1)
        } else {
            let col = rm.m.col_of_word(jw);
            match test {
                Some((tc, t)) if tc == col => t,
                _ => {
                    let t = rm.test(col);
                    test = Some((col, t));
                    t
                }
            }
        };
        // Compensated candidates: a byte group's plain counts read out of
        // the bit planes once.
        let mut m = cand;
        let mut counts = slices::Groups::new(c);
        while m != 0 {
            let i = m.trailing_zeros();
            m &= m - 1;
            let x = 64 * jw + i as usize;
            let cp = counts.count(i);
            let tested = ws.mc[r * width + x];
            let b_q10 = lv.b_at(x).max((u32::from(cp) << B_FRAC_BITS) & floor);
            let particle = if segs > 1 {
                is_particle_compensated(tested, b_q10, p, segs)
            } else {
                th.is_particle(tested, b_q10, p)
            };
            let at = base + i as usize;
            if particle {
                ws.class[at] = lv.decided.0;
                ws.c_t[at] = tested;
                stats.particle_pixels += 1;
                ws.masks[words + w] |= 1 << i;
                done |= 1 << i;
            } else if u32::from(cp) >= lv.sat_c {
                ws.class[at] = lv.decided.1;
                ws.c_t[at] = cp;
                stats.saturated_pixels += 1;
                done |= 1 << i;
            }
        }
        if lv.last {
            // The last level decides the rest: background, at their count
            // over n_max.
            background_rest(c, a & !done, base, lv.decided.1, ws.class, ws.c_t);
            done = a;
        }
        ws.masks[w] = a & !done;
    }
}

/// One level's plain test of strip row `r`'s words (`width` px, `wpr`
/// words per row, `words` in the strip): for each word with pixels that
/// could change (mask plane 2), those whose count passes at the word's
/// lowest background are tested exactly ([`test_plain`]), the others that
/// reach the saturation count are saturated background outright; on the
/// last level the rest are background at their count. Apart from the
/// compensated path so each loop holds only what it needs.
fn words_plain(
    ws: &mut Workspace<'_>,
    lv: &Level<'_>,
    (th, p): (&Thresholds, &Params),
    r: usize,
    (width, wpr, words): (usize, usize, usize),
    stats: &mut SegmentStats,
) {
    for w in r * wpr..(r + 1) * wpr {
        let a = ws.masks[w];
        let a0 = ws.masks[2 * words + w];
        if a0 == 0 {
            continue;
        }
        let c = counter(ws.counts, w);
        let jw = w - r * wpr;
        let base = r * width + 64 * jw;
        let range = lv.b_range(jw, width);
        let tp = u32::from(th.min_count(range.0));
        let maybe = a0 & slices::at_least_live(c, tp, lv.live);
        // The rest saturate or wait (no compare when there is no rest).
        let rest = a0 & !maybe;
        let sat = if rest == 0 {
            0
        } else {
            rest & slices::at_least_live(c, lv.sat_c, lv.live)
        };
        let mut done = 0u64;
        if sat != 0 {
            background_rest(c, sat, base, lv.decided.1, ws.class, ws.c_t);
            stats.saturated_pixels += sat.count_ones();
            done = sat;
        }
        if maybe != 0 {
            let end = base + 64;
            let class = ws.class.get_mut(base..end.min(ws.class.len()));
            let c_t = ws.c_t.get_mut(base..end.min(ws.c_t.len()));
            let (part_bits, sat) = test_plain(
                c,
                maybe,
                lv,
                (th, p),
                (64 * jw, range),
                (class.unwrap_or_default(), c_t.unwrap_or_default()),
            );
            stats.particle_pixels += part_bits.count_ones();
            stats.saturated_pixels += sat.count_ones();
            ws.masks[words + w] |= part_bits;
            done |= part_bits | sat;
        }
        if lv.last {
            background_rest(c, a & !done, base, lv.decided.1, ws.class, ws.c_t);
            done = a;
        }
        ws.masks[w] = a & !done;
    }
}

/// The plain particle test of the candidates `cand` of a word (counters
/// `c`, first column `x0`, backgrounds within `(lo, hi)` ([`Level::b_range`]);
/// `class` and `c_t` from its first pixel): a byte group's counts read
/// out of the bit planes once, each candidate tested against the
/// background at its column; particles and saturated pixels get their
/// class byte and count. Returns both as bits. Kept apart from the
/// compensated test so its loop holds only what it needs.
fn test_plain(
    c: &Counter,
    cand: u64,
    lv: &Level<'_>,
    (th, p): (&Thresholds, &Params),
    (x0, (lo, hi)): (usize, (u32, u32)),
    (class, c_t): (&mut [u8], &mut [u8]),
) -> (u64, u64) {
    let (mut part, mut sat) = (0u64, 0u64);
    let mut counts = slices::Groups::new(c);
    // In native words: on a 32-bit core a `u64`'s bit scan and a bit set
    // at a variable position are several instructions each.
    for h in 0..64 / slices::WORD {
        let mut m = (cand >> (h * slices::WORD)) as usize;
        let (mut ph, mut sh) = (0usize, 0usize);
        while m != 0 {
            let b = m.trailing_zeros();
            m &= m - 1;
            let i = (h * slices::WORD) as u32 + b;
            let cp = counts.count(i);
            // Particle exactly below the count's bound: a bound above the
            // word's highest background or at most its lowest decides
            // without the column's background.
            let bound = th.bound(cp, p);
            let particle = bound > hi || (bound > lo && lv.b_at(x0 + i as usize) < bound);
            let decided = if particle {
                ph |= 1 << b;
                lv.decided.0
            } else if u32::from(cp) >= lv.sat_c {
                sh |= 1 << b;
                lv.decided.1
            } else {
                continue;
            };
            if let (Some(cl), Some(ct)) = (class.get_mut(i as usize), c_t.get_mut(i as usize)) {
                *cl = decided;
                *ct = cp;
            }
        }
        part |= (ph as u64) << (h * slices::WORD);
        sat |= (sh as u64) << (h * slices::WORD);
    }
    (part, sat)
}

/// Pixels `left` of a word (its first pixel at `base`) decided background
/// (saturated at this level, or left at the last level), at their count.
fn background_rest(
    c: &Counter,
    left: u64,
    base: usize,
    class_bg: u8,
    class: &mut [u8],
    c_t: &mut [u8],
) {
    #[cfg(target_arch = "x86_64")]
    if whole_word(c, left, base, class_bg, class, c_t) {
        return;
    }
    let bg8 = u64::from(class_bg) * 0x0101_0101_0101_0101;
    // Byte groups found in native words (a `u64` scan and a shift by a
    // variable amount are several instructions each on a 32-bit core).
    for h in 0..64 / slices::WORD {
        let mut x = (left >> (h * slices::WORD)) as usize;
        while x != 0 {
            let gh = x.trailing_zeros() / 8;
            let grp = (x >> (8 * gh)) & 0xff;
            x &= !(0xff << (8 * gh));
            group_rest(
                c,
                (h * slices::WORD / 8) as u32 + gh,
                grp,
                base,
                (class_bg, bg8),
                class,
                c_t,
            );
        }
    }
}

/// [`background_rest`] of the pixels `grp` of byte group `g`.
#[inline(always)]
fn group_rest(
    c: &Counter,
    g: u32,
    grp: usize,
    base: usize,
    (class_bg, bg8): (u8, u64),
    class: &mut [u8],
    c_t: &mut [u8],
) {
    let bytes = slices::bytes8(c, g);
    let at = base + 8 * g as usize;
    let group = (class.get_mut(at..at + 8), c_t.get_mut(at..at + 8));
    if let (Some(cl), Some(ct)) = group {
        // The group's eight bytes at once, its pixels' bytes replaced
        // (a byte mask from the group's bits).
        let m = slices::SPREAD[grp] * 0xff;
        let blend = |old: &mut [u8], new: u64| {
            let mut o = [0u8; 8];
            o.copy_from_slice(old);
            let v = (u64::from_le_bytes(o) & !m) | (new & m);
            old.copy_from_slice(&v.to_le_bytes());
        };
        blend(cl, bg8);
        blend(ct, u64::from_le_bytes(bytes));
    } else {
        // The buffer's last pixels: one at a time.
        let mut m = grp;
        while m != 0 {
            let q = m.trailing_zeros() as usize;
            m &= m - 1;
            if let (Some(cl), Some(ct)) = (class.get_mut(at + q), c_t.get_mut(at + q)) {
                *cl = class_bg;
                *ct = bytes[q];
            }
        }
    }
}

/// [`background_rest`] of a word with pixels in at least three byte
/// groups, on x86-64: all 64 counts read at once ([`slices::bytes64`])
/// and the class and count bytes written sixteen at a time through byte
/// masks (SSE2), cheaper than a byte group at a time for such words (most
/// are the last level's, nearly full).
/// False (nothing written) for fewer groups or a word past the buffers'
/// end.
#[cfg(target_arch = "x86_64")]
#[inline]
fn whole_word(
    c: &Counter,
    left: u64,
    base: usize,
    class_bg: u8,
    class: &mut [u8],
    c_t: &mut [u8],
) -> bool {
    use wide::u8x16;
    let groups = (left | left >> 1 | left >> 2 | left >> 3) & 0x1111_1111_1111_1111;
    let groups = (groups | groups >> 4) & 0x0101_0101_0101_0101;
    let ends = (class.get_mut(base..base + 64), c_t.get_mut(base..base + 64));
    let (true, (Some(cl), Some(ct))) = (groups.count_ones() >= 3, ends) else {
        return false;
    };
    let counts = slices::bytes64(c);
    const SEL: [u8; 16] = [1, 2, 4, 8, 16, 32, 64, 128, 1, 2, 4, 8, 16, 32, 64, 128];
    let sel = u8x16::new(SEL);
    let bg = u8x16::splat(class_bg);
    let load = |s: &[u8]| {
        let mut a = [0u8; 16];
        a.copy_from_slice(s);
        u8x16::new(a)
    };
    let chunks = cl.chunks_exact_mut(16).zip(ct.chunks_exact_mut(16));
    for (k, ((cl, ct), n)) in chunks.zip(counts.chunks_exact(16)).enumerate() {
        let bits = (left >> (16 * k)) as u16;
        if bits == 0 {
            continue;
        }
        let [lo, hi] = bits.to_le_bytes();
        let spread = u8x16::new([
            lo, lo, lo, lo, lo, lo, lo, lo, hi, hi, hi, hi, hi, hi, hi, hi,
        ]);
        let m = (spread & sel).simd_eq(sel);
        cl.copy_from_slice(&m.bitselect(bg, load(cl)).to_array());
        ct.copy_from_slice(&m.bitselect(load(n), load(ct)).to_array());
    }
    true
}

/// The bit-sliced counter of word `w` (zero past the buffer). After
/// [`segment`], every pixel's plain count over the last level's window.
#[inline]
pub(crate) fn counter(counts: &[u64], w: usize) -> &Counter {
    const ZERO: Counter = [0; 8];
    counts
        .get(8 * w..8 * w + 8)
        .and_then(|s| <&Counter>::try_from(s).ok())
        .unwrap_or(&ZERO)
}

/// Saturation time alone: for every pixel of the band, `t_bgmax` = the
/// smallest window n of n0, 2n0, …, n_max (centred on `k`) whose count
/// reaches `N_fs` (rate-scaled when clipped), or n_max if none. `counts` is
/// scratch of `rows × width` bytes; `out` receives ticks. Unlike
/// [`crate::reconstruct_adaptive`] it ignores particles: a pixel's own
/// spikes decide, so more spikes never lengthen it.
pub fn saturation_times(
    hist: &History<'_>,
    k: u32,
    p: &Params,
    counts: &mut [u8],
    out: &mut [u16],
) -> Result<(), crate::Error> {
    p.validate(hist.depth())?;
    if !hist.holds(k) {
        return Err(crate::Error::TickUnavailable);
    }
    let px = usize::from(hist.width()) * usize::from(hist.rows());
    crate::window::check_len(counts.len(), px)?;
    crate::window::check_len(out.len(), px)?;
    let (levels, nlev) = p.levels();
    counts[..px].fill(0);
    out[..px].fill(0);
    let mut prev: Option<Window> = None;
    for &n in levels.iter().take(nlev) {
        let win = Window::in_history(hist, k, n);
        let rows = (0, hist.rows());
        match prev {
            None => add_counts(hist, rows, (win.start, win.end()), &mut counts[..px]),
            Some(pw) => {
                add_counts(hist, rows, (win.start, pw.start), &mut counts[..px]);
                add_counts(hist, rows, (pw.end(), win.end()), &mut counts[..px]);
            }
        }
        prev = Some(win);
        for (o, &c) in out[..px].iter_mut().zip(counts[..px].iter()) {
            if *o == 0 && is_saturated(c, &win, p.n_fs) {
                *o = n;
            }
        }
    }
    for o in out[..px].iter_mut().filter(|o| **o == 0) {
        *o = p.n_max;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_positions() {
        assert_eq!(tile_pos(0, 0, 3), (0, 0, 17));
        assert_eq!(tile_pos(7, 0, 3), (0, 0, 31));
        assert_eq!(tile_pos(8, 0, 3), (0, 1, 1));
        assert_eq!(tile_pos(23, 0, 3), (0, 1, 31));
        assert_eq!(tile_pos(24, 0, 3), (1, 2, 1));
        assert_eq!(tile_pos(63, 0, 3), (3, 3, 15));
    }

    /// The planes' sums into bit-sliced counters, on this target's path
    /// ([`add_sliced`]) and on the one without a vector unit
    /// ([`add_runs`]), equal a pixel-by-pixel count: up to 40 planes
    /// (groups of 15 and a remainder), some planes short (a run or a
    /// block not held whole), counters started fresh or added to.
    #[test]
    fn sliced_sums_count_like_pixels() {
        let mut rnd = crate::testing::rng(0x2545_f491_4f6c_dd1d);
        for case in 0..48 {
            let (rows, wpr) = (1 + rnd(9) as usize, 1 + rnd(7) as usize);
            let words = rows * wpr;
            let n = rnd(41) as usize;
            let planes: std::vec::Vec<std::vec::Vec<u64>> = (0..n)
                .map(|_| {
                    let len = if rnd(5) == 0 {
                        rnd(words as u64)
                    } else {
                        words as u64
                    };
                    (0..len).map(|_| rnd(u64::MAX) & rnd(u64::MAX)).collect()
                })
                .collect();
            let refs: std::vec::Vec<&[u64]> = planes.iter().map(|p| p.as_slice()).collect();
            let split = rnd(n as u64 + 1) as usize;
            let prior: std::vec::Vec<u64> = (0..8 * words)
                .map(|i| if i % 8 < 4 { rnd(u64::MAX) } else { 0 })
                .collect();
            for fresh in [true, false] {
                let count = |c: &[u64], w: usize, i: u32| {
                    slices::count(<&Counter>::try_from(&c[8 * w..8 * w + 8]).unwrap(), i)
                };
                let want = |w: usize, i: u32| {
                    let base = if fresh { 0 } else { count(&prior, w, i) };
                    let spikes = planes
                        .iter()
                        .filter(|p| p.get(w).is_some_and(|x| (x >> i) & 1 == 1))
                        .count();
                    usize::from(base) + spikes
                };
                let mut a = prior.clone();
                add_sliced(
                    [&refs[..split], &refs[split..]],
                    wpr,
                    0,
                    rows,
                    &mut a,
                    fresh,
                );
                let mut b = prior.clone();
                let mut rest = &refs[..];
                let mut first = fresh;
                while !rest.is_empty() {
                    let m = rest.len().min(15);
                    add_runs(&rest[..m], &mut b, first);
                    first = false;
                    rest = &rest[m..];
                }
                if n == 0 && fresh {
                    b.fill(0);
                }
                for w in 0..words {
                    for i in 0..64 {
                        let e = want(w, i);
                        assert_eq!(usize::from(count(&a, w, i)), e, "case {case} sliced");
                        assert_eq!(usize::from(count(&b, w, i)), e, "case {case} runs");
                    }
                }
            }
        }
    }

    #[test]
    fn class_bytes_round_trip() {
        for c in [Class::Active, Class::Particle, Class::Background] {
            for l in 0..9 {
                assert_eq!(decode(encode(c, l)), (c, l));
            }
        }
    }
}
