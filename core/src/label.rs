//! Region labelling: particle pixels form regions by 8-connectivity
//! (union-find over runs of a row's particle pixels, in a caller-supplied
//! table); regions under 3 px are noise. Bounded: when the
//! provisional-label table or the region table is full, further pixels or
//! regions stay background, and are counted.

use crate::region::Region;
use crate::slices::low_bits;
use crate::state::Workspace;

/// Regions smaller than this many pixels are noise.
pub const MIN_REGION_PIXELS: u32 = 3;

/// Counts of one labelling.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LabelStats {
    /// Regions kept (≥ 3 px), at most the table's size.
    pub regions: u32,
    /// Regions under 3 px, left as background.
    pub noise_regions: u32,
    /// Regions that did not fit the table, left as background.
    pub overflow_regions: u32,
    /// Particle pixels that found no provisional label (table full).
    pub dropped_pixels: u32,
}

const ASSIGNED: u16 = 0x8000;
const NONE: u16 = 0x7fff;

#[inline]
fn find(parents: &[u16], mut x: u16) -> u16 {
    // Parents always point to smaller labels, so this ends.
    while let Some(&p) = parents.get(usize::from(x)) {
        if p == x || p & ASSIGNED != 0 {
            return x;
        }
        x = p;
    }
    x
}

/// The root of provisional label `l` after flattening (`None` for 0: no
/// label): its parent, or itself where a region already took it.
#[inline(always)]
fn root_of(parents: &[u16], l: u16) -> Option<u16> {
    if l == 0 {
        return None;
    }
    let root = parents.get(usize::from(l)).copied().unwrap_or(l);
    Some(if root & ASSIGNED != 0 { l } else { root })
}

/// Calls `f` with the pixel index of every set bit of `mask` (`wpr` words
/// per row of `width` px), in raster order.
#[inline(always)]
fn for_each_bit(mask: &[u64], wpr: usize, width: usize, mut f: impl FnMut(usize)) {
    for (w, &m) in mask.iter().enumerate() {
        let mut m = m;
        let base = (w / wpr) * width + 64 * (w % wpr);
        while m != 0 {
            f(base + m.trailing_zeros() as usize);
            m &= m - 1;
        }
    }
}

/// The runs of set bits of one row's mask words, in order, as columns
/// `a..e` (bits past the row's width are clear). An iterator, so each
/// pass's loop body is inlined once, not a call per run.
fn runs(row: &[u64]) -> RowRuns<'_> {
    RowRuns {
        row,
        next: 0,
        m: 0,
        open: None,
    }
}

/// See [`runs`].
struct RowRuns<'a> {
    row: &'a [u64],
    /// The next word to load; `m` holds what is left of the one before.
    next: usize,
    m: u64,
    /// The first column of a run that reached the end of the last word.
    open: Option<usize>,
}

impl Iterator for RowRuns<'_> {
    type Item = (usize, usize);

    #[inline]
    fn next(&mut self) -> Option<(usize, usize)> {
        loop {
            if self.m == 0 {
                let Some(&w) = self.row.get(self.next) else {
                    // The row's end closes an open run.
                    return self.open.take().map(|a| (a, 64 * self.row.len()));
                };
                let base = 64 * self.next;
                self.next += 1;
                self.m = w;
                if let Some(a) = self.open {
                    // The open run goes on through this word's low ones.
                    let ones = (!w).trailing_zeros();
                    if ones == 64 {
                        self.m = 0;
                        continue;
                    }
                    self.open = None;
                    self.m &= !low_bits(ones as usize);
                    return Some((a, base + ones as usize));
                }
                continue;
            }
            let base = 64 * (self.next - 1);
            let m = self.m;
            let s = m.trailing_zeros();
            let end = s + (!(m >> s)).trailing_zeros().min(64 - s);
            if end == 64 {
                self.open = Some(base + s as usize);
                self.m = 0;
                continue;
            }
            self.m = m & !low_bits(end as usize);
            return Some((base + s as usize, base + end as usize));
        }
    }
}

/// Calls `f(c)` with the first column of each run of set bits of `row`
/// within columns `lo..=hi` (a run entering the range at `lo` counts from
/// `lo`).
#[inline]
fn for_each_run_in(row: &[u64], lo: usize, hi: usize, mut f: impl FnMut(usize)) {
    let mut carry = 0u64;
    for j in lo / 64..=hi / 64 {
        let Some(&w) = row.get(j) else {
            break;
        };
        let a = if j == lo / 64 { (lo % 64) as u32 } else { 0 };
        let e = if j == hi / 64 {
            (hi % 64) as u32 + 1
        } else {
            64
        };
        let m = w & low_bits(e as usize) & !low_bits(a as usize);
        let mut starts = m & !((m << 1) | carry);
        carry = m >> 63;
        while starts != 0 {
            f(64 * j + starts.trailing_zeros() as usize);
            starts &= starts - 1;
        }
    }
}

