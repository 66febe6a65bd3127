//! Motion-compensated innovation frames: each pixel sums the innovation
//! ([`super::Innovation`]) along the path a particle there would follow
//! through the predicted (steady) velocity field, so a particle moving as
//! predicted piles its unexpected spikes up where it is at the frame's
//! time, while static light (background, glare, the sensor's fixed
//! pattern) adds about nothing. Paths are integrated through the field
//! (midpoint rule, steps of at most one tick), so a particle turning in a
//! vortex is followed round the turn, not along its tangent.

use ndarray::Array2;
use rayon::prelude::*;

use super::spikes::SCALE;
use super::Innovation;

/// A velocity per pixel, px per tick (u right, v down), upright.
#[derive(Debug, Clone)]
pub struct Velocity {
    /// Right.
    pub u: Array2<f32>,
    /// Down.
    pub v: Array2<f32>,
}

impl Velocity {
    /// No motion over an `h × w` image.
    pub fn zero(h: usize, w: usize) -> Velocity {
        Velocity {
            u: Array2::zeros((h, w)),
            v: Array2::zeros((h, w)),
        }
    }

    /// The velocity at `(x, y)` (px, pixel centres on integers), bilinear
    /// between pixels, the nearest edge pixel's outside.
    pub fn at(&self, x: f64, y: f64) -> (f64, f64) {
        let (h, w) = self.u.dim();
        if h == 0 || w == 0 {
            return (0.0, 0.0);
        }
        let xc = x.clamp(0.0, (w - 1) as f64);
        let yc = y.clamp(0.0, (h - 1) as f64);
        let (j, i) = (xc.floor() as usize, yc.floor() as usize);
        let (j1, i1) = ((j + 1).min(w - 1), (i + 1).min(h - 1));
        let (fx, fy) = (xc - j as f64, yc - i as f64);
        let lerp = |a: &Array2<f32>| {
            let top = f64::from(a[[i, j]]) * (1.0 - fx) + f64::from(a[[i, j1]]) * fx;
            let bot = f64::from(a[[i1, j]]) * (1.0 - fx) + f64::from(a[[i1, j1]]) * fx;
            top * (1.0 - fy) + bot * fy
        };
        (lerp(&self.u), lerp(&self.v))
    }

    /// Where a particle at `(x, y)` is after `ticks` ticks (either sign)
    /// in this steady field: midpoint steps of at most one tick.
    pub fn advect(&self, (mut x, mut y): (f64, f64), ticks: f64) -> (f64, f64) {
        let n = ticks.abs().ceil().max(1.0);
        let h = ticks / n;
        for _ in 0..n as usize {
            let (u1, v1) = self.at(x, y);
            let (u2, v2) = self.at(x + 0.5 * h * u1, y + 0.5 * h * v1);
            x += h * u2;
            y += h * v2;
        }
        (x, y)
    }

    /// The displacement over `ticks` ticks of the particle at `(x, y)`
    /// halfway through (its path from `−ticks/2` to `+ticks/2`).
    pub fn displacement(&self, (x, y): (f64, f64), ticks: f64) -> (f64, f64) {
        let a = self.advect((x, y), -0.5 * ticks);
        let b = self.advect((x, y), 0.5 * ticks);
        (b.0 - a.0, b.1 - a.1)
    }

    /// [`Velocity::displacement`] at every pixel: the field of
    /// displacements over `ticks` ticks, `(u, v)` in px.
    pub fn displacements(&self, ticks: f64) -> (Array2<f32>, Array2<f32>) {
        let mut u = Array2::zeros(self.u.dim());
        let mut v = Array2::zeros(self.u.dim());
        ndarray::Zip::indexed(&mut u)
            .and(&mut v)
            .par_for_each(|(i, j), u, v| {
                let (du, dv) = self.displacement((j as f64, i as f64), ticks);
                *u = du as f32;
                *v = dv as f32;
            });
        (u, v)
    }

    /// A displacement field over `ticks` ticks as a velocity.
    pub fn from_displacement(u: &Array2<f32>, v: &Array2<f32>, ticks: f64) -> Velocity {
        let k = (1.0 / ticks.max(1e-9)) as f32;
        Velocity {
            u: u.mapv(|x| x * k),
            v: v.mapv(|x| x * k),
        }
    }
}

