//! The `f64` reference of the core's algorithm (docs/spec.md §5), written for
//! clarity rather than speed: spikes unpacked to one byte per pixel and tick,
//! counts by plain loops, tile medians by sorting, backgrounds, the particle
//! test and SNR in `f64` (with the square root), regions by flood fill, rings
//! by looking at each pixel's 5×5 neighbourhood.
//!
//! It makes the same integer decisions as `spiv-core` (counts, classes,
//! regions, windows) and computes intensities in `f64`.
//!
//! **Tolerance** (held by `host/tests/reference_parity.rs` on realistic
//! scenes, whole bands, strips with margins and the banded dwell-cap path):
//! classes, saturation times, labels and region windows n* identical for
//! every pixel; every output gray level within 1 level of the reference's
//! unrounded value (the core rounds exact rationals once, so the difference
//! is at most ½ level plus `f64` rounding).

pub mod light;
pub mod motion;

use spiv_core::Params;

/// A spike recording unpacked: `data[(t·rows + r)·width + c]` is 0 or 1,
/// stored row order, ticks `first..first + ticks`.
#[derive(Debug, Clone)]
pub struct SpikeVolume {
    /// Width, px.
    pub width: usize,
    /// Rows, px.
    pub rows: usize,
    /// Tick of the first plane.
    pub first: u32,
    /// Planes held.
    pub ticks: usize,
    /// One byte per pixel and tick.
    pub data: Vec<u8>,
}

impl SpikeVolume {
    /// Unpacks Vidar planes (LSB first, stored order) given back to back.
    pub fn from_packed(packed: &[u8], width: usize, rows: usize, first: u32) -> SpikeVolume {
        let plane = width * rows / 8;
        let ticks = packed.len().checked_div(plane).unwrap_or(0);
        let mut data = vec![0u8; ticks * width * rows];
        for (t, bytes) in packed.chunks_exact(plane).enumerate() {
            for p in 0..width * rows {
                data[t * width * rows + p] = (bytes[p / 8] >> (p % 8)) & 1;
            }
        }
        SpikeVolume {
            width,
            rows,
            first,
            ticks,
            data,
        }
    }

    fn spike(&self, t: i64, r: usize, c: usize) -> u32 {
        let i = t - i64::from(self.first);
        if i < 0 || i as usize >= self.ticks {
            return 0;
        }
        u32::from(self.data[(i as usize * self.rows + r) * self.width + c])
    }

    /// The window of `n` ticks centred on `k`, clipped to the ticks held:
    /// `(start, real length)`.
    pub fn window(&self, k: u32, n: u16) -> (i64, u32) {
        let start = i64::from(k) - i64::from(n / 2);
        let lo = start.max(i64::from(self.first));
        let hi = (start + i64::from(n)).min(i64::from(self.first) + self.ticks as i64);
        (lo, (hi - lo).max(0) as u32)
    }

    /// Rows `s0..s1` alone (clamped to the volume), and the first row kept.
    fn rows_of(&self, s0: usize, s1: usize) -> (SpikeVolume, usize) {
        let s1 = s1.min(self.rows);
        let s0 = s0.min(s1);
        let w = self.width;
        let plane = self.rows * w;
        let mut data = Vec::with_capacity(self.ticks * (s1 - s0) * w);
        for t in 0..self.ticks {
            data.extend_from_slice(&self.data[t * plane + s0 * w..t * plane + s1 * w]);
        }
        let strip = SpikeVolume {
            width: w,
            rows: s1 - s0,
            first: self.first,
            ticks: self.ticks,
            data,
        };
        (strip, s0)
    }

    /// Spikes of pixel (r, c) in the window of `n` ticks centred on `k`.
    pub fn count(&self, k: u32, n: u16, r: usize, c: usize) -> u32 {
        let (s, len) = self.window(k, n);
        (s..s + i64::from(len)).map(|t| self.spike(t, r, c)).sum()
    }
}

/// What the reference says about one pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefClass {
    /// Particle found at this level index.
    Particle(u8),
    /// Background decided at this level index (saturated, or the last level).
    Background(u8),
}

/// The reference frame.
#[derive(Debug, Clone)]
pub struct RefFrame {
    /// Class per pixel.
    pub class: Vec<RefClass>,
    /// Region index + 1 per pixel (0: none).
    pub labels: Vec<u32>,
    /// n* per region.
    pub n_star: Vec<u16>,
    /// Gray level per pixel, unrounded.
    pub gray: Vec<f64>,
}

