//! Saturation time `t_bgmax` and iterative particle/background segmentation
//! (paper section 2.2; SPEC section 5).
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
use crate::motion::{add_compensated, positions, travel, MIN_TRAVEL};
use crate::params::Params;
use crate::particle::is_particle_compensated;
use crate::q::B_FRAC_BITS;
use crate::state::Workspace;
use crate::window::{add_counts, add_plane_counts, Window};

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
const LEVEL_MASK: u8 = 0x0f;

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
/// for such pixels.
pub(crate) fn pixel_saturation(
    ctx: &crate::context::Ctx<'_, '_>,
    levels: &[u16],
    row: u16,
    col: u16,
) -> (u8, u16, u16) {
    let (hist, span, p) = (ctx.hist, ctx.span, ctx.p);
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
    for &n in levels {
        let win = Window::in_history(hist, ctx.k, n);
        let c = match prev {
            None => bits(win.start, win.end()),
            Some(pw) => last
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
            x: usize::from(width).div_ceil(16),
            y0: usize::from(s0) / 16,
            y1: usize::from(s1.saturating_sub(1)) / 16,
        }
    }
}

/// Lower median of the non-particle counts of each tile (of all counts where
/// a tile has only particle pixels): of the motion-compensated counts when
/// `compensated`, else of the plain ones.
pub(crate) fn tile_medians(
    ws: &mut Workspace<'_>,
    s0: u16,
    s1: u16,
    tiles: &Tiles,
    compensated: bool,
) {
    let width = usize::from(ws.sizes.width);
    let counts: &[u8] = if compensated { ws.mc } else { ws.counts };
    for ty in tiles.y0..=tiles.y1 {
        let r_lo = (ty * 16).max(usize::from(s0));
        let r_hi = (ty * 16 + 16).min(usize::from(s1));
        for tx in 0..tiles.x {
            let c_lo = tx * 16;
            let c_hi = (tx * 16 + 16).min(width);
            let mut hist = [0u16; 256];
            let mut n = 0u32;
            for r in r_lo..r_hi {
                let base = (r - usize::from(s0)) * width;
                let row = base + c_lo..base + c_hi;
                for (&c, &cl) in counts[row.clone()].iter().zip(&ws.class[row]) {
                    if decode(cl).0 != Class::Particle {
                        hist[usize::from(c)] += 1;
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
            let (h, m) = (&hist, n);
            let rank = m.saturating_sub(1) / 2;
            let mut seen = 0u32;
            let mut med = 0u8;
            for (v, &cnt) in h.iter().enumerate() {
                seen += u32::from(cnt);
                if seen > rank {
                    med = v as u8;
                    break;
                }
            }
            if let Some(t) = ws.tiles.get_mut((ty - tiles.y0) * tiles.x + tx) {
                *t = med;
            }
        }
    }
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

/// One band row of one segmentation level: what its undecided pixels are
/// tested against.
struct Row<'a, B> {
    /// Background of tile column `tx` at this row, in 1/32 of 1/1024
    /// counts (bilinear between the two tile rows).
    bg: B,
    tiles_x: usize,
    counts: &'a [u8],
    tested: &'a [u8],
    /// All ones where the plain count floors the background, else 0.
    floor: u32,
    sat_c: u32,
    last: bool,
    /// Class bytes of a particle and a background decided at this level.
    decided: (u8, u8),
}

impl<B: Fn(usize) -> u32> Row<'_, B> {
    /// Decides the row's active pixels with `is_particle(count, b_q10)`.
    #[inline(always)]
    fn decide(
        &self,
        class: &mut [u8],
        c_t: &mut [u8],
        stats: &mut SegmentStats,
        is_particle: impl Fn(u8, u32) -> bool,
    ) {
        let active = encode(Class::Active, 0);
        let (decided_particle, decided_bg) = self.decided;
        let width = class.len();
        // Runs of pixels between the same two tile centres: x in [0, 8),
        // then [8 + 16t, 24 + 16t). Along a run the background is linear
        // in x, so it advances by a constant step (exact, in 1/1024).
        let mut x = 0usize;
        while x < width {
            let run_end = if x < 8 { 8 } else { x + 16 - (x - 8) % 16 }.min(width);
            let (tx0, tx1, fx) = tile_pos(x, 0, self.tiles_x - 1);
            let (r0, r1) = ((self.bg)(tx0), (self.bg)(tx1));
            let mut b = i64::from((32 - fx) * r0 + fx * r1);
            let step = 2 * (i64::from(r1) - i64::from(r0));
            for i in x..run_end {
                if class[i] == active {
                    let c = self.counts[i];
                    // Branch-free: the floor is 0 where it does not apply.
                    let b_q10 = (b as u32).max((u32::from(c) << B_FRAC_BITS) & self.floor);
                    if is_particle(self.tested[i], b_q10) {
                        class[i] = decided_particle;
                        c_t[i] = self.tested[i];
                        stats.particle_pixels += 1;
                    } else if u32::from(c) >= self.sat_c {
                        class[i] = decided_bg;
                        c_t[i] = c;
                        stats.saturated_pixels += 1;
                    } else if self.last {
                        class[i] = decided_bg;
                        c_t[i] = c;
                    }
                }
                b += step;
            }
            x = run_end;
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
pub(crate) fn segment(
    ctx: &crate::context::Ctx<'_, '_>,
    ws: &mut Workspace<'_>,
    s0: u16,
    s1: u16,
) -> SegmentStats {
    let crate::context::Ctx {
        hist,
        span,
        k,
        p,
        th,
        motion,
        ..
    } = *ctx;
    let width = usize::from(ws.sizes.width);
    let px = width * usize::from(s1 - s0);
    let mc = motion.is_some() && ws.mc.len() >= px;
    let (levels, nlev) = p.levels();
    let tiles = Tiles::for_strip(ws.sizes.width, s0, s1);
    let mut stats = SegmentStats::default();
    let active = encode(Class::Active, 0);
    ws.counts[..px].fill(0);
    ws.class[..px].fill(active);
    ws.c_t[..px].fill(0);
    if mc {
        ws.mc[..px].fill(0);
    }
    let mut prev: Option<Window> = None;
    for (j, &n) in levels.iter().enumerate().take(nlev) {
        let win = Window::in_history(hist, k, n);
        // Windows are nested: add only the ticks the previous one lacked.
        let rows = (s0, s1);
        let added = match prev {
            None => [(win.start, win.end()), (win.end(), win.end())],
            Some(pw) => [(win.start, pw.start), (pw.end(), win.end())],
        };
        for (a, e) in added {
            add_plane_counts(span.range(a, e), hist.width(), rows, &mut ws.counts[..px]);
            if let (true, Some(m)) = (mc, &motion) {
                let planes = span.range(a, e);
                let start = a.max(span.start);
                add_compensated(
                    planes,
                    start,
                    k,
                    hist.width(),
                    hist.rows(),
                    rows,
                    m,
                    &mut ws.mc[..px],
                );
            }
        }
        prev = Some(win);
        tile_medians(ws, s0, s1, &tiles, mc);
        // c ≥ sat_c ⟺ c·n ≥ N_fs·len (the rate reaches N_fs/n).
        let sat_c = if win.len == 0 {
            u32::MAX
        } else {
            (u32::from(p.n_fs) * u32::from(win.len)).div_ceil(u32::from(n))
        };
        let decided_bg = encode(Class::Background, j as u8);
        let decided_particle = encode(Class::Particle, j as u8);
        let last = j + 1 == nlev;
        for r in s0..s1 {
            let (ty0, ty1, fy) = tile_pos(usize::from(r), tiles.y0, tiles.y1);
            let (wy0, wy1) = (32 - fy, fy);
            let row_t0 = (ty0 - tiles.y0) * tiles.x;
            let row_t1 = (ty1 - tiles.y0) * tiles.x;
            let base = usize::from(r - s0) * width;
            let counts = &ws.counts[base..base + width];
            let tested: &[u8] = if mc {
                &ws.mc[base..base + width]
            } else {
                counts
            };
            // Where the row moves, the pixel's own plain count is a floor
            // of its background (docs above): all ones to keep it, else 0.
            let floor: u32 = match (mc, &motion) {
                (true, Some(m)) if travel(m.at(r), win.start, win.end(), k) >= MIN_TRAVEL => {
                    u32::MAX
                }
                _ => 0,
            };
            // A compensated count sums this many pixels' spikes: its own
            // noise model (1: the plain test, by the tables).
            let segs = match (mc, &motion) {
                (true, Some(m)) => positions(m.at(r), win.start, win.end(), k),
                _ => 1,
            };
            let class = &mut ws.class[base..base + width];
            let c_t = &mut ws.c_t[base..base + width];
            // Tile medians of this row's two tile rows, weighted in 1/32.
            let tile = |t: usize| u32::from(ws.tiles.get(t).copied().unwrap_or(0));
            let row = Row {
                bg: |tx: usize| wy0 * tile(row_t0 + tx) + wy1 * tile(row_t1 + tx),
                tiles_x: tiles.x,
                counts,
                tested,
                floor,
                sat_c,
                last,
                decided: (decided_particle, decided_bg),
            };
            // One loop per test, so the plain frame's loop stays as it was.
            if segs > 1 {
                row.decide(class, c_t, &mut stats, |c, b| {
                    is_particle_compensated(c, b, p, segs)
                });
            } else {
                row.decide(class, c_t, &mut stats, |c, b| th.is_particle(c, b, p));
            }
        }
    }
    stats
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

    #[test]
    fn class_bytes_round_trip() {
        for c in [Class::Active, Class::Particle, Class::Background] {
            for l in 0..9 {
                assert_eq!(decode(encode(c, l)), (c, l));
            }
        }
    }
}
