//! A stretch of a recording's spikes as the host's motion estimate reads
//! them: unpacked upright (row 0 at the top), padding columns cropped, and
//! turned into each pixel's *innovation* — its spikes less what its own
//! static light predicts ([`Innovation`]). Memory: one byte per pixel and
//! tick of the stretch, at most [`MAX_SPAN`] ticks.

use crate::reconstruct::Planes;

/// Most ticks a stretch holds (a 1000×1000 sensor: 512 MB).
pub const MAX_SPAN: usize = 512;

/// Fewest intervals a pixel must show before its period is trusted.
const MIN_INTERVALS: usize = 3;

/// Share of a pixel's intervals (in tenths) that must equal the median for
/// the pixel to count as periodic.
const PERIODIC_TENTHS: usize = 7;

/// Fixed-point scale of [`Innovation`]'s values: 64 per spike.
pub const SCALE: f32 = 64.0;

/// Spikes less their static prediction, per pixel and tick: a value in
/// [−1, 1] spikes stored as `i8` in units of 1/[`SCALE`].
///
/// The static prediction follows the integrate-and-fire sensor. A pixel
/// under steady light fires almost periodically, so once it has fired, a
/// spike exactly one usual interval later is expected (predicted 1) and
/// any other tick predicts 0: its spikes cancel whatever its brightness,
/// phase or threshold, and glare adds nothing to a frame. A pixel too dark
/// or too irregular for a period (fewer than [`MIN_INTERVALS`] intervals,
/// or fewer than 70 % of them equal) predicts its mean rate at every tick.
/// Light that moves — a particle — fires a pixel early, which no
/// prediction expected.
#[derive(Debug, Clone)]
pub struct Innovation {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Recording tick of the first plane.
    pub first: u64,
    /// Planes held.
    pub ticks: usize,
    data: Vec<i8>,
}

impl Innovation {
    /// The innovation of `planes` (stored row order, packed), upright and
    /// cropped; at most [`MAX_SPAN`] planes (the first ones).
    pub fn of(planes: &Planes) -> Innovation {
        let (w, h) = (usize::from(planes.width), usize::from(planes.height));
        let cw = usize::from(planes.crop_width.min(planes.width));
        let pb = (w * h / 8).max(1);
        let n = (planes.data.len() / pb).min(MAX_SPAN);
        let px = cw * h;
        // Pixel by pixel over time: unpack one pixel's train at a time.
        let mut data = vec![0i8; px * n];
        let mut train = vec![0u8; n];
        let mut times: Vec<usize> = Vec::with_capacity(n);
        for r in 0..h {
            let up = if planes.flip { h - 1 - r } else { r };
            for c in 0..cw {
                let bit = r * w + c;
                let (byte, shift) = (bit / 8, bit % 8);
                for (t, s) in train.iter_mut().enumerate() {
                    *s = (planes.data[t * pb + byte] >> shift) & 1;
                }
                let i = up * cw + c;
                predict_out(&train, &mut times, |t, x| data[t * px + i] = x);
            }
        }
        Innovation {
            width: cw,
            height: h,
            first: planes.first,
            ticks: n,
            data,
        }
    }

    /// The recording ticks held, `first..first + ticks`.
    pub fn range(&self) -> std::ops::Range<u64> {
        self.first..self.first + self.ticks as u64
    }

    /// Plane `t` (0 = the first held), row-major, or `None` past the end.
    pub fn plane(&self, t: usize) -> Option<&[i8]> {
        let px = self.width * self.height;
        self.data.get(t * px..(t + 1) * px)
    }
}

/// Writes `s − p` (in 1/[`SCALE`]) for each tick of one pixel's `train`
/// through `out(t, value)`, `p` the static prediction ([`Innovation`]).
fn predict_out(train: &[u8], times: &mut Vec<usize>, mut out: impl FnMut(usize, i8)) {
    times.clear();
    times.extend(
        train
            .iter()
            .enumerate()
            .filter(|(_, &s)| s != 0)
            .map(|(t, _)| t),
    );
    let period = period(times);
    let rate = times.len() as f32 / train.len().max(1) as f32;
    let q = |x: f32| (x * SCALE).round().clamp(-127.0, 127.0) as i8;
    let mut last: Option<usize> = None;
    for (t, &s) in train.iter().enumerate() {
        let p = match (period, last) {
            (Some(p), Some(l)) => f32::from(u8::from(t - l == p)),
            _ => rate,
        };
        out(t, q(f32::from(s) - p));
        if s != 0 {
            last = Some(t);
        }
    }
}

/// The usual interval between `times` (ticks, ascending): the median
/// interval when at least [`MIN_INTERVALS`] intervals show and 70 % of them
/// equal it; `None` otherwise.
fn period(times: &[usize]) -> Option<usize> {
    let n = times.len().checked_sub(1)?;
    if n < MIN_INTERVALS {
        return None;
    }
    let mut isi: Vec<usize> = times.windows(2).map(|p| p[1] - p[0]).collect();
    isi.sort_unstable();
    let p = isi[n / 2];
    let same = isi.iter().filter(|&&d| d == p).count();
    (same * 10 >= n * PERIODIC_TENTHS).then_some(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn innovation(train: &[u8]) -> Vec<f32> {
        let mut out = vec![0f32; train.len()];
        predict_out(train, &mut Vec::new(), |t, x| out[t] = f32::from(x) / SCALE);
        out
    }

    /// A periodic pixel cancels after its first spike, whatever its phase;
    /// an early spike (a particle) stands out, and the train's reset moves
    /// the prediction with it.
    #[test]
    fn a_periodic_pixel_cancels_and_an_early_spike_stands_out() {
        for phase in 0..3 {
            let train: Vec<u8> = (0..30).map(|t| u8::from((t + phase) % 3 == 0)).collect();
            let inn = innovation(&train);
            let first = train.iter().position(|&s| s == 1).unwrap();
            assert!(inn[first + 1..].iter().all(|&x| x == 0.0), "{inn:?}");
        }
        // Period 3 with one early spike at tick 10 (the last regular one at 9).
        let mut train: Vec<u8> = (0..30).map(|t| u8::from(t % 3 == 0)).collect();
        train[10] = 1;
        for t in (13..30).step_by(3) {
            train[t] = 1;
            train[t - 1] = 0;
        }
        train[12] = 0;
        let inn = innovation(&train);
        assert_eq!(inn[10], 1.0);
        assert!(inn[11..].iter().all(|&x| x == 0.0), "{inn:?}");
    }

    /// A dark pixel predicts its mean rate: its spikes stand out by
    /// 1 − rate, its silent ticks sink by the rate.
    #[test]
    fn a_dark_pixel_predicts_its_rate() {
        let mut train = vec![0u8; 64];
        train[5] = 1;
        train[40] = 1;
        let inn = innovation(&train);
        let r = 2.0 / 64.0;
        assert!((inn[5] - (1.0 - r)).abs() <= 0.5 / SCALE);
        assert!((inn[0] + r).abs() <= 0.5 / SCALE);
        assert!(inn.iter().sum::<f32>().abs() < 0.2);
    }

    #[test]
    fn period_needs_enough_regular_intervals() {
        assert_eq!(period(&[0, 2, 4, 6]), Some(2));
        assert_eq!(period(&[0, 2, 4]), None);
        assert_eq!(period(&[0, 2, 5, 9, 14]), None);
        assert_eq!(period(&[]), None);
    }
}