fn params_f64(p: &Params) -> (f64, f64, f64, f64) {
    (
        p.k_sig.to_num::<f64>(),
        p.beta.to_num::<f64>(),
        p.sigma_fpn.to_num::<f64>(),
        f64::from(p.electrons_per_spike),
    )
}

/// Count noise of an integrate-and-fire pixel with mean count `b`.
pub fn count_variance(b: f64, sigma_fpn: f64, g: f64) -> f64 {
    0.25 + (sigma_fpn * b).powi(2) + b / g
}

/// Count noise of a motion-compensated count with mean `b` that sums the
/// spikes of `segs` pixels along the path (docs/spec.md §5's pixel noise per
/// segment: a segment of mean μ = b/S varies by {μ}(1 − {μ}) — μ(1 − μ)
/// when dim, 1/6 on average when bright — never below one pixel's 1/4 in
/// all; fixed-pattern noise averages over the S thresholds). One segment
/// is [`count_variance`].
pub fn compensated_variance(b: f64, segs: u32, sigma_fpn: f64, g: f64) -> f64 {
    if segs <= 1 {
        return count_variance(b, sigma_fpn, g);
    }
    let s = f64::from(segs);
    let mu = b / s;
    let per_segment = if mu < 0.5 { mu * (1.0 - mu) } else { 1.0 };
    let quantisation = (s * per_segment.min(1.0 / 6.0)).max(0.25);
    quantisation + (sigma_fpn * b).powi(2) / s + b / g
}

/// The segmentation windows n0, 2n0, …, n_max.
pub fn levels(p: &Params) -> Vec<u16> {
    let mut v = Vec::new();
    let mut n = u32::from(p.n0);
    while n < u32::from(p.n_max) {
        v.push(n as u16);
        n *= 2;
    }
    v.push(p.n_max);
    v
}

/// The adaptive frame at tick `k` (full-scale `fs`), the way docs/spec.md §5 reads.
pub fn adaptive_frame(vol: &SpikeVolume, k: u32, p: &Params, fs: f64) -> RefFrame {
    adaptive_rows(vol, k, p, fs, (0, vol.rows))
}

/// The adaptive frame computed on rows `s0..s1` of `vol` alone, as a strip
/// of the core computes them (its rows and their margins): regions, rings
/// and tile medians see only these rows, and the 16×16 tiles stay aligned
/// to row 0 of `vol` (a tile cut by the strip's edge has only its rows in
/// it; bilinear weights are constant beyond the strip's first and last
/// tile). The frame returned holds the `s1 − s0` rows.
pub fn adaptive_rows(
    vol: &SpikeVolume,
    k: u32,
    p: &Params,
    fs: f64,
    (s0, s1): (usize, usize),
) -> RefFrame {
    let (strip, s0) = vol.rows_of(s0, s1);
    strip_frame(&strip, s0, k, p, fs, None)
}

/// [`adaptive_rows`] motion-compensated (`spiv_core::reconstruct_compensated`):
/// particles are segmented and integrated on counts compensated for the
/// velocity of each pixel's band row and tile column (`grid`, 1/4096 px
/// per tick; see [`motion::compensated_count`], over the whole band),
/// saturation and background on plain counts.
pub fn adaptive_rows_compensated(
    vol: &SpikeVolume,
    k: u32,
    p: &Params,
    fs: f64,
    (s0, s1): (usize, usize),
    grid: motion::Grid<'_>,
) -> RefFrame {
    let (strip, s0) = vol.rows_of(s0, s1);
    strip_frame(&strip, s0, k, p, fs, Some((vol, grid)))
}

/// The band and its velocity grid, for a motion-compensated strip.
type Compensation<'a> = Option<(&'a SpikeVolume, motion::Grid<'a>)>;

/// One strip's inputs: the strip, where it sits in the band, the frame's
/// tick and parameters, and the compensation if any.
struct Strip<'a> {
    vol: &'a SpikeVolume,
    row0: usize,
    k: u32,
    p: &'a Params,
    comp: Compensation<'a>,
}

/// Per pixel: the count, window and real window length that decided it.
type Decided = Vec<(u32, u16, u32)>;