/// Labels the particle pixels of the first `rows` rows of the workspace:
/// the set bits of `ws.masks[words..2·words]` (`words` = `rows` × words
/// per row), as the segmentation leaves them. Writes `labels` (region
/// index + 1, 0 for none) and the region table, the regions in the raster
/// order of their first pixel; returns the counts. Only particle pixels
/// are visited, so the cost follows them, not the frame. Run by run (a row's consecutive particle pixels share their
/// neighbours' unions, so a run costs about what a pixel did); when the
/// runs could fill the provisional table, pixel by pixel, whose table
/// overflow rules the module docs state. Both give the same labels,
/// regions and roots: a run makes a provisional label exactly when its
/// first pixel would (no particle above it, up-left or up-right), and
/// every set's root is its smallest label either way.
pub(crate) fn label(ws: &mut Workspace<'_>, rows: u16) -> LabelStats {
    let wpr = crate::plane::words_per_row(ws.sizes.width);
    let words = usize::from(rows) * wpr;
    let cap_prov = ws
        .parents
        .len()
        .saturating_sub(1)
        .min(usize::from(NONE) - 1);
    let part = &ws.masks[words..2 * words];
    let mut runs = 0usize;
    for (w, &m) in part.iter().enumerate() {
        let carry = if w % wpr == 0 { 0 } else { part[w - 1] >> 63 };
        runs += (m & !((m << 1) | carry)).count_ones() as usize;
    }
    if runs > cap_prov {
        return label_pixels(ws, rows);
    }
    label_runs(ws, rows)
}

/// [`label`] run by run; the caller has checked that the runs cannot
/// fill the provisional table.
fn label_runs(ws: &mut Workspace<'_>, rows: u16) -> LabelStats {
    let width = usize::from(ws.sizes.width);
    let wpr = crate::plane::words_per_row(ws.sizes.width);
    let px = width * usize::from(rows);
    let words = usize::from(rows) * wpr;
    let mut stats = LabelStats::default();
    let labels = &mut ws.labels[..px];
    labels.fill(0);
    let part = &ws.masks[words..2 * words];
    let parents = &mut *ws.parents;
    let mut next: u16 = 0;
    // Pass 1: provisional labels, unions with the runs above that touch
    // a run (8-connectivity: columns a − 1 ..= e).
    for r in 0..usize::from(rows) {
        let row = &part[r * wpr..(r + 1) * wpr];
        let above = r.checked_sub(1).map(|u| &part[u * wpr..(u + 1) * wpr]);
        for (a, e) in runs(row) {
            let (lo, hi) = (a.saturating_sub(1), e.min(width - 1));
            let mut root = 0u16;
            let mut first_touches = false;
            if let Some(up) = above {
                let up_labels = (r - 1) * width;
                for_each_run_in(up, lo, hi, |c| {
                    let rt = find(parents, labels[up_labels + c]);
                    root = if root == 0 { rt } else { root.min(rt) };
                    first_touches |= c <= a + 1;
                });
                if root != 0 {
                    for_each_run_in(up, lo, hi, |c| {
                        let rt = find(parents, labels[up_labels + c]);
                        if rt != root {
                            parents[usize::from(rt)] = root;
                        }
                    });
                }
            }
            if !first_touches {
                // The run's first pixel starts a provisional label; the
                // later pixels join it to the runs above (whose root is
                // smaller), as they would one by one.
                next += 1;
                parents[usize::from(next)] = next;
                if root == 0 {
                    root = next;
                } else {
                    parents[usize::from(next)] = root;
                }
            }
            labels[r * width + a..r * width + e].fill(root);
        }
    }
    flatten(parents, next);
    // Pass 2: one region per root, with size and bounding box.
    let mut n = 0usize;
    let regions = &mut *ws.regions;
    for r in 0..usize::from(rows) {
        let row = &part[r * wpr..(r + 1) * wpr];
        for (a, e) in runs(row) {
            let Some(root) = root_of(parents, labels[r * width + a]) else {
                continue;
            };
            add_run(regions, &mut n, parents, &mut stats, root, (r, a, e));
        }
    }
    let kept = drop_noise(regions, n, parents, &mut stats);
    // Pass 3: final labels.
    for r in 0..usize::from(rows) {
        let row = &part[r * wpr..(r + 1) * wpr];
        for (a, e) in runs(row) {
            if let Some(root) = root_of(parents, labels[r * width + a]) {
                let id = parents[usize::from(root)] & !ASSIGNED;
                labels[r * width + a..r * width + e].fill(if id == NONE { 0 } else { id + 1 });
            }
        }
    }
    stats.regions = kept as u32;
    stats
}

