//! `spiv.simulate`: a recording from the simulated camera (the `sim`
//! feature; without it the function says how to build it in).

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A simulated recording (the same as `spiv simulate`): `scene` is
/// "paper-linear", "paper-quadratic", "paper-log", "blasius", "uniform",
/// "vortex", "turbulence", "large-shift", "vortex-array" or
/// "spectral-turbulence"; `width`,
/// `height` px; `ticks` planes; `dt` the pair's separation, ticks; `shift`
/// the uniform scene's (u, v) px per pair; `spacing` the minimum particle
/// spacing, px; `speed` the top speed of the shear scenes and the vortex
/// array, px/tick; `flow_seed` the seed of a turbulence field or of the
/// vortex array's offset and drift; `member` the spectral-turbulence
/// member `spiv bench flows` draws from that seed; `out` a folder to also
/// write `spiv simulate`'s files to (spikes.dat, scene.json, frame_a.png,
/// frame_b.png, truth.csv, truth.flo, profile.csv).
///
/// Returns a dict: `spikes` `uint8 (ticks, height, width)` upright 0/1,
/// `frames` the frame camera's pair `uint16 (2, height, width)` with its
/// `frame_full_scale`, `pair` the pair's ticks `(k_a, k_b)`, and `truth`
/// a dict of `x, y, u, v` `(ny, nx)` on the 32-px, 16-px-step grid of
/// `truth.csv` (px per pair, v down), and `truth_dense`, `u, v` per pixel
/// `float32 (height, width)` (`truth.flo`).
///
/// A build without the `sim` feature raises `SpivError` saying how to
/// build one that has it.
#[pyfunction]
#[pyo3(signature = (scene="paper-linear", seed=1, width=None, height=None, ticks=None, dt=None, shift=None, spacing=None, out=None, speed=None, flow_seed=None, member=None))]
#[allow(clippy::too_many_arguments)]
#[cfg_attr(not(feature = "sim"), allow(unused_variables))]
pub(crate) fn simulate<'py>(
    py: Python<'py>,
    scene: &str,
    seed: u64,
    width: Option<u16>,
    height: Option<u16>,
    ticks: Option<u32>,
    dt: Option<u32>,
    shift: Option<(f64, f64)>,
    spacing: Option<f64>,
    out: Option<PathBuf>,
    speed: Option<f64>,
    flow_seed: Option<u64>,
    member: Option<u64>,
) -> PyResult<Bound<'py, PyDict>> {
    #[cfg(feature = "sim")]
    {
        let req = spiv_host::simulate::SimulateRequest {
            scene: scene.into(),
            seed,
            width,
            height,
            ticks,
            dt,
            shift,
            spacing,
            speed,
            flow_seed,
            member,
        }
        .request()
        .map_err(crate::err)?;
        with_sim::simulate(py, req, out)
    }
    #[cfg(not(feature = "sim"))]
    Err(crate::SpivError::new_err(
        "this build of spiv has no simulator: install it with \
         MATURIN_PEP517_ARGS=\"--features sim\" pip install ./python \
         (or simulate with the spiv CLI and read its spikes.dat)",
    ))
}

#[cfg(feature = "sim")]
mod with_sim {
    use std::path::{Path, PathBuf};

    use numpy::IntoPyArray;
    use pyo3::prelude::*;
    use pyo3::types::PyDict;
    use spiv_firmware_sim::scene::Scene;
    use spiv_firmware_sim::simulation::{simulate_planes, simulate_to_dir, Request};
    use spiv_formats::dat::{unpack_upright, DatOptions, DatReader};
    use spiv_formats::grid::Grid;
    use spiv_formats::Vector;

    use crate::{array2, array3, err, field_arrays, Failure, SpivError, MAX_ARRAY_BYTES};