impl Strip<'_> {
    /// The velocity at strip row `r`, column `c` (1/4096 px per tick),
    /// when compensated.
    fn velocity(&self, r: usize, c: usize) -> Option<(&SpikeVolume, (i16, i16))> {
        self.comp
            .map(|(band, grid)| (band, grid.at(self.row0 + r, c)))
    }

    /// The count a particle is judged and integrated by: plain, or
    /// compensated for its pixel's motion over the whole band.
    fn pcount(&self, n: u16, r: usize, c: usize) -> u32 {
        match self.velocity(r, c) {
            None => self.vol.count(self.k, n, r, c),
            Some((band, v)) => motion::compensated_count(band, self.k, n, (self.row0 + r, c), v),
        }
    }

    /// Tiles `y0..=y1` of the band (16 rows each from band row 0) that meet
    /// the strip.
    fn tile_rows(&self) -> (usize, usize) {
        let h = self.vol.rows;
        (self.row0 / 16, (self.row0 + h.max(1) - 1) / 16)
    }

    /// The lower median of the non-particle `tested` counts of each 16×16
    /// tile (its rows inside the strip; all its counts when every pixel is
    /// a particle), `ty` tile rows of `tx`.
    fn tile_medians(&self, tested: &[u32], class: &[Option<RefClass>]) -> Vec<f64> {
        let (w, h) = (self.vol.width, self.vol.rows);
        let (tile_y0, tile_y1) = self.tile_rows();
        let (tx, ty) = (w.div_ceil(16), tile_y1 - tile_y0 + 1);
        let mut med = vec![0.0f64; tx * ty];
        for a in 0..ty {
            let band_r0 = 16 * (a + tile_y0);
            let lo = band_r0.max(self.row0) - self.row0;
            let hi = (band_r0 + 16).min(self.row0 + h) - self.row0;
            for b in 0..tx {
                let mut all = Vec::new();
                let mut bg = Vec::new();
                for r in lo..hi {
                    for c in 16 * b..(16 * b + 16).min(w) {
                        all.push(tested[r * w + c]);
                        if !matches!(class[r * w + c], Some(RefClass::Particle(_))) {
                            bg.push(tested[r * w + c]);
                        }
                    }
                }
                let mut v = if bg.is_empty() { all } else { bg };
                v.sort_unstable();
                med[a * tx + b] = f64::from(v[(v.len() - 1) / 2]);
            }
        }
        med
    }

    /// The background of pixel (r, c) from the tile medians: bilinear
    /// between tile centres (16·t + 8), constant beyond the edges.
    fn background(&self, med: &[f64], r: usize, c: usize) -> f64 {
        let (tile_y0, tile_y1) = self.tile_rows();
        let (tx, ty) = (self.vol.width.div_ceil(16), tile_y1 - tile_y0 + 1);
        // `first` is the band tile index of local tile 0.
        let interp = |pos: f64, first: usize, tiles: usize| -> (usize, usize, f64) {
            let u = (pos - 8.0) / 16.0;
            let t0 = u.floor();
            let (lo, hi) = (first as f64, (first + tiles - 1) as f64);
            let cl = |t: f64| (t.max(lo).min(hi) - lo) as usize;
            (cl(t0), cl(t0 + 1.0), u - t0)
        };
        let (a0, a1, fy) = interp((self.row0 + r) as f64 + 0.5, tile_y0, ty);
        let (b0, b1, fx) = interp(c as f64 + 0.5, 0, tx);
        let m = |a: usize, b: usize| med[a * tx + b];
        (1.0 - fy) * ((1.0 - fx) * m(a0, b0) + fx * m(a0, b1))
            + fy * ((1.0 - fx) * m(a1, b0) + fx * m(a1, b1))
    }

    /// Segmentation over the levels n0, 2n0, …, n_max: each undecided
    /// pixel is a particle when its tested count stands out of the
    /// background by k_σ, background when saturated or at the last level.
    fn classify(&self) -> (Vec<RefClass>, Decided) {
        let (w, h) = (self.vol.width, self.vol.rows);
        let (k_sig, _, sigma, g) = params_f64(self.p);
        let levels = levels(self.p);
        let mut class: Vec<Option<RefClass>> = vec![None; w * h];
        let mut decided = vec![(0u32, 0u16, 0u32); w * h];
        for (j, &n) in levels.iter().enumerate() {
            let (_, len) = self.vol.window(self.k, n);
            let counts: Vec<u32> = (0..w * h)
                .map(|i| self.vol.count(self.k, n, i / w, i % w))
                .collect();
            let tested: Vec<u32> = match self.comp {
                None => counts.clone(),
                Some(_) => (0..w * h).map(|i| self.pcount(n, i / w, i % w)).collect(),
            };
            let med = self.tile_medians(&tested, &class);
            let last = j + 1 == levels.len();
            for r in 0..h {
                // Compensated over a path of at least MIN_TRAVEL px, a
                // particle must also stand out against the pixel's own
                // plain count (static light gives the same count either
                // way); a compensated count's noise is that of the pixels
                // it sums.
                for c in 0..w {
                    let (floor, segs) = self.velocity(r, c).map_or((false, 1), |(band, v)| {
                        (
                            motion::travel(band, self.k, n, v)
                                >= i64::from(spiv_core::motion::MIN_TRAVEL),
                            motion::positions(band, self.k, n, v),
                        )
                    });
                    let i = r * w + c;
                    if class[i].is_some() {
                        continue;
                    }
                    let cnt = f64::from(counts[i]);
                    let tc = f64::from(tested[i]);
                    let bgd = self.background(&med, r, c);
                    let bgd = if floor { bgd.max(cnt) } else { bgd };
                    let particle = tc > bgd
                        && (tc - bgd).powi(2)
                            > k_sig * k_sig * compensated_variance(bgd, segs, sigma, g);
                    let saturated =
                        len > 0 && cnt / f64::from(len) >= f64::from(self.p.n_fs) / f64::from(n);
                    if particle {
                        class[i] = Some(RefClass::Particle(j as u8));
                        decided[i] = (tested[i], n, len);
                    } else if saturated || last {
                        class[i] = Some(RefClass::Background(j as u8));
                        decided[i] = (counts[i], n, len);
                    }
                }
            }
        }
        let class = class
            .into_iter()
            .map(|c| c.unwrap_or(RefClass::Background(0)))
            .collect();
        (class, decided)
    }

    /// Particle pixels that no region took (noise regions under 3 px) are
    /// background: their segmentation stopped at detection, so they get
    /// their own saturation time here — the first level whose window rate
    /// reaches N_fs per n, else n_max — and are suppressed like background.
    fn saturate_noise(&self, class: &[RefClass], labels: &[u32], decided: &mut Decided) {
        let w = self.vol.width;
        let levels = levels(self.p);
        for (i, d) in decided.iter_mut().enumerate() {
            if labels[i] != 0 || !matches!(class[i], RefClass::Particle(_)) {
                continue;
            }
            for (j, &n) in levels.iter().enumerate() {
                let (_, len) = self.vol.window(self.k, n);
                let cnt = self.vol.count(self.k, n, i / w, i % w);
                let saturated = len > 0
                    && f64::from(cnt) / f64::from(len) >= f64::from(self.p.n_fs) / f64::from(n);
                if saturated || j + 1 == levels.len() {
                    *d = (cnt, n, len);
                    break;
                }
            }
        }
    }

    /// The background ring of region `id`: the pixels of no region within
    /// 2 px (Chebyshev) of one of its pixels `pix`.
    fn ring(&self, labels: &[u32], id: u32, pix: &[usize]) -> Vec<usize> {
        let (w, h) = (self.vol.width, self.vol.rows);
        let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
        for &i in pix {
            r0 = r0.min(i / w);
            r1 = r1.max(i / w);
            c0 = c0.min(i % w);
            c1 = c1.max(i % w);
        }
        let mut ring = Vec::new();
        for r in r0.saturating_sub(2)..=(r1 + 2).min(h - 1) {
            for c in c0.saturating_sub(2)..=(c1 + 2).min(w - 1) {
                if labels[r * w + c] != 0 {
                    continue;
                }
                let near = (r.saturating_sub(2)..=(r + 2).min(h - 1)).any(|rr| {
                    (c.saturating_sub(2)..=(c + 2).min(w - 1)).any(|cc| labels[rr * w + cc] == id)
                });
                if near {
                    ring.push(r * w + c);
                }
            }
        }
        ring
    }

    /// The adaptive window n* of region `pix` against its `ring`: the best
    /// SNR over n = 1, 2, 4, …, n_max, then every n within a factor of 2
    /// of that (the first on a tie).
    fn region_window(&self, pix: &[usize], ring: &[usize]) -> u16 {
        let (_, _, sigma, g) = params_f64(self.p);
        let snr = |n: u16| {
            let (s, b) = (self.mean(pix, n), self.mean(ring, n));
            (s - b) / count_variance(b, sigma, g).sqrt()
        };
        let mut best = (1u16, snr(1));
        let mut n = 1u16;
        while n < self.p.n_max {
            n = (n * 2).min(self.p.n_max);
            let v = snr(n);
            if v > best.1 {
                best = (n, v);
            }
        }
        let lo = (best.0 / 2).max(1);
        let hi = (best.0 * 2).min(self.p.n_max);
        let mut star = (lo, snr(lo));
        for m in lo + 1..=hi {
            let v = snr(m);
            if v > star.1 {
                star = (m, v);
            }
        }
        star.0
    }

    /// The mean tested count of the pixels `set` over `n` ticks (0 for
    /// none).
    fn mean(&self, set: &[usize], n: u16) -> f64 {
        let w = self.vol.width;
        if set.is_empty() {
            return 0.0;
        }
        let s: u32 = set.iter().map(|&i| self.pcount(n, i / w, i % w)).sum();
        f64::from(s) / set.len() as f64
    }

    /// The gray levels of region `pix` integrated over `n` ticks: its
    /// counts stretched from the ring's mean `b` (FS/β) to its brightest
    /// pixel (FS).
    fn region_gray(&self, pix: &[usize], b: f64, n: u16, fs: f64, gray: &mut [f64]) {
        let w = self.vol.width;
        let (_, beta, _, _) = params_f64(self.p);
        let cmax = pix
            .iter()
            .map(|&i| self.pcount(n, i / w, i % w))
            .max()
            .unwrap_or(0);
        let lo_gray = fs / beta;
        for &i in pix {
            let c = f64::from(self.pcount(n, i / w, i % w));
            let den = f64::from(cmax) - b;
            gray[i] = if den <= 0.0 {
                lo_gray.min(fs)
            } else {
                let x = (c - b) / den;
                (lo_gray + x * (fs - lo_gray)).clamp(0.0, fs)
            };
        }
    }
}

