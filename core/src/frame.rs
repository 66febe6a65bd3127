//! One adaptive frame at any tick k (docs/spec.md §5): segmentation, region
//! labelling, adaptive windows, background suppression and the output
//! mapping, strip by strip.
//!
//! Frame alignment: every region is shown at its own n*, each window centred
//! on k (the paper's replication of one integrated value over its n* ticks,
//! made time-accurate), and every background pixel at its `t_bgmax` window,
//! also centred on k. A frame at k therefore needs ⌊n_max/2⌋ ticks of
//! look-ahead; near the ends of the history windows are clipped and rates use
//! their real length.
//!
//! Strips: when the workspace holds fewer rows than the band, the band is
//! processed in strips of `rows − 2·margin` output rows, each computed with
//! `margin` extra rows on both sides so that regions crossing a strip edge
//! are whole. With a workspace as tall as the band the result is one pass.

use crate::context::Ctx;
use crate::error::Error;
use crate::gray::Gray;
use crate::history::History;
use crate::integrate::{adapt_region, own_bits, region_table};
use crate::label::{label, LabelStats};
use crate::motion::Motion;
use crate::params::{Params, MAX_LEVELS};
use crate::particle::Thresholds;
use crate::region::Region;
use crate::segment::{counter, decode, pixel_saturation, segment, SegmentStats, LEVEL_MASK};
use crate::slices;
use crate::state::Workspace;
use crate::suppress::{background_gray, background_table};
use crate::window::{check_len, Offsets, Span, Window};

/// Entries of the output pass's flat per-level table: 256 counts for
/// every value of a class byte's level field.
const PX_TABLE: usize = (LEVEL_MASK as usize + 1) * 256;

/// What one frame found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameStats {
    /// The frame's centre tick.
    pub tick: u32,
    /// Strips processed.
    pub strips: u16,
    /// Segmentation counts, summed over strips (margins included).
    pub segment: SegmentStats,
    /// Labelling counts, summed over strips (margins included).
    pub labels: LabelStats,
    /// Regions whose pixels were written (each counted once).
    pub regions_out: u32,
    /// Sum of n* over those regions (mean window = this / `regions_out`).
    pub n_star_sum: u64,
}

/// Reconstructs the adaptive frame at tick `k` of the band held by `hist`
/// into `out` (`rows × width` gray levels, stored row order).
///
/// Errors: bad parameters, a tick not held, a workspace of another width or
/// too short for its margins, an `out` too small.
pub fn reconstruct_adaptive<G: Gray>(
    hist: &History<'_>,
    k: u32,
    p: &Params,
    ws: &mut Workspace<'_>,
    out: &mut [G],
) -> Result<FrameStats, Error> {
    reconstruct_rows(hist, k, p, ws, (0, hist.rows()), out)
}

/// Rows `rows.0..rows.1` (stored order, within the band) of the adaptive
/// frame at `k`, written to the same rows of `out` (a whole frame); other
/// rows of `out` are left alone. Each strip is computed with `p.margin`
/// extra rows on both sides, so regions crossing the range's edges are
/// whole. Calling it band by band with a different `p.n_max` each gives a
/// frame whose window limit varies with the row (the dwell cap, beyond the
/// paper: docs/spec.md §5).
pub fn reconstruct_rows<G: Gray>(
    hist: &History<'_>,
    k: u32,
    p: &Params,
    ws: &mut Workspace<'_>,
    rows: (u16, u16),
    out: &mut [G],
) -> Result<FrameStats, Error> {
    rows_with(hist, k, p, ws, rows, None, out)
}

