//! The dwell cap (beyond the paper, docs/spec.md §5): PIV of the TFP pair predicts
//! each band's fastest particle, and each 32-row band's adaptive window is
//! capped so that particle blurs by at most a budget of pixels. One
//! implementation of the banded frame ([`spiv_core::sidecar::capped_frame`])
//! serves the firmware and the in-process path.

use spiv_core::Params;
use spiv_formats::vectors::Vector;

use crate::reconstruct::Planes;
use crate::Error;

/// The default blur budget, px: a particle's image may move this far
/// within its window (`spiv bench speed`: 6 and 16 px measured worse on
/// paper-linear).
pub const DWELL_CAP: f64 = 8.0;

/// The default blur budget as the command line's `--dwell-cap` text.
pub const DWELL_CAP_ARG: &str = "8";

/// Rows per band of the capped adaptive reconstruction (the firmware's
/// [`spiv_core::sidecar::CAP_BAND`]; margins are `Params::margin`).
pub const BAND: usize = spiv_core::sidecar::CAP_BAND as usize;

/// The adaptive frame at `k` (upright) with each band of `BAND` rows
/// reconstructed by the core with its own window limit `caps[band]`, as the
/// sidecar firmware does ([`spiv_core::sidecar::capped_frame`]).
pub fn adaptive_banded(
    planes: &Planes,
    k: u64,
    core: &Params,
    caps: &[u16],
) -> Result<(Vec<u16>, spiv_core::label::LabelStats), Error> {
    let (w, h) = (planes.width, planes.height);
    let mut ring = planes.ring(k, core.n_max)?;
    let tick = ring.tick;
    let hist = ring.history()?;
    let mut ws = spiv_core::buffers::WorkspaceBuf::whole(w, h);
    let mut out = vec![0u16; usize::from(w) * usize::from(h)];
    let labels =
        spiv_core::sidecar::capped_frame(&hist, tick, core, caps, &mut ws.workspace()?, &mut out)?;
    Ok((planes.output(&out), labels))
}

/// [`band_caps`] for the bands [`adaptive_banded`] makes from `planes`:
/// the core counts bands from the bottom stored row up, which is the top
/// of the upright image when rows are stored bottom-up (the camera) and
/// its bottom when they are stored upright (`.npz` captures), so the field
/// is mirrored for the latter.
pub fn caps_for(
    planes: &Planes,
    field: &[Vector],
    dt: f64,
    budget: f64,
    core: &Params,
) -> Vec<u16> {
    let h = usize::from(planes.height);
    if planes.flip {
        band_caps(field, h, dt, budget, core)
    } else {
        let hf = planes.height as f64 - 1.0;
        let mirrored: Vec<Vector> = field.iter().map(|v| Vector { y: hf - v.y, ..*v }).collect();
        band_caps(&mirrored, h, dt, budget, core)
    }
}

/// Window limit per band from a field: the budget over the fastest valid
/// vector near the band, px per tick, as ticks within [2·n0, n_max].
pub fn band_caps(field: &[Vector], h: usize, dt: f64, budget: f64, core: &Params) -> Vec<u16> {
    (0..h.div_ceil(BAND))
        .map(|b| {
            let (lo, hi) = ((b * BAND) as f64 - 16.0, ((b + 1) * BAND) as f64 + 16.0);
            let vmax = field
                .iter()
                .filter(|v| v.state.is_measured() && v.y >= lo && v.y < hi)
                .map(|v| v.u.hypot(v.v))
                .fold(0.0, f64::max);
            let n = if vmax > 0.0 {
                budget / (vmax / dt)
            } else {
                f64::from(core.n_max)
            };
            // Within [2·n0, n_max]; n_max wins where the two cross (n0 near
            // n_max), and the core then checks n0 ≤ n_max as always.
            n.max(2.0 * f64::from(core.n0)).min(f64::from(core.n_max)) as u16
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_command_line_default_is_the_constant() {
        assert_eq!(super::DWELL_CAP_ARG.parse::<f64>(), Ok(super::DWELL_CAP));
    }
}
