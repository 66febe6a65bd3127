//! `spiv flow --movie`: the pairs' speed over time as an animated GIF
//! (`flow.gif`), each frame the colour map of one pair's field on one
//! scale, the glare marked.

use std::path::Path;

use crate::flow::{FlowOptions, FlowOutcome};

use super::flow::speed_and_vorticity;
use super::plot::{self, plot_error, NodeScalar};
use crate::Error;

/// Most frames a movie holds: a longer run shows every k-th pair.
pub const MOVIE_FRAMES: usize = 240;
/// Frames per second of the movie.
pub const MOVIE_FPS: u16 = 10;

/// Writes `path`: one frame per pair (every k-th pair when there are more
/// than [`MOVIE_FRAMES`]), each pair's speed in m/s when calibrated (else
/// px per pair) on one viridis scale from 0 to the 99th percentile of the
/// shown pairs' valid speeds, at [`MOVIE_FPS`] frames per second, looping.
pub fn write_movie(path: &Path, out: &FlowOutcome, opts: &FlowOptions) -> Result<(), Error> {
    let n = out.pairs.len();
    let dt = f64::from(opts.dt);
    let (k, unit) = match opts.calibration {
        Some(c) => (c.m_per_s(1.0, dt), "m/s"),
        None => (1.0, "px per pair"),
    };
    let shown: Vec<(usize, Vec<f64>)> = shown_pairs(n)
        .map(|i| {
            let (speed, _) = speed_and_vorticity(&out.pairs[i].vectors, &out.grid);
            (i, speed.into_iter().map(|s| s * k).collect())
        })
        .collect();
    let mut all: Vec<f64> = shown
        .iter()
        .flat_map(|(_, s)| s.iter().copied().filter(|v| v.is_finite()))
        .collect();
    let top = if all.is_empty() {
        0.0
    } else {
        let at = ((all.len() - 1) as f64 * 0.99).round() as usize;
        *all.select_nth_unstable_by(at, f64::total_cmp).1
    };
    let size = (u32::from(out.size.0), u32::from(out.size.1));
    let e = |msg: String| plot_error(path, msg);
    let (w, h) = plot::node_map_size(size);
    let (Ok(w), Ok(h)) = (u16::try_from(w), u16::try_from(h)) else {
        return Err(e(format!(
            "{w}x{h} px: a GIF frame holds at most 65535x65535"
        )));
    };
    let file = std::fs::File::create(path).map_err(|x| Error::io(path.display().to_string(), x))?;
    let mut gif = gif::Encoder::new(std::io::BufWriter::new(file), w, h, &[])
        .map_err(|x| e(x.to_string()))?;
    gif.set_repeat(gif::Repeat::Infinite)
        .map_err(|x| e(x.to_string()))?;
    for (i, speed) in &shown {
        let p = &out.pairs[*i];
        let t = match opts.calibration {
            Some(c) => format!("t={:.4} s", c.seconds(p.ticks[0] as f64 + dt / 2.0)),
            None => format!("tick {}", p.ticks[0]),
        };
        let name = format!("speed, pair {}/{n}, {t}", i + 1);
        let scalar = NodeScalar {
            values: speed,
            name: &name,
            unit,
            signed: false,
            top: Some(top),
            mm_per_px: opts.calibration.map(|c| c.pixel_mm),
            y_up: opts.y_up,
        };
        let (rgb, _) = plot::node_map_rgb(size, &out.grid, scalar, &out.glare)?;
        // NeuQuant at its fastest setting: the frames are flat colour cells.
        let mut frame = gif::Frame::from_rgb_speed(w, h, &rgb, 30);
        frame.delay = 100 / MOVIE_FPS;
        gif.write_frame(&frame).map_err(|x| e(x.to_string()))?;
    }
    Ok(())
}

/// The pairs a movie of `n` pairs shows: all of them, or every k-th from
/// the first, at most [`MOVIE_FRAMES`].
fn shown_pairs(n: usize) -> std::iter::StepBy<std::ops::Range<usize>> {
    (0..n).step_by(n.div_ceil(MOVIE_FRAMES).max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_runs_show_every_kth_pair_within_the_frame_budget() {
        for (n, frames, every) in [(1, 1, 1), (240, 240, 1), (241, 121, 2), (3846, 227, 17)] {
            let shown: Vec<usize> = shown_pairs(n).collect();
            assert_eq!(shown.len(), frames, "{n}");
            assert!(shown.len() <= MOVIE_FRAMES);
            assert_eq!(shown[0], 0);
            assert!(shown.windows(2).all(|w| w[1] - w[0] == every), "{n}");
        }
        assert_eq!(shown_pairs(0).count(), 0);
    }
}