    /// [`super::simulate`] on a checked request.
    pub(crate) fn simulate<'py>(
        py: Python<'py>,
        req: Request,
        out: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (w, h) = (req.scene.width, req.scene.height);
        let (n, _) = req.layout().map_err(err)?;
        let px = u64::from(w) * u64::from(h);
        if u64::from(n).saturating_mul(px) > MAX_ARRAY_BYTES {
            return Err(SpivError::new_err(format!(
                "{n} planes of {w}x{h} px exceed {MAX_ARRAY_BYTES} bytes"
            )));
        }
        let sim = py.detach(|| simulated(&req, out.as_deref())).map_err(err)?;
        simulated_dict(py, sim)
    }

    /// What [`simulate`] returns, before it becomes a dict.
    struct Simulation {
        /// Upright 0/1 per pixel, plane after plane.
        spikes: Vec<u8>,
        /// The frame camera's pair, back to back, upright.
        frames: Vec<u16>,
        frame_full_scale: u16,
        pair: [u32; 2],
        truth: Vec<Vector>,
        dense: spiv_formats::dense::DenseField,
        grid: Grid,
        size: (usize, usize),
    }

    /// Simulates `req` (writing `spiv simulate`'s files to `out` too, and
    /// reading the planes back from them) with its truth on the 32-px grid.
    fn simulated(req: &Request, out: Option<&Path>) -> Result<Simulation, Failure> {
        let (w, h) = (req.scene.width, req.scene.height);
        let (planes, sim) = match out {
            None => simulate_planes(req)?,
            Some(dir) => {
                let sim = simulate_to_dir(req, dir, |_, _| {})?;
                let mut r = DatReader::open(&dir.join("spikes.dat"), w, h, DatOptions::default())?;
                (r.read_range(0, r.planes())?, sim)
            }
        };
        let pb = usize::from(w) * usize::from(h) / 8;
        let mut spikes = Vec::with_capacity(planes.len() * 8);
        for p in planes.chunks_exact(pb) {
            spikes.extend(unpack_upright(p, w, h, true));
        }
        let pair = sim.meta.capture.pair;
        let dtp = f64::from(pair[1] - pair[0]);
        let grid = Grid::new(usize::from(w), usize::from(h), 32, 16)
            .ok_or_else(|| format!("{w}x{h} px: smaller than the 32-px truth grid"))?;
        let mid = Scene::pair_mid(u64::from(pair[0]), u64::from(pair[1]));
        let truth = sim.scene.truth_vectors_at(&grid.centres(), mid, dtp);
        let dense = sim.scene.truth_dense_at(mid, dtp);
        let [fa, fb] = sim.frames;
        Ok(Simulation {
            spikes,
            frames: [fa, fb].concat(),
            frame_full_scale: req.camera.max_dn(),
            pair,
            truth,
            dense,
            grid,
            size: (usize::from(h), usize::from(w)),
        })
    }

    /// [`simulate`]'s dict.
    fn simulated_dict(py: Python<'_>, s: Simulation) -> PyResult<Bound<'_, PyDict>> {
        let (h, w) = s.size;
        let t = s.spikes.len() / (h * w);
        let d = PyDict::new(py);
        d.set_item("spikes", array3((t, h, w), s.spikes)?.into_pyarray(py))?;
        d.set_item("frames", array3((2, h, w), s.frames)?.into_pyarray(py))?;
        d.set_item("frame_full_scale", s.frame_full_scale)?;
        d.set_item("pair", (s.pair[0], s.pair[1]))?;
        let (x, y, u, v, _) = field_arrays(&s.truth, &s.grid);
        let td = PyDict::new(py);
        td.set_item("x", x.into_pyarray(py))?;
        td.set_item("y", y.into_pyarray(py))?;
        td.set_item("u", u.into_pyarray(py))?;
        td.set_item("v", v.into_pyarray(py))?;
        d.set_item("truth", td)?;
        let dd = PyDict::new(py);
        dd.set_item("u", array2((h, w), s.dense.u)?.into_pyarray(py))?;
        dd.set_item("v", array2((h, w), s.dense.v)?.into_pyarray(py))?;
        d.set_item("truth_dense", dd)?;
        Ok(d)
    }
}