/// Regions of `class`'s particle pixels: 8-connected flood fill in raster
/// order; under 3 px is noise. Returns the label (region index + 1, 0 for
/// none) of each pixel and each region's pixels.
fn regions(class: &[RefClass], w: usize, h: usize) -> (Vec<u32>, Vec<Vec<usize>>) {
    let mut labels = vec![0u32; w * h];
    let mut regions: Vec<Vec<usize>> = Vec::new();
    let mut seen = vec![false; w * h];
    for start in 0..w * h {
        if seen[start] || !matches!(class[start], RefClass::Particle(_)) {
            continue;
        }
        let mut stack = vec![start];
        let mut pix = Vec::new();
        seen[start] = true;
        while let Some(i) = stack.pop() {
            pix.push(i);
            let (r, c) = ((i / w) as i64, (i % w) as i64);
            for (dr, dc) in (-1..=1).flat_map(|dr| (-1..=1).map(move |dc| (dr, dc))) {
                let (rr, cc) = (r + dr, c + dc);
                if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                    continue;
                }
                let q = rr as usize * w + cc as usize;
                if !seen[q] && matches!(class[q], RefClass::Particle(_)) {
                    seen[q] = true;
                    stack.push(q);
                }
            }
        }
        if pix.len() >= 3 {
            regions.push(pix);
        }
    }
    for (id, pix) in regions.iter().enumerate() {
        for &i in pix {
            labels[i] = id as u32 + 1;
        }
    }
    (labels, regions)
}

