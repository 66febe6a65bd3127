//! The light a stream's static-light model ([`crate::light`]) is trained
//! on before the first plane of a recording ([`crate::pairs::PairMaker::train`]):
//! the recording's first planes, with every pixel that a particle lights
//! steadily through them trained on its surroundings' background instead.
//!
//! A sidecar that ran before the recording would have seen particles come
//! and go: a pixel's period is its background's, and a particle that
//! arrives fires it off that beat for as long as it stays (up to
//! [`crate::light::RELEARN_TICKS`]). The recording's own planes played
//! backwards and forth stand in for that light, but a particle that moves
//! less than its size over them (slow flow, a short recording) sits on
//! the same pixels through the whole stand-in: the model learns it as
//! static light, its own spikes make no events, and the innovation frames
//! show only where it went since (A and B of a rung anticorrelate, and
//! their peak lies a particle radius along the motion: slow spectral
//! turbulence on 62 planes read 0.64 px per pair as 1.1, docs/results.md).
//!
//! The background of a pixel is the largest of the spike counts'
//! grayscale openings by [`SIDE`]-pixel segments in four directions
//! ([`opening`]): a blob shorter than a segment every way (a particle,
//! however slow) goes; a glare band, a thin bright stripe or line in any
//! direction stays, edges and all. A pixel is trained on a spike train at its
//! background's rate when it fires well above that background
//! ([`above`]) in most of the recording's [`BLOCK`]-tick blocks (lit
//! steadily: a particle passing by once is light the model already
//! leaves alone) and a 4-neighbour does too (a lone bright pixel is the
//! sensor's own, static).
//!
//! Units: spike counts over the planes given; rates in spikes per tick.

use std::vec;
use std::vec::Vec;

/// Length of the segments whose openings are the background, px: longer
/// than the particles' images (2.5–6.5 px in every scene of the benches).
pub const SIDE: usize = 9;

/// Ticks per block of the steadiness test.
pub const BLOCK: usize = 8;

/// Whether a pixel that fired `count` spikes over planes whose background
/// there fired `background` fires well above it: by 2 spikes, or a quarter
/// of the background where that is more (glare pixels fire within a spike
/// or two of their background's count).
pub fn above(count: u32, background: u32) -> bool {
    count > background + (background / 4).max(2)
}

/// The planes `planes` (each `width × height` pixels packed as
/// [`crate::plane::PlaneView`] reads them) with every pixel lit steadily
/// above its background replaced by a regular train at that background's
/// rate; `None` when no pixel is (the planes serve as they are), when
/// there are fewer than two blocks of planes, or when a plane's length
/// does not match the size.
pub fn background_planes(planes: &[&[u8]], width: u16, height: u16) -> Option<Vec<Vec<u8>>> {
    let (w, h) = (usize::from(width), usize::from(height));
    let px = w * h;
    // `None` for an empty size too.
    let bytes = crate::plane::plane_bytes(width, height)?;
    let n = planes.len();
    if n < 2 * BLOCK || planes.iter().any(|p| p.len() != bytes) {
        return None;
    }
    let bit = |p: &[u8], i: usize| (p[i / 8] >> (i % 8)) & 1 == 1;
    let mut count = vec![0u32; px];
    for p in planes {
        for (i, c) in count.iter_mut().enumerate() {
            *c += u32::from(bit(p, i));
        }
    }
    let bg = opening(&count, w, h, SIDE);
    let blocks = n / BLOCK;
    // Candidates: well above the background over all the planes.
    let mut lit = vec![false; px];
    for i in 0..px {
        if !above(count[i], bg[i]) {
            continue;
        }
        // Blocks in which the pixel fired above its background's share.
        let share = f64::from(bg[i]) * BLOCK as f64 / n as f64;
        let steady = (0..blocks)
            .filter(|&b| {
                let c = planes[b * BLOCK..(b + 1) * BLOCK]
                    .iter()
                    .filter(|p| bit(p, i))
                    .count();
                c as f64 > share
            })
            .count();
        lit[i] = 4 * steady >= 3 * blocks;
    }
    let neighbour = |i: usize| {
        let (r, c) = (i / w, i % w);
        (r > 0 && lit[i - w])
            || (r + 1 < h && lit[i + w])
            || (c > 0 && lit[i - 1])
            || (c + 1 < w && lit[i + 1])
    };
    let replace: Vec<usize> = (0..px).filter(|&i| lit[i] && neighbour(i)).collect();
    if replace.is_empty() {
        return None;
    }
    let mut out: Vec<Vec<u8>> = planes.iter().map(|p| p.to_vec()).collect();
    for &i in &replace {
        let rate = f64::from(bg[i]) / n as f64;
        // A regular train at the background's rate, its phase spread over
        // the pixels (the golden ratio's fractional part times the index).
        let phase = (i as f64 * 0.618_033_988_749_894_9).fract();
        for (j, p) in out.iter_mut().enumerate() {
            let fire = ((j + 1) as f64 * rate + phase).floor() > (j as f64 * rate + phase).floor();
            if fire {
                p[i / 8] |= 1 << (i % 8);
            } else {
                p[i / 8] &= !(1 << (i % 8));
            }
        }
    }
    Some(out)
}