/// Points every provisional label `1..=next` at its root (roots are
/// smaller, so done first).
fn flatten(parents: &mut [u16], next: u16) {
    for l in 1..=next {
        let p = parents[usize::from(l)];
        parents[usize::from(l)] = parents[usize::from(p)];
    }
}

/// Pass 2 of both labellings: the pixels `a..e` of row `r`, of the set
/// whose root is `root`, join its region — a new one (the next of the
/// first `n`) when the root has none yet and the table has room, none
/// (counted) when it is full.
fn add_run(
    regions: &mut [Region],
    n: &mut usize,
    parents: &mut [u16],
    stats: &mut LabelStats,
    root: u16,
    (r, a, e): (usize, usize, usize),
) {
    let p = parents[usize::from(root)];
    let id = if p & ASSIGNED != 0 {
        p & !ASSIGNED
    } else if *n < regions.len().min(usize::from(NONE) - 1) {
        regions[*n] = Region {
            root,
            row0: u16::MAX,
            col0: u16::MAX,
            ..Region::default()
        };
        parents[usize::from(root)] = ASSIGNED | *n as u16;
        *n += 1;
        (*n - 1) as u16
    } else {
        parents[usize::from(root)] = ASSIGNED | NONE;
        stats.overflow_regions += 1;
        NONE
    };
    if let Some(reg) = regions.get_mut(usize::from(id)).filter(|_| id != NONE) {
        reg.pixels += (e - a) as u32;
        reg.row0 = reg.row0.min(r as u16);
        reg.row1 = reg.row1.max(r as u16 + 1);
        reg.col0 = reg.col0.min(a as u16);
        reg.col1 = reg.col1.max(e as u16);
    }
}

/// Drops the noise regions of the first `n`, compacts the table and
/// points the roots at the new indices; returns the regions kept.
fn drop_noise(
    regions: &mut [Region],
    n: usize,
    parents: &mut [u16],
    stats: &mut LabelStats,
) -> usize {
    let mut kept = 0usize;
    for j in 0..n {
        let reg = regions[j];
        if reg.pixels >= MIN_REGION_PIXELS {
            regions[kept] = reg;
            parents[usize::from(reg.root)] = ASSIGNED | kept as u16;
            kept += 1;
        } else {
            parents[usize::from(reg.root)] = ASSIGNED | NONE;
            stats.noise_regions += 1;
        }
    }
    kept
}