/// Rows `rows.0..rows.1` of the motion-compensated adaptive frame at `k`
/// (beyond the paper): as [`reconstruct_rows`], but particles are
/// segmented, their windows n* chosen and their gray levels counted on
/// counts compensated for `motion` (`crate::motion`: each plane shifted by
/// the row's velocity times its distance from `k`), so a particle moving as
/// predicted piles its spikes up where it is at `k` and long windows do not
/// blur it. Static light keeps its meaning: saturation times and background
/// suppression use the plain counts, so a background renders exactly as
/// without motion. The workspace needs its motion counts
/// ([`Workspace::with_motion_counts`]).
pub fn reconstruct_compensated<G: Gray>(
    hist: &History<'_>,
    k: u32,
    p: &Params,
    ws: &mut Workspace<'_>,
    rows: (u16, u16),
    motion: &Motion<'_>,
    out: &mut [G],
) -> Result<FrameStats, Error> {
    check_len(ws.mc.len(), ws.sizes.pixels())?;
    rows_with(hist, k, p, ws, rows, Some(*motion), out)
}

fn rows_with<G: Gray>(
    hist: &History<'_>,
    k: u32,
    p: &Params,
    ws: &mut Workspace<'_>,
    rows: (u16, u16),
    motion: Option<Motion<'_>>,
    out: &mut [G],
) -> Result<FrameStats, Error> {
    p.validate(hist.depth())?;
    if !hist.holds(k) {
        return Err(Error::TickUnavailable);
    }
    if ws.sizes.width != hist.width() {
        return Err(Error::PlaneMismatch);
    }
    let width = usize::from(hist.width());
    let band = hist.rows();
    check_len(out.len(), width * usize::from(band))?;
    let (r0, r1) = (rows.0.min(band), rows.1.min(band));
    let whole = r0 == 0 && r1 == band;
    let cap = ws.sizes.rows;
    let (inner, margin) = if whole && cap >= band {
        (band, 0)
    } else {
        let inner = cap.saturating_sub(p.margin.saturating_mul(2));
        if inner == 0 {
            return Err(Error::BufferTooSmall {
                needed: (2 * usize::from(p.margin) + 1) * width,
                got: ws.sizes.pixels(),
            });
        }
        (inner, p.margin)
    };
    let fs = p.full_scale.min(G::MAX);
    let (levels, nlev) = p.levels();
    let mut lens = [0u16; MAX_LEVELS];
    for (l, &n) in lens.iter_mut().zip(levels.iter()).take(nlev) {
        *l = Window::in_history(hist, k, n).len;
    }
    let th = Thresholds::new(p);
    let span = Span::new(hist, Window::in_history(hist, k, p.n_max));
    let wins = Offsets::new(hist, k, &span, p.n_max);
    let ctx = Ctx {
        hist,
        span: &span,
        wins: &wins,
        k,
        p,
        th: &th,
        levels: &levels,
        lens: &lens,
        fs,
        motion,
    };
    let mut stats = FrameStats {
        tick: k,
        ..FrameStats::default()
    };
    let mut e0 = r0;
    while e0 < r1 {
        let e1 = e0.saturating_add(inner).min(r1);
        let s0 = e0.saturating_sub(margin);
        let s1 = e1.saturating_add(margin).min(band);
        strip(&ctx, ws, (s0, s1), (e0, e1), out, &mut stats);
        stats.strips += 1;
        e0 = e1;
    }
    Ok(stats)
}

/// Pixels per round of the output pass.
const ROUND: usize = if cfg!(target_arch = "x86_64") { 16 } else { 8 };

/// The flat table indices of [`ROUND`] pixels (class bytes `cb`, counts
/// `ct`, both `ROUND` long): the class byte's level field above the count,
/// so below [`PX_TABLE`]. Built as one SSE2 mask and two byte interleaves,
/// cheaper than a shift, an OR and an address add per pixel; on a
/// Cortex-M4 the per-pixel form is the cheaper one.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn px_indices(cb: &[u8], ct: &[u8]) -> [u16; ROUND] {
    use wide::u8x16;
    let load = |s: &[u8]| {
        let mut a = [0u8; 16];
        a.copy_from_slice(&s[..16]);
        u8x16::new(a)
    };
    let (l, t) = (load(cb) & u8x16::splat(LEVEL_MASK), load(ct));
    let lo: [u16; 8] = bytemuck::cast(u8x16::unpack_low(t, l).to_array());
    let hi: [u16; 8] = bytemuck::cast(u8x16::unpack_high(t, l).to_array());
    let mut idx = [0u16; ROUND];
    idx[..8].copy_from_slice(&lo);
    idx[8..].copy_from_slice(&hi);
    idx
}