/// The algorithm on one strip whose first row is row `row0` of the band:
/// segmentation, regions, background gray FS·(c_t/len)·t/(β·N_fs), and
/// each region integrated over its own window.
fn strip_frame(
    vol: &SpikeVolume,
    row0: usize,
    k: u32,
    p: &Params,
    fs: f64,
    comp: Compensation<'_>,
) -> RefFrame {
    let s = Strip {
        vol,
        row0,
        k,
        p,
        comp,
    };
    let (w, h) = (vol.width, vol.rows);
    let (_, beta, _, _) = params_f64(p);
    let (class, mut decided) = s.classify();
    let (labels, regions) = regions(&class, w, h);
    s.saturate_noise(&class, &labels, &mut decided);
    let mut gray: Vec<f64> = decided
        .iter()
        .map(|&(c, t, len)| {
            if len == 0 {
                0.0
            } else {
                (fs * f64::from(c) / f64::from(len) * f64::from(t) / (beta * f64::from(p.n_fs)))
                    .min(fs)
            }
        })
        .collect();
    let mut n_star = Vec::new();
    for (id, pix) in regions.iter().enumerate() {
        let ring = s.ring(&labels, id as u32 + 1, pix);
        let n = s.region_window(pix, &ring);
        n_star.push(n);
        s.region_gray(pix, s.mean(&ring, n), n, fs, &mut gray);
    }
    RefFrame {
        class,
        labels,
        n_star,
        gray,
    }
}

/// TFP in `f64`: FS·c/len.
pub fn tfp(vol: &SpikeVolume, k: u32, n: u16, fs: f64) -> Vec<f64> {
    let (_, len) = vol.window(k, n);
    (0..vol.width * vol.rows)
        .map(|i| {
            fs * f64::from(vol.count(k, n, i / vol.width, i % vol.width)) / f64::from(len.max(1))
        })
        .collect()
}