/// [`label`] pixel by pixel, with the provisional table's overflow rule:
/// a pixel that needs a new label when the table is full stays background
/// and is counted.
fn label_pixels(ws: &mut Workspace<'_>, rows: u16) -> LabelStats {
    let width = usize::from(ws.sizes.width);
    let wpr = crate::plane::words_per_row(ws.sizes.width);
    let px = width * usize::from(rows);
    let words = usize::from(rows) * wpr;
    let cap_prov = ws
        .parents
        .len()
        .saturating_sub(1)
        .min(usize::from(NONE) - 1) as u16;
    let mut stats = LabelStats::default();
    let labels = &mut ws.labels[..px];
    labels.fill(0);
    let part = &ws.masks[words..2 * words];
    let parents = &mut *ws.parents;
    let mut next: u16 = 0;
    // Pass 1: provisional labels and unions with the W, NW, N, NE neighbours.
    for_each_bit(part, wpr, width, |i| {
        let (r, c) = (i / width, i % width);
        let mut root = 0u16;
        let mut neighbours = [0u16; 4];
        if c > 0 {
            neighbours[0] = labels[i - 1];
        }
        if r > 0 {
            let up = i - width;
            if c > 0 {
                neighbours[1] = labels[up - 1];
            }
            neighbours[2] = labels[up];
            if c + 1 < width {
                neighbours[3] = labels[up + 1];
            }
        }
        for &nb in neighbours.iter().filter(|&&l| l != 0) {
            let rt = find(parents, nb);
            root = if root == 0 { rt } else { root.min(rt) };
        }
        if root == 0 {
            if next < cap_prov {
                next += 1;
                parents[usize::from(next)] = next;
                root = next;
            } else {
                stats.dropped_pixels += 1;
            }
        } else {
            for &nb in neighbours.iter().filter(|&&l| l != 0) {
                let rt = find(parents, nb);
                if rt != root {
                    parents[usize::from(rt)] = root;
                }
            }
        }
        labels[i] = root;
    });
    flatten(parents, next);
    // Pass 2: one region per root, with size and bounding box.
    let mut n = 0usize;
    let regions = &mut *ws.regions;
    for_each_bit(part, wpr, width, |i| {
        let Some(root) = root_of(parents, labels[i]) else {
            return;
        };
        let (r, c) = (i / width, i % width);
        add_run(regions, &mut n, parents, &mut stats, root, (r, c, c + 1));
    });
    let kept = drop_noise(regions, n, parents, &mut stats);
    // Pass 3: final labels.
    for_each_bit(part, wpr, width, |i| {
        let Some(root) = root_of(parents, labels[i]) else {
            return;
        };
        let id = parents[usize::from(root)] & !ASSIGNED;
        labels[i] = if id == NONE { 0 } else { id + 1 };
    });
    stats.regions = kept as u32;
    stats
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::buffers::WorkspaceBuf;
    use crate::state::WorkspaceSizes;

    /// Labels `bits` (row-major, `width` per row) both ways with room for
    /// `regions` regions and `prov` provisional labels; returns each way's
    /// labels, regions and stats.
    fn both(
        bits: &[bool],
        width: u16,
        rows: u16,
        regions: u16,
        prov: u16,
    ) -> [(Vec<u16>, Vec<Region>, LabelStats); 2] {
        let sizes = WorkspaceSizes {
            max_regions: regions,
            max_provisional: prov,
            ..WorkspaceSizes::for_strip(width, rows)
        };
        let wpr = crate::plane::words_per_row(width);
        let words = usize::from(rows) * wpr;
        [true, false].map(|runs| {
            let mut buf = WorkspaceBuf::new(sizes);
            let mut ws = buf.workspace().unwrap();
            for (i, _) in bits.iter().enumerate().filter(|(_, &b)| b) {
                let (r, c) = (i / usize::from(width), i % usize::from(width));
                ws.masks[words + r * wpr + c / 64] |= 1 << (c % 64);
            }
            let stats = if runs {
                label(&mut ws, rows)
            } else {
                label_pixels(&mut ws, rows)
            };
            let px = usize::from(width) * usize::from(rows);
            let n = stats.regions as usize;
            (ws.labels[..px].to_vec(), ws.regions[..n].to_vec(), stats)
        })
    }

    /// Run by run equals pixel by pixel (labels, regions with their
    /// roots, counts) on random masks of every density, across word
    /// edges, with full region tables and provisional tables that the
    /// runs could fill (then the pixel rule runs, and drops pixels).
    #[test]
    fn runs_label_as_pixels_do() {
        let mut rnd = crate::testing::rng(0x853c_49e6_748f_ea9bu64);
        let mut dropped = 0;
        for case in 0..600 {
            let width = [1u16, 5, 63, 64, 65, 127, 128, 129, 200][case % 9];
            let rows = 1 + rnd(24) as u16;
            let density = [5u64, 20, 45, 70, 95][case / 9 % 5];
            let bits: Vec<bool> = (0..usize::from(width) * usize::from(rows))
                .map(|_| rnd(100) < density)
                .collect();
            let regions = [16u16, 2, 5000][case % 3];
            let prov = [32766u16, 64, 3][case / 3 % 3];
            let [a, b] = both(&bits, width, rows, regions, prov);
            assert_eq!(a, b, "case {case}: {width}x{rows}, density {density}");
            dropped += a.2.dropped_pixels;
        }
        assert!(dropped > 0, "the fallback was never exercised");
    }

    /// Shapes with a known answer: a diagonal chain is one region
    /// (8-connectivity), a U joins at its bottom, pairs are noise, and a
    /// run crossing a word edge is one run.
    #[test]
    fn known_shapes() {
        let width = 130u16;
        let rows = 6u16;
        let mut bits = vec![false; usize::from(width) * usize::from(rows)];
        let mut set = |r: usize, c: usize| bits[r * usize::from(width) + c] = true;
        for i in 0..4 {
            set(i, 10 + i); // diagonal chain, 4 px
        }
        for r in 0..3 {
            set(r, 30);
            set(r, 34); // the U's arms
        }
        for c in 30..=34 {
            set(3, c); // its bottom
        }
        set(5, 50);
        set(5, 51); // noise pair
        for c in 60..=70 {
            set(5, c); // across the word edge at 64
        }
        let [a, b] = both(&bits, width, rows, 16, 100);
        assert_eq!(a, b);
        let (labels, regions, stats) = a;
        assert_eq!(stats.regions, 3);
        assert_eq!(stats.noise_regions, 1);
        assert_eq!(
            regions.iter().map(|r| r.pixels).collect::<Vec<_>>(),
            vec![4, 11, 11]
        );
        assert_eq!(
            (regions[1].col0, regions[1].col1, regions[1].row1),
            (30, 35, 4)
        );
        assert_eq!(labels[3 * usize::from(width) + 13], 1);
        assert_eq!(labels[5 * usize::from(width) + 64], 3);
        assert_eq!(labels[5 * usize::from(width) + 50], 0);
    }
}