/// One strip's frame: segmentation and labelling of strip rows `s0..s1`,
/// then the output rows `e0..e1` (band rows): every pixel at its
/// background gray, particle pixels no region took at their own
/// saturation, and each region integrated over its own window.
fn strip<G: Gray>(
    ctx: &Ctx<'_, '_>,
    ws: &mut Workspace<'_>,
    (s0, s1): (u16, u16),
    (e0, e1): (u16, u16),
    out: &mut [G],
    stats: &mut FrameStats,
) {
    let seg = segment(ctx, ws, s0, s1);
    stats.segment.particle_pixels += seg.particle_pixels;
    stats.segment.saturated_pixels += seg.saturated_pixels;
    let lab = label(ws, s1 - s0);
    stats.labels.regions += lab.regions;
    stats.labels.noise_regions += lab.noise_regions;
    stats.labels.overflow_regions += lab.overflow_regions;
    stats.labels.dropped_pixels += lab.dropped_pixels;
    let mut gray = backgrounds(ctx, ws, (s0, e0, e1), out);
    loose_particles(ctx, ws, (s0, s1, e0, e1), out);
    for idx in 0..lab.regions as usize {
        let reg = ws.regions[idx];
        if reg.row1 <= e0 - s0 || reg.row0 >= e1 - s0 {
            continue;
        }
        let reg = adapt_region(ctx, ws, s0, s1 - s0, idx);
        stats.regions_out += 1;
        stats.n_star_sum += u64::from(reg.n_star);
        region_table(&reg, ctx.p, ctx.fs, &mut gray);
        region_out(ws, &reg, (s0, e0, e1), &gray, out);
    }
}

/// Every output pixel (band rows `e0..e1` of the strip from `s0`) at its
/// level's background gray; region pixels are overwritten later, and
/// particle pixels no region took get their own saturation time
/// ([`loose_particles`]). Returns a table the size of a level's, free for
/// the regions'.
fn backgrounds<G: Gray>(
    ctx: &Ctx<'_, '_>,
    ws: &Workspace<'_>,
    (s0, e0, e1): (u16, u16, u16),
    out: &mut [G],
) -> [u16; 256] {
    let Ctx {
        hist,
        p,
        levels,
        lens,
        fs,
        ..
    } = *ctx;
    let width = usize::from(hist.width());
    let first = usize::from(e0 - s0) * width;
    let last = usize::from(e1 - s0) * width;
    let nlev = levels.iter().take_while(|&&n| n != 0).count();
    // Each level's background gray per count (`background_gray` for its
    // window), built by exact steps instead of a division per pixel, in
    // one flat table for every value of a class byte's level field (the
    // levels past the frame's are zero), so a pixel's value is one
    // indexed load without a bounds check.
    let mut tbl = [0u16; 256];
    let mut px_tables = [G::default(); PX_TABLE];
    for (l, pt) in px_tables.chunks_exact_mut(256).enumerate().take(nlev) {
        background_table(levels[l], lens[l], p, fs, &mut tbl);
        for (o, &g) in pt.iter_mut().zip(&tbl) {
            *o = G::from_level(g);
        }
    }
    let outs = out.get_mut(usize::from(e0) * width..).unwrap_or_default();
    let n = (last - first).min(outs.len());
    let (cls, cts, outs) = (
        &ws.class[first..first + n],
        &ws.c_t[first..first + n],
        &mut outs[..n],
    );
    let px = |cb: u8, c: u8| px_tables[usize::from(cb & LEVEL_MASK) << 8 | usize::from(c)];
    // ROUND pixels per round: the loop's own work (three pointers, a
    // test) was a third of the pass; their table indices are built
    // together ([`px_indices`]).
    let (mut c8, mut t8, mut o8) = (
        cls.chunks_exact(ROUND),
        cts.chunks_exact(ROUND),
        outs.chunks_exact_mut(ROUND),
    );
    for ((cb, ct), o) in c8.by_ref().zip(t8.by_ref()).zip(o8.by_ref()) {
        #[cfg(target_arch = "x86_64")]
        for (o, &i) in o.iter_mut().zip(&px_indices(cb, ct)) {
            *o = px_tables[usize::from(i)];
        }
        #[cfg(not(target_arch = "x86_64"))]
        for q in 0..ROUND {
            o[q] = px(cb[q], ct[q]);
        }
    }
    let tail = c8.remainder().iter().zip(t8.remainder());
    for ((&cb, &c), o) in tail.zip(o8.into_remainder()) {
        *o = px(cb, c);
    }
    tbl
}

