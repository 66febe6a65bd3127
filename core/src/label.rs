//! Region labelling: particle pixels form regions by 8-connectivity
//! (two-pass union-find in a caller-supplied table); regions under 3 px are
//! noise. Bounded: when the provisional-label table or the region table is
//! full, further pixels or regions stay background, and are counted.

use crate::region::Region;
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

/// Labels the particle pixels of the first `rows` rows of the workspace:
/// the set bits of `ws.masks[words..2·words]` (`words` = `rows` × words
/// per row), as the segmentation leaves them. Writes `labels` (region
/// index + 1, 0 for none) and the region table; returns the counts. Only
/// particle pixels are visited (raster order), so the cost follows them,
/// not the frame.
pub(crate) fn label(ws: &mut Workspace<'_>, rows: u16) -> LabelStats {
    let width = usize::from(ws.sizes.width);
    let wpr = crate::plane::words_per_row(ws.sizes.width);
    let px = width * usize::from(rows);
    let words = usize::from(rows) * wpr;
    let cap_prov = ws
        .parents
        .len()
        .saturating_sub(1)
        .min(usize::from(NONE) - 1) as u16;
    let cap_regions = ws.regions.len().min(usize::from(NONE) - 1);
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
    // Flatten: every label points at its root (roots are smaller, done first).
    for l in 1..=next {
        let p = parents[usize::from(l)];
        parents[usize::from(l)] = parents[usize::from(p)];
    }
    // Pass 2: one region per root, with size and bounding box.
    let mut n = 0usize;
    let regions = &mut *ws.regions;
    for_each_bit(part, wpr, width, |i| {
        let Some(root) = root_of(parents, labels[i]) else {
            return;
        };
        let e = parents[usize::from(root)];
        let id = if e & ASSIGNED != 0 {
            e & !ASSIGNED
        } else if n < cap_regions {
            regions[n] = Region {
                root,
                row0: u16::MAX,
                col0: u16::MAX,
                ..Region::default()
            };
            parents[usize::from(root)] = ASSIGNED | n as u16;
            n += 1;
            (n - 1) as u16
        } else {
            parents[usize::from(root)] = ASSIGNED | NONE;
            stats.overflow_regions += 1;
            NONE
        };
        if let Some(reg) = regions.get_mut(usize::from(id)).filter(|_| id != NONE) {
            let (r, c) = ((i / width) as u16, (i % width) as u16);
            reg.pixels += 1;
            reg.row0 = reg.row0.min(r);
            reg.row1 = reg.row1.max(r + 1);
            reg.col0 = reg.col0.min(c);
            reg.col1 = reg.col1.max(c + 1);
        }
    });
    // Drop noise regions, compact the table, point roots at the new index.
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