/// The background of `v` (`w × h`, row-major): the largest of its
/// grayscale openings by line segments of `side` pixels along the rows,
/// the columns and both diagonals. Each opening (the minimum along the
/// segment around a pixel, clipped at the edges, then the maximum of that
/// along the same segment) removes what is shorter than the segment along
/// it; their largest keeps a line or band of any direction however thin
/// (a glare stripe, an interface), and removes a blob shorter than the
/// segment every way (a particle). Hand-written: eight passes of a
/// sliding minimum or maximum on the core's own counts.
pub fn opening(v: &[u32], w: usize, h: usize, side: usize) -> Vec<u32> {
    let r = side / 2;
    let mut out = vec![0u32; v.len()];
    for dir in [(1, 0), (0, 1), (1, 1), (1, -1)] {
        let eroded = pass(v, (w, h), r, dir, u32::min);
        let opened = pass(&eroded, (w, h), r, dir, u32::max);
        for (o, x) in out.iter_mut().zip(opened) {
            *o = (*o).max(x);
        }
    }
    out
}

/// One pass of `f` over the pixels within `±r` steps of `(dx, dy)` around
/// each pixel (those inside the image).
fn pass(
    v: &[u32],
    (w, h): (usize, usize),
    r: usize,
    (dx, dy): (i64, i64),
    f: fn(u32, u32) -> u32,
) -> Vec<u32> {
    let (wi, hi, ri) = (w as i64, h as i64, r as i64);
    let mut out = vec![0u32; v.len()];
    for y in 0..hi {
        for x in 0..wi {
            out[(y * wi + x) as usize] = (-ri..=ri)
                .map(|k| (x + k * dx, y + k * dy))
                .filter(|&(a, b)| (0..wi).contains(&a) && (0..hi).contains(&b))
                .map(|(a, b)| v[(b * wi + a) as usize])
                .reduce(f)
                .unwrap_or(0);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bright 3×3 blob goes in the opening by 9-pixel segments; a band
    /// 12 pixels wide stays, edges and all, and so do stripes 2 pixels
    /// thin along a row and along a diagonal.
    #[test]
    fn the_opening_removes_blobs_and_keeps_bands() {
        let (w, h) = (48, 48);
        let mut v = vec![1u32; w * h];
        for y in 10..13 {
            for x in 10..13 {
                v[y * w + x] = 50;
            }
        }
        for y in 34..46 {
            for x in 0..w {
                v[y * w + x] = 30;
            }
        }
        for x in 0..w {
            v[4 * w + x] = 40;
            v[5 * w + x] = 40;
        }
        for k in 0..10 {
            v[(16 + k) * w + (24 + k)] = 60;
            v[(16 + k) * w + (25 + k)] = 60;
        }
        let o = opening(&v, w, h, SIDE);
        assert_eq!(o[11 * w + 11], 1);
        assert!((0..w).all(|x| o[4 * w + x] == 40 && o[5 * w + x] == 40));
        assert!((0..10).all(|k| o[(16 + k) * w + (24 + k)] == 60));
        assert!((34..46).all(|y| (0..w).all(|x| o[y * w + x] == 30)));
        assert!((6..14).all(|y| (0..w).all(|x| o[y * w + x] == 1)));
    }

    fn planes_of(n: usize, w: u16, h: u16, on: impl Fn(usize, usize) -> bool) -> Vec<Vec<u8>> {
        let px = usize::from(w) * usize::from(h);
        (0..n)
            .map(|t| {
                let mut p = vec![0u8; crate::plane::plane_bytes(w, h).unwrap()];
                for i in 0..px {
                    if on(t, i) {
                        p[i / 8] |= 1 << (i % 8);
                    }
                }
                p
            })
            .collect()
    }

    /// A particle that sits on a 3×3 patch through the planes (firing
    /// every 3 ticks) is trained on the dark around it; a lone hot pixel,
    /// a glare band 12 rows wide (its edges too) and a particle that
    /// passes in one block are left as they were.
    #[test]
    fn a_still_particle_is_trained_on_its_background() {
        let (w, h) = (32u16, 40u16);
        let n = 64;
        let at = |x: usize, y: usize| y * usize::from(w) + x;
        let planes = planes_of(n, w, h, |t, i| {
            let (x, y) = (i % usize::from(w), i / usize::from(w));
            let still = (4..7).contains(&x) && (4..7).contains(&y) && t % 3 == 0;
            let hot = i == at(20, 5) && t % 2 == 0;
            let glare = (20..32).contains(&y) && t % 2 == 0;
            let passing = (12..15).contains(&x) && (4..7).contains(&y) && (8..16).contains(&t);
            still || hot || glare || passing
        });
        let refs: Vec<&[u8]> = planes.iter().map(Vec::as_slice).collect();
        let out = background_planes(&refs, w, h).expect("a pixel replaced");
        let fired =
            |ps: &[Vec<u8>], i: usize| ps.iter().filter(|p| (p[i / 8] >> (i % 8)) & 1 == 1).count();
        for y in 4..7 {
            for x in 4..7 {
                assert_eq!(fired(&out, at(x, y)), 0, "the still particle at ({x}, {y})");
            }
        }
        for i in [
            at(20, 5),
            at(3, 20),
            at(3, 25),
            at(31, 31),
            at(12, 4),
            at(13, 5),
            at(0, 0),
        ] {
            assert_eq!(
                out.iter()
                    .zip(&planes)
                    .filter(|(a, b)| (a[i / 8] ^ b[i / 8]) >> (i % 8) & 1 == 1)
                    .count(),
                0,
                "pixel {i} kept"
            );
        }
        // Nothing lit steadily: the planes serve as they are.
        let dark = planes_of(n, w, h, |t, i| i == at(20, 5) && t % 2 == 0);
        let refs: Vec<&[u8]> = dark.iter().map(Vec::as_slice).collect();
        assert!(background_planes(&refs, w, h).is_none());
    }

    /// Over a background that fires, the replaced pixel fires at the
    /// background's rate, not at its own.
    #[test]
    fn the_replaced_train_fires_at_the_background_rate() {
        let (w, h) = (24u16, 24u16);
        let n = 80;
        let planes = planes_of(n, w, h, |t, i| {
            let (x, y) = (i % usize::from(w), i / usize::from(w));
            let bg = t % 10 == (i % 10);
            let still = (10..13).contains(&x) && (10..13).contains(&y) && t % 2 == 0;
            bg || still
        });
        let refs: Vec<&[u8]> = planes.iter().map(Vec::as_slice).collect();
        let out = background_planes(&refs, w, h).expect("replaced");
        let i = 11 * usize::from(w) + 11;
        let fired = out
            .iter()
            .filter(|p| (p[i / 8] >> (i % 8)) & 1 == 1)
            .count();
        assert!(
            (7..=9).contains(&fired),
            "{fired} spikes in {n} ticks at 0.1 per tick"
        );
    }

    proptest::proptest! {
        /// Any planes of a small size: the planes back unchanged (`None`)
        /// or as many planes of the same length, never a panic; a pixel
        /// that changed fires fewer spikes than it did. A size no plane
        /// has gives `None`.
        #[test]
        fn any_planes_train_on_fewer_spikes_or_as_they_were(
            w8 in 1u16..4,
            h in 1u16..24,
            n in 0usize..48,
            seed in proptest::num::u64::ANY,
            density in 0u64..8,
        ) {
            let mut x = seed | 1;
            let mut next = move || {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x
            };
            let w = 8 * w8;
            // A size no plane has: nothing to train on.
            proptest::prop_assert!(background_planes(&[&[0u8; 4][..]; 20], w + 1, h | 1).is_none());
            let bytes = crate::plane::plane_bytes(w, h).unwrap();
            // Dense blobs in some runs: a pixel fires where a random
            // pattern shared by every plane says so, or at random.
            let still: Vec<u8> = (0..bytes).map(|_| next() as u8).collect();
            let planes: Vec<Vec<u8>> = (0..n)
                .map(|_| {
                    (0..bytes)
                        .map(|k| if next() % 8 < density { still[k] } else { next() as u8 & still[k] })
                        .collect()
                })
                .collect();
            let refs: Vec<&[u8]> = planes.iter().map(Vec::as_slice).collect();
            if let Some(out) = background_planes(&refs, w, h) {
                proptest::prop_assert_eq!(out.len(), planes.len());
                let px = usize::from(w) * usize::from(h);
                let fired = |ps: &[Vec<u8>], i: usize| ps.iter().filter(|p| (p[i / 8] >> (i % 8)) & 1 == 1).count();
                for i in 0..px {
                    let (a, b) = (fired(&planes, i), fired(&out, i));
                    let same = planes.iter().zip(&out).all(|(p, q)| (p[i / 8] ^ q[i / 8]) >> (i % 8) & 1 == 0);
                    proptest::prop_assert!(same || b < a, "pixel {} fired {} then {}", i, a, b);
                }
                for p in &out {
                    proptest::prop_assert_eq!(p.len(), bytes);
                }
            }
        }
    }
}