/// The frame of the recording ticks `t0..t0 + n` (clipped to what `inn`
/// holds) showing each particle where it is at time `centre` (ticks; a
/// spike of tick `t` is taken at `t + 0.5`): pixel `x` sums, over the
/// ticks, the innovation at the pixel nearest to where a particle at `x`
/// at `centre` is at `t + 0.5` ([`Velocity::advect`]), in spikes. Paths
/// that leave the image add nothing.
pub fn compensated(
    inn: &Innovation,
    centre: f64,
    (t0, n): (u64, u64),
    vel: &Velocity,
) -> Array2<f32> {
    let (w, h) = (inn.width, inn.height);
    let span = inn.range();
    let a = t0.max(span.start);
    let b = t0.saturating_add(n).min(span.end);
    // The ticks after the centre in time order, those before it in reverse
    // order: each path is walked outwards from the centre both ways.
    let offset = |t: u64| t as f64 + 0.5 - centre;
    let planes = |ts: &mut dyn Iterator<Item = u64>| -> Vec<(&[i8], f64)> {
        ts.filter_map(|t| Some((inn.plane((t - span.start) as usize)?, offset(t))))
            .collect()
    };
    let after = planes(&mut (a..b).filter(|&t| offset(t) >= 0.0));
    let before = planes(&mut (a..b).rev().filter(|&t| offset(t) < 0.0));
    let mut out = Array2::<f32>::zeros((h, w));
    // Without motion every path stays on its pixel: plain sums.
    if vel.u.iter().chain(vel.v.iter()).all(|&x| x == 0.0) {
        let mut acc = vec![0i32; w * h];
        for (plane, _) in after.iter().chain(&before) {
            for (a, &x) in acc.iter_mut().zip(plane.iter()) {
                *a += i32::from(x);
            }
        }
        for (o, a) in out.iter_mut().zip(acc) {
            *o = a as f32 / SCALE;
        }
        return out;
    }
    out.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .enumerate()
        .for_each(|(r, mut row)| {
            for (c, o) in row.iter_mut().enumerate() {
                let mut s = 0i32;
                for side in [&after, &before] {
                    let (mut p, mut at) = ((c as f64, r as f64), 0.0);
                    for &(plane, d) in side.iter() {
                        p = vel.advect(p, d - at);
                        at = d;
                        let (x, y) = (p.0.round(), p.1.round());
                        if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                            s += i32::from(plane[y as usize * w + x as usize]);
                        }
                    }
                }
                *o = s as f32 / SCALE;
            }
        });
    out
}

/// The pair of frames a rung of separation `s` makes around `mid` (a tick
/// boundary): A from the ticks `mid − s..mid` showing the particles at
/// `mid − s/2`, B from `mid..mid + s` at `mid + s/2`; each as
/// [`compensated`] makes it. A steady field moves a particle alike in both,
/// so each pixel's path is walked once for the two.
pub fn compensated_pair(inn: &Innovation, mid: u64, s: u64, vel: &Velocity) -> [Array2<f32>; 2] {
    let (w, h) = (inn.width, inn.height);
    let span = inn.range();
    if mid < span.start + s || mid + s > span.end {
        let sf = s as f64;
        return [
            compensated(inn, mid as f64 - sf / 2.0, (mid.saturating_sub(s), s), vel),
            compensated(inn, mid as f64 + sf / 2.0, (mid, s), vel),
        ];
    }
    // Offsets from the frame's centre, walked outwards: the later half of
    // A's ticks (and of B's) in time order, then the earlier half reversed.
    let a0 = (mid - s - span.start) as usize;
    let half = (s / 2) as usize;
    let order: Vec<(usize, f64)> = (half..s as usize)
        .chain((0..half).rev())
        .map(|i| (i, i as f64 + 0.5 - s as f64 / 2.0))
        .collect();
    let planes: Vec<(&[i8], &[i8], f64)> = order
        .iter()
        .filter_map(|&(i, d)| Some((inn.plane(a0 + i)?, inn.plane(a0 + i + s as usize)?, d)))
        .collect();
    let mut a = Array2::<f32>::zeros((h, w));
    let mut b = Array2::<f32>::zeros((h, w));
    a.axis_iter_mut(ndarray::Axis(0))
        .into_par_iter()
        .zip(b.axis_iter_mut(ndarray::Axis(0)))
        .enumerate()
        .for_each(|(r, (mut ra, mut rb))| {
            for (c, (oa, ob)) in ra.iter_mut().zip(rb.iter_mut()).enumerate() {
                let (mut sa, mut sb) = (0i32, 0i32);
                let (mut p, mut at) = ((c as f64, r as f64), 0.0);
                for &(pa, pb, d) in &planes {
                    // The walk restarts from the pixel for the earlier half.
                    if d < 0.0 && at > 0.0 {
                        (p, at) = ((c as f64, r as f64), 0.0);
                    }
                    p = vel.advect(p, d - at);
                    at = d;
                    let (x, y) = (p.0.round(), p.1.round());
                    if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                        let i = y as usize * w + x as usize;
                        sa += i32::from(pa[i]);
                        sb += i32::from(pb[i]);
                    }
                }
                *oa = sa as f32 / SCALE;
                *ob = sb as f32 / SCALE;
            }
        });
    [a, b]
}