/// "Any region" bits, for the rings: the particle pixels (mask plane 1,
/// as the segmentation left it) that a region took, written to plane 0
/// in increasing order (which only overwrites particle words already
/// read). The others, in output rows `e0..e1`, are background at their
/// own saturation time (`segment::pixel_saturation`).
fn loose_particles<G: Gray>(
    ctx: &Ctx<'_, '_>,
    ws: &mut Workspace<'_>,
    (s0, s1, e0, e1): (u16, u16, u16, u16),
    out: &mut [G],
) {
    let Ctx {
        hist,
        p,
        levels,
        fs,
        ..
    } = *ctx;
    let width = usize::from(hist.width());
    let (first, last) = (usize::from(e0 - s0) * width, usize::from(e1 - s0) * width);
    let out_base = usize::from(e0) * width;
    let nlev = levels.iter().take_while(|&&n| n != 0).count();
    let wpr = crate::plane::words_per_row(hist.width());
    let words = usize::from(s1 - s0) * wpr;
    for w in 0..words {
        let mut m = ws.masks[words + w];
        let base = (w / wpr) * width + 64 * (w % wpr);
        let mut any = 0u64;
        while m != 0 {
            let b = m.trailing_zeros();
            m &= m - 1;
            let i = base + b as usize;
            if ws.labels[i] != 0 {
                any |= 1 << b;
            } else if (first..last).contains(&i) {
                let (r, col) = (s0 + (i / width) as u16, (i % width) as u16);
                // On plain counts the segmentation stopped at the pixel's
                // level with its count there.
                let (_, lev) = decode(ws.class[i]);
                let known = ctx
                    .motion
                    .is_none()
                    .then_some((usize::from(lev), ws.c_t[i]));
                let at_last = slices::count(counter(ws.counts, w), b);
                let (c, t, len) = pixel_saturation(ctx, &levels[..nlev], r, col, known, at_last);
                if let Some(o) = out.get_mut(out_base + i - first) {
                    *o = G::from_level(background_gray(c, t, len, p, fs));
                }
            }
        }
        ws.masks[w] = any;
    }
}

/// Region `reg`'s pixels in output rows `e0..e1` at their gray over its
/// window (`gray` per count), as [`adapt_region`] left them (no label
/// reads over the box: a third of the box was not the region's).
fn region_out<G: Gray>(
    ws: &Workspace<'_>,
    reg: &Region,
    (s0, e0, e1): (u16, u16, u16),
    gray: &[u16; 256],
    out: &mut [G],
) {
    let width = usize::from(ws.sizes.width);
    let (r_lo, r_hi) = (e0 - s0, e1 - s0);
    let (j0, j1) = (
        usize::from(reg.col0) / 64,
        usize::from(reg.col1.max(1) - 1) / 64,
    );
    for r in usize::from(reg.row0.max(r_lo))..usize::from(reg.row1.min(r_hi)) {
        for j in j0..=j1 {
            let base = r * width + 64 * j;
            slices::for_each_bit(own_bits(ws, r, j), |b| {
                let i = base + b as usize;
                let g = gray[usize::from(ws.c_t.get(i).copied().unwrap_or(0))];
                if let Some(o) = out.get_mut(usize::from(s0) * width + i) {
                    *o = G::from_level(g);
                }
            });
        }
    }
}
