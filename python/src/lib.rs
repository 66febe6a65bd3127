//! The Python module `spiv`: spike files, frames, PIV, simulation and the
//! flow job over numpy arrays, by the same library calls as the `spiv`
//! command line (so the same vectors and the same one-line errors).
//!
//! Conventions (as OpenPIV's before `tools.transform_coordinates`):
//! images and spike planes are upright arrays, row 0 at the top, indexed
//! `[row, column]` (spikes `[tick, row, column]`); vector fields are 2-D
//! arrays `(ny, nx)` on the PIV grid, `x` to the right and `y` down the rows
//! in pixels (pixel centres on integers), `u` and `v` in pixels per pair,
//! `v` positive down the rows, as in `spiv piv`'s CSV. Heavy work releases
//! the GIL. Errors raise `spiv.SpivError` (a `ValueError`) or `OSError`
//! with the CLI's message.

mod simulate;

use std::path::{Path, PathBuf};

use numpy::ndarray::{Array2, Array3};
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use spiv_core::{Method, Params};
use spiv_formats::capture::Capture;
use spiv_formats::dat::{unpack_upright, DatOptions, DatReader};
use spiv_formats::grid::Grid;
use spiv_formats::image::read_gray;
use spiv_formats::{FormatError, State, Vector, MAX_FRAME_PIXELS};
use spiv_host::flow::{FlowRequest, MeanField, Recording};
use spiv_host::live::{open_downlink, run_live, LiveOptions};
use spiv_host::piv::options::PivOptions;
use spiv_host::piv::{piv as run_piv, PivError};
use spiv_host::receive::{FrameLimit, Spec};
use spiv_host::reconstruct::{frame_from_planes, FileOptions, Planes};
use spiv_host::units::Calibration;

/// mimalloc instead of the system allocator, as in the `spiv` binary: PIV
/// allocates image-sized buffers per call, and glibc hands those back to
/// the kernel on free, so every call paid fresh page faults (a fifth of a
/// 1024² `piv` on one thread); mimalloc keeps and reuses its pages.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

pyo3::create_exception!(
    spiv,
    SpivError,
    PyValueError,
    "A value spiv refuses (the message is the CLI's one line)."
);

/// Largest array the module returns, bytes: a bound on sizes that come
/// from files and arguments, checked before anything is allocated.
const MAX_ARRAY_BYTES: u64 = 1 << 31;

/// The Python exception for a library error: `OSError` when a file could
/// not be read or written, else [`SpivError`]; the message is the one the
/// CLI prints after `spiv: error:`.
fn err(e: impl Into<Failure>) -> PyErr {
    match e.into() {
        Failure::Io(m) => PyOSError::new_err(m),
        Failure::Value(m) => SpivError::new_err(m),
    }
}

/// What went wrong, sorted for Python.
enum Failure {
    Io(String),
    Value(String),
}

impl From<FormatError> for Failure {
    fn from(e: FormatError) -> Self {
        match e {
            FormatError::Io { .. } => Failure::Io(e.to_string()),
            e => Failure::Value(e.to_string()),
        }
    }
}

impl From<PivError> for Failure {
    fn from(e: PivError) -> Self {
        spiv_host::Error::from(e).into()
    }
}

#[cfg(feature = "sim")]
impl From<spiv_firmware_sim::Error> for Failure {
    fn from(e: spiv_firmware_sim::Error) -> Self {
        spiv_host::Error::from(e).into()
    }
}

/// The one mapping of the host's errors to Python: the operating
/// system's failures ([`spiv_host::Error::is_io`]) as `OSError`, every
/// refused value as `SpivError`.
impl From<spiv_host::Error> for Failure {
    fn from(e: spiv_host::Error) -> Self {
        if e.is_io() {
            Failure::Io(e.to_string())
        } else {
            Failure::Value(e.to_string())
        }
    }
}

impl From<String> for Failure {
    fn from(m: String) -> Self {
        Failure::Value(m)
    }
}

/// `obj` as a C-contiguous numpy array of `dtype` (a copy only when it is
/// not one already).
fn contiguous<'py>(obj: &Bound<'py, PyAny>, dtype: &str) -> PyResult<Bound<'py, PyAny>> {
    let np = obj.py().import("numpy")?;
    np.call_method1("ascontiguousarray", (obj, dtype))
}

/// A 2-D image of any numeric dtype as the library's `f32` array.
fn image(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<ndarray::Array2<f32>> {
    let a = contiguous(obj, "float32")?;
    let a: PyReadonlyArray2<f32> = a
        .extract()
        .map_err(|_| SpivError::new_err(format!("{name}: expected a 2-D image array")))?;
    let (h, w) = (a.shape()[0], a.shape()[1]);
    let v = a
        .as_slice()
        .map_err(|e| SpivError::new_err(e.to_string()))?;
    ndarray::Array2::from_shape_vec((h, w), v.to_vec())
        .map_err(|e| SpivError::new_err(e.to_string()))
}

fn method_named(name: &str) -> PyResult<Method> {
    Method::from_name(name).ok_or_else(|| {
        SpivError::new_err(format!(
            "method {name}: expected ladder, adaptive, tfp, tfi or mc"
        ))
    })
}

fn dat_size(path: &Path, width: Option<u16>, height: Option<u16>) -> Result<(u16, u16), Failure> {
    match (width, height) {
        (Some(w), Some(h)) => Ok((w, h)),
        (None, None) => match Capture::beside(path)? {
            Some(m) => Ok((m.width, m.height)),
            None => Err(FormatError::NoSize(path.to_path_buf()).into()),
        },
        _ => Err("give both width and height, or neither".to_string().into()),
    }
}

/// Spike planes of a Vidar `.dat` file as a `uint8` array `(ticks, height,
/// width − strip_head)` of 0 and 1, upright (row 0 at the top).
///
/// `width` and `height` (px) come from the `scene.json` beside the file
/// when not given; `flip=False` for files whose rows are stored upright;
/// `strip_head` drops that many columns at the right of every row (16 for
/// 416-wide captures); `start` and `count` select planes (ticks).
#[pyfunction]
#[pyo3(signature = (path, width=None, height=None, flip=true, strip_head=0, start=0, count=None))]
#[allow(clippy::too_many_arguments)]
fn read_dat<'py>(
    py: Python<'py>,
    path: PathBuf,
    width: Option<u16>,
    height: Option<u16>,
    flip: bool,
    strip_head: u16,
    start: u64,
    count: Option<u64>,
) -> PyResult<Bound<'py, PyArray3<u8>>> {
    let (w, h) = dat_size(&path, width, height).map_err(err)?;
    let opts = DatOptions {
        flip,
        strip_head,
        allow_truncated: false,
    };
    let out = py
        .detach(|| -> Result<Array3<u8>, Failure> {
            let mut r = DatReader::open(&path, w, h, opts)?;
            let planes = r.planes();
            if start >= planes {
                return Err(format!(
                    "start {start}: the file has {planes} planes (0..{planes})"
                )
                .into());
            }
            let n = count.unwrap_or(planes - start).min(planes - start);
            let (ow, oh) = (r.width(), r.height());
            let px = u64::from(ow) * u64::from(oh);
            if n.saturating_mul(px) > MAX_ARRAY_BYTES {
                return Err(format!(
                    "{n} planes of {ow}x{oh} px exceed {MAX_ARRAY_BYTES} bytes: read fewer (start, count)"
                )
                .into());
            }
            let data = r.read_range(start, n)?;
            let pb = (px / 8) as usize;
            let mut out = Vec::with_capacity((n * px) as usize);
            for plane in data.chunks_exact(pb) {
                out.extend(unpack_upright(plane, ow, oh, r.flip()));
            }
            Array3::from_shape_vec((n as usize, usize::from(oh), usize::from(ow)), out)
                .map_err(|e| e.to_string().into())
        })
        .map_err(err)?;
    Ok(out.into_pyarray(py))
}

/// A gray image file (PNG, TIFF or BMP; 8- or 16-bit) as a `uint16`
/// array `(height, width)`, as `spiv piv` reads it.
#[pyfunction]
fn read_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray2<u16>>> {
    let g = py.detach(|| read_gray(&path)).map_err(err)?;
    let out = Array2::from_shape_vec((g.height as usize, g.width as usize), g.data)
        .map_err(|e| SpivError::new_err(e.to_string()))?;
    Ok(out.into_pyarray(py))
}

/// Packs upright 0/1 planes `(n, h, w)` into the core's stored order
/// (bottom-up rows, bit `p % 8` of byte `p / 8`), as a `.dat` holds them.
/// Hand-written: a bit-packing loop no crate does in this layout.
fn pack_bottom_up(spikes: &[u8], n: usize, h: usize, w: usize) -> Vec<u8> {
    let pb = w * h / 8;
    let mut out = vec![0u8; n * pb];
    for (t, plane) in out.chunks_exact_mut(pb).enumerate() {
        for r in 0..h {
            let src = &spikes[(t * h + (h - 1 - r)) * w..][..w];
            for (c, &s) in src.iter().enumerate() {
                if s != 0 {
                    let p = r * w + c;
                    plane[p / 8] |= 1 << (p % 8);
                }
            }
        }
    }
    out
}

/// One frame from spike planes, through the core: `spikes` is `(ticks,
/// height, width)`, nonzero where a pixel fired (upright, as
/// [`read_dat`] returns it); `at` the frame's centre tick (index into the
/// first axis). `method` is "adaptive" (the paper's), "tfp" or "tfi";
/// `window` the TFP window or the adaptive/TFI n_max, ticks (default 8 for
/// TFP, else 128). Returns `uint16` gray levels `0..=full_scale`, `(height,
/// width)`, upright.
#[pyfunction]
#[pyo3(signature = (spikes, at, method="adaptive", window=None, full_scale=255))]
fn reconstruct<'py>(
    py: Python<'py>,
    spikes: &Bound<'py, PyAny>,
    at: u64,
    method: &str,
    window: Option<u16>,
    full_scale: u16,
) -> PyResult<Bound<'py, PyArray2<u16>>> {
    let method = method_named(method)?;
    let window = window.unwrap_or(if method == Method::Tfp { 8 } else { 128 });
    let s = contiguous(spikes, "uint8")?;
    let s: PyReadonlyArray3<u8> = s
        .extract()
        .map_err(|_| SpivError::new_err("spikes: expected a 3-D array (ticks, height, width)"))?;
    let (n, h, w) = (s.shape()[0], s.shape()[1], s.shape()[2]);
    let (Ok(w16), Ok(h16)) = (u16::try_from(w), u16::try_from(h)) else {
        return Err(SpivError::new_err(format!(
            "{w}x{h} px: at most 65535 each"
        )));
    };
    if w * h == 0 || (w * h) % 8 != 0 || (w * h) as u64 > MAX_FRAME_PIXELS {
        return Err(SpivError::new_err(format!(
            "{w}x{h} px: width*height must be a positive multiple of 8, at most {MAX_FRAME_PIXELS}"
        )));
    }
    if full_scale == 0 {
        return Err(SpivError::new_err("full_scale must be 1..=65535"));
    }
    let data = s
        .as_slice()
        .map_err(|e| SpivError::new_err(e.to_string()))?;
    let packed = pack_bottom_up(data, n, h, w);
    let frame = py
        .detach(|| {
            let planes = Planes::simulated(w16, h16, packed);
            let p = Params {
                full_scale,
                ..Params::default()
            };
            frame_from_planes(&planes, at, method, window, &p)
        })
        .map_err(err)?;
    let out = Array2::from_shape_vec((h, w), frame.data)
        .map_err(|e| SpivError::new_err(e.to_string()))?;
    Ok(out.into_pyarray(py))
}

/// A field's nodes as `(ny, nx)` arrays: x, y, u, v and flags (0 valid, 1
/// replaced from neighbours, 2 masked or invalid: then u = v = NaN).
type FieldArrays = (
    Array2<f64>,
    Array2<f64>,
    Array2<f64>,
    Array2<f64>,
    Array2<u8>,
);

fn field_arrays(vectors: &[Vector], grid: &Grid) -> FieldArrays {
    field_arrays_of(vectors, (grid.ny, grid.nx))
}

fn field_arrays_of(vectors: &[Vector], (ny, nx): (usize, usize)) -> FieldArrays {
    let at = |f: &dyn Fn(&Vector) -> f64| {
        Array2::from_shape_fn((ny, nx), |(r, c)| {
            vectors.get(r * nx + c).map_or(f64::NAN, f)
        })
    };
    let measured = |v: &Vector| v.state.is_measured();
    (
        at(&|v| v.x),
        at(&|v| v.y),
        at(&|v| if measured(v) { v.u } else { f64::NAN }),
        at(&|v| if measured(v) { v.v } else { f64::NAN }),
        Array2::from_shape_fn((ny, nx), |(r, c)| {
            vectors.get(r * nx + c).map_or(2, |v| v.state.flag())
        }),
    )
}

/// Per-vector uncertainties `(σu, σv)` as two `(ny, nx)` arrays (inf past
/// the end).
fn sigma_arrays(sigma: &[(f64, f64)], (ny, nx): (usize, usize)) -> (Array2<f64>, Array2<f64>) {
    let at = |f: fn(&(f64, f64)) -> f64| {
        Array2::from_shape_fn((ny, nx), |(r, c)| {
            sigma.get(r * nx + c).map_or(f64::INFINITY, f)
        })
    };
    (at(|s| s.0), at(|s| s.1))
}

/// PIV on an image pair (any numeric dtype, `(height, width)`), by the
/// same code and defaults as `spiv piv`: multi-pass window deformation
/// (`windows`, px, one pass each), `overlap` 0..=0.9, `mask` (nonzero
/// pixels excluded), `interp` "bspline" | "bspline5" | "bicubic" |
/// "bilinear", the normalised median test (`median_threshold`, 0 off),
/// `clip` "auto" | "off" | a gray level, a high-pass of σ `highpass` px,
/// `subpixel` "parabolic" | "gaussian" | "gaussian2d", `min_peak_ratio`
/// (1 off); `dense_fallback`: where the last pass fails as a whole (eddies
/// below the window, displacements beyond it), the dense stage's vectors,
/// flagged 1, instead of nothing.
///
/// Returns `(x, y, u, v, flags)`, each `(ny, nx)`: window centres in px
/// (x right, y down), displacements in px per pair (v positive down the
/// rows), flags 0 valid, 1 replaced, 2 invalid (u = v = NaN). With
/// `confidence=True` also each vector's `peak_ratio` and `correlation`
/// (the normalised correlation at the peak), as `spiv piv`'s CSV columns
/// (0 where no peak).
#[pyfunction]
#[pyo3(signature = (a, b, windows=vec![64, 32, 32], overlap=0.5, mask=None, interp="bspline", median_threshold=2.0, clip="auto", highpass=3.0, subpixel="parabolic", min_peak_ratio=1.5, dense_fallback=true, confidence=false))]
#[pyo3(
    text_signature = "(a, b, windows=(64, 32, 32), overlap=0.5, mask=None, interp='bspline', median_threshold=2.0, clip='auto', highpass=3.0, subpixel='parabolic', min_peak_ratio=1.5, dense_fallback=True, confidence=False)"
)]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn piv<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
    windows: Vec<usize>,
    overlap: f64,
    mask: Option<&Bound<'py, PyAny>>,
    interp: &str,
    median_threshold: f64,
    clip: &str,
    highpass: f32,
    subpixel: &str,
    min_peak_ratio: f64,
    dense_fallback: bool,
    confidence: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let settings = PivOptions {
        windows,
        overlap,
        interp: interp.into(),
        median_threshold,
        clip: clip.into(),
        highpass,
        subpixel: subpixel.into(),
        min_peak_ratio,
        dense_fallback,
    }
    .settings()
    .map_err(err)?;
    // The arrays returned carry no uncertainty.
    let settings = spiv_host::piv::Settings {
        uncertainty: false,
        ..settings
    };
    let ia = image(a, "a")?;
    let ib = image(b, "b")?;
    let m = mask
        .map(|m| image(m, "mask").map(|m| m.mapv(|v| v != 0.0)))
        .transpose()?;
    let field = py
        .detach(|| run_piv(&ia, &ib, m.as_ref(), &settings))
        .map_err(err)?;
    let (x, y, u, v, f) = field_arrays(&field.vectors(), &field.grid);
    let mut out: Vec<Bound<'py, PyAny>> = vec![
        x.into_pyarray(py).into_any(),
        y.into_pyarray(py).into_any(),
        u.into_pyarray(py).into_any(),
        v.into_pyarray(py).into_any(),
        f.into_pyarray(py).into_any(),
    ];
    if confidence {
        out.push(field.peak_ratio.into_pyarray(py).into_any());
        out.push(field.peak_height.into_pyarray(py).into_any());
    }
    PyTuple::new(py, out)
}

/// The dense flow of an image pair, one vector per pixel (as `spiv piv
/// --dense`): window PIV with the defaults, then the variational stage,
/// refined from the PIV field where PIV measured at least half its vectors,
/// else from rest. Returns `(u, v, mode)`: `float32 (height, width)` arrays,
/// px per pair (v down), and "refine" or "pyramid".
#[pyfunction]
#[allow(clippy::type_complexity)]
fn dense<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
) -> PyResult<(
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray2<f32>>,
    &'static str,
)> {
    let ia = image(a, "a")?;
    let ib = image(b, "b")?;
    let (flow, mode) = py
        .detach(|| {
            run_piv(&ia, &ib, None, &spiv_host::piv::Settings::default())
                .map(|f| spiv_host::piv::dense::for_piv(&ia, &ib, &f))
        })
        .map_err(err)?;
    let d = flow.to_field();
    let (h, w) = (d.height, d.width);
    let arr = |v: Vec<f32>| {
        Array2::from_shape_vec((h, w), v).map_err(|e| SpivError::new_err(e.to_string()))
    };
    let mode = match mode {
        spiv_host::piv::dense::DenseMode::Refine => "refine",
        spiv_host::piv::dense::DenseMode::Pyramid => "pyramid",
    };
    Ok((arr(d.u)?.into_pyarray(py), arr(d.v)?.into_pyarray(py), mode))
}

/// `v` as an array of `shape` (a Python error if the lengths disagree).
fn array2<T>(shape: (usize, usize), v: Vec<T>) -> PyResult<Array2<T>> {
    Array2::from_shape_vec(shape, v).map_err(|e| SpivError::new_err(e.to_string()))
}

#[cfg(feature = "sim")]
/// `v` as an array of `shape` (a Python error if the lengths disagree).
fn array3<T>(shape: (usize, usize, usize), v: Vec<T>) -> PyResult<Array3<T>> {
    Array3::from_shape_vec(shape, v).map_err(|e| SpivError::new_err(e.to_string()))
}

/// The flow job on a spike recording (the same as `spiv flow`, without
/// the files): frame pairs through the core's closed loop, PIV of each.
///
/// `path` is a Vidar `.dat` (size from `width`/`height` or the
/// `scene.json` beside it) or a `.npz` capture; `dt` ticks between a
/// pair's frames (default: scene.json's), `every` between pairs (default
/// 4·dt), `start`/`end` ticks; `method` "ladder" (default, the time
/// ladder), "adaptive", "tfp" or "tfi"; `window` ticks; `dwell_cap` px or None (off); `windows` the PIV
/// passes, px; `dense` also runs the dense stage on every pair;
/// `pixel_size` (mm) and `tick_hz` calibrate it (default: the
/// `scene.json` beside the file); `mask` (nonzero = left out, the frames'
/// `(height, width)`) leaves a wall, a body or a region outside the flow
/// out: nodes whose centre it covers are invalid in every pair; `pairs`
/// `(a, b)` measures only pairs `a..b` of the schedule (`flow_pairs`);
/// `segment` splits the pairs into independent loops of that many pairs,
/// each from nothing (run in parallel; `spiv.dask` spreads them).
/// `progress` a callable told `(pairs done, pairs)` as pairs finish, or
/// `True` for a tqdm bar (needs tqdm); `y_up` gives y up from the bottom
/// row's centre and v positive up (so that vorticity is positive
/// counterclockwise and plots with y up show the image upright), with
/// `y_up` True in the dict.
///
/// Ctrl-C stops the run between pairs: `KeyboardInterrupt` is raised with
/// the pairs measured so far as its `partial` attribute (the dict or
/// Dataset this call returns, over those pairs; None if none was done).
/// An exception raised by `progress` stops it the same way.
///
/// Returns a dict: `ticks` `int64 (pairs, 2)`, `methods` (each pair's),
/// `x`, `y` `(ny, nx)`, `u`, `v`, `flags`, and each vector's standard
/// uncertainty `sigma_u`, `sigma_v` (px per pair, inf where invalid)
/// `(pairs, ny, nx)`, and the robust mean field over pairs (per node the
/// median of the valid vectors) `mean_u`, `mean_v`, `mean_flags`,
/// `mean_sigma_u`, `mean_sigma_v` and `mean_pairs` (valid vectors per
/// node) `(ny, nx)`; with `dense`, `mean_dense_u`, `mean_dense_v`
/// `float32 (height, width)`; calibrated, `pixel_size`, `tick_hz` and
/// `u_m_s`, `v_m_s`, `mean_u_m_s`, `mean_v_m_s` (m/s, v down), else
/// `pixel_size` and `tick_hz` None. With `as_xarray`, an xarray Dataset
/// in pivpy's layout instead: dimensions `y, x, t`, variables `u, v`,
/// `chc` (the flags), `sigma_u, sigma_v`, and the mean field as `mean_u`,
/// `mean_v`, `mean_chc`, `mean_sigma_u`, `mean_sigma_v`, `mean_pairs` on
/// `y, x`, in m, s and m/s when calibrated (else px, ticks and px per
/// pair), so `ds.piv.vorticity()` works.
#[pyfunction]
#[pyo3(signature = (path, dt=None, every=None, start=None, end=None, method="ladder", window=None, dwell_cap=Some(spiv_host::dwell::DWELL_CAP), windows=None, width=None, height=None, flip=true, strip_head=0, dense=false, pixel_size=None, tick_hz=None, as_xarray=false, mask=None, pairs=None, progress=None, y_up=false, segment=None))]
#[allow(clippy::too_many_arguments)]
fn flow<'py>(
    py: Python<'py>,
    path: PathBuf,
    dt: Option<i64>,
    every: Option<i64>,
    start: Option<i64>,
    end: Option<i64>,
    method: &str,
    window: Option<i64>,
    dwell_cap: Option<f64>,
    windows: Option<Vec<usize>>,
    width: Option<u16>,
    height: Option<u16>,
    flip: bool,
    strip_head: u16,
    dense: bool,
    pixel_size: Option<f64>,
    tick_hz: Option<f64>,
    as_xarray: bool,
    mask: Option<&Bound<'py, PyAny>>,
    pairs: Option<(i64, i64)>,
    progress: Option<&Bound<'py, PyAny>>,
    y_up: bool,
    segment: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    let mask = mask
        .map(|m| image(m, "mask").map(|m| m.mapv(|v| v != 0.0)))
        .transpose()?;
    let req = FlowRequest {
        dt: ticks("dt", dt, 1)?,
        every: ticks("every", every, 1)?,
        start: ticks("start", start, 0)?,
        end: ticks("end", end, 0)?,
        method: method_named(method)?,
        window: ticks("window", window, 0)?,
        dwell_cap,
        windows,
        dense,
        joint: true,
        pixel_mm: pixel_size,
        tick_hz,
        mask,
        pairs: pairs
            .map(|(a, b)| -> PyResult<_> {
                let index = |x: i64| {
                    usize::try_from(x).map_err(|_| {
                        SpivError::new_err(format!("pairs ({a}, {b}): indices start at 0"))
                    })
                };
                Ok(index(a)?..index(b)?)
            })
            .transpose()?,
        segment,
    };
    let fopts = file_options(width, height, flip, strip_head)?;
    let (rec, o) = py
        .detach(|| -> Result<_, Failure> {
            let rec = Recording::open(&path, &fopts)?;
            let o = req.options(&rec, &path)?;
            Ok((rec, spiv_host::flow::FlowOptions { y_up, ..o }))
        })
        .map_err(err)?;
    let progress = match progress {
        Some(p) if p.is_truthy()? && !p.is_callable() => Some(
            py.import("spiv._progress")?
                .getattr("tqdm_bar")?
                .call1((o.pair_ticks().len(),))?,
        ),
        Some(p) if p.is_callable() => Some(p.clone()),
        _ => None,
    };
    let (out, stopped) = interruptible(py, &rec, &o, progress.as_ref())?;
    let dict = |mut out: spiv_host::flow::FlowOutcome| -> PyResult<Bound<'py, PyAny>> {
        if y_up {
            out.flip_y();
        }
        let d = flow_dict(py, out)?;
        d.set_item("y_up", y_up)?;
        calibrated(&d, o.calibration, f64::from(o.dt))?;
        if !as_xarray {
            return Ok(d.into_any());
        }
        // pivpy's layout, built by xarray itself (python/pysrc/spiv/_xarray.py).
        py.import("spiv._xarray")?.getattr("to_xarray")?.call1((d,))
    };
    if let Some(e) = stopped {
        // The pairs measured before the interruption ride on the exception.
        let partial = if out.pairs.is_empty() {
            py.None().into_bound(py)
        } else {
            dict(out)?
        };
        e.value(py).setattr("partial", partial)?;
        return Err(e);
    }
    dict(out)
}

/// Runs `run_flow` on a worker thread while this one, holding the GIL
/// every 20 ms, reports progress (`progress(done, total)`) and checks for
/// signals. Ctrl-C (or an exception from `progress`) stops the run
/// between pairs: the outcome holds the pairs measured so far, and the
/// exception is returned beside it to be raised.
fn interruptible(
    py: Python<'_>,
    rec: &Recording,
    o: &spiv_host::flow::FlowOptions,
    progress: Option<&Bound<'_, PyAny>>,
) -> PyResult<(spiv_host::flow::FlowOutcome, Option<PyErr>)> {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    let stop = AtomicBool::new(false);
    let done = AtomicUsize::new(0);
    let total = o.pair_ticks().len();
    let mut stopped: Option<PyErr> = None;
    let joined = std::thread::scope(|s| {
        let worker = s.spawn(|| {
            spiv_host::flow::run_flow_until(rec, o, |i, _| done.store(i, Ordering::Relaxed), &stop)
        });
        let mut told = 0;
        loop {
            let finished = py.detach(|| {
                for _ in 0..4 {
                    if worker.is_finished() {
                        return true;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
                worker.is_finished()
            });
            let n = done.load(Ordering::Relaxed);
            if n != told && stopped.is_none() {
                told = n;
                if let Some(Err(e)) = progress.map(|p| p.call1((n, total))) {
                    stop.store(true, Ordering::Relaxed);
                    stopped = Some(e);
                }
            }
            if stopped.is_none() {
                if let Err(e) = py.check_signals() {
                    stop.store(true, Ordering::Relaxed);
                    stopped = Some(e);
                }
            }
            if finished {
                break;
            }
        }
        py.detach(|| worker.join())
    });
    let out = joined
        .map_err(|_| SpivError::new_err("the flow run failed unexpectedly (a worker panicked)"))?
        .map_err(err)?;
    Ok((out, stopped))
}

/// The pairs `flow` measures with these options: their frame ticks,
/// `int64 (pairs, 2)`. `flow(..., pairs=(a, b), segment=FLOW_SEGMENT)`
/// measures pairs `a..b` of them; when `a` is a multiple of
/// `FLOW_SEGMENT` those pairs' vectors are exactly the ones
/// `flow(..., segment=FLOW_SEGMENT)` gives, which is how `spiv.dask`
/// spreads a recording over workers.
#[pyfunction]
#[pyo3(signature = (path, dt=None, every=None, start=None, end=None, method="ladder", width=None, height=None, flip=true, strip_head=0))]
#[allow(clippy::too_many_arguments)]
fn flow_pairs<'py>(
    py: Python<'py>,
    path: PathBuf,
    dt: Option<i64>,
    every: Option<i64>,
    start: Option<i64>,
    end: Option<i64>,
    method: &str,
    width: Option<u16>,
    height: Option<u16>,
    flip: bool,
    strip_head: u16,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let req = FlowRequest {
        dt: ticks("dt", dt, 1)?,
        every: ticks("every", every, 1)?,
        start: ticks("start", start, 0)?,
        end: ticks("end", end, 0)?,
        method: method_named(method)?,
        ..FlowRequest::default()
    };
    let fopts = file_options(width, height, flip, strip_head)?;
    let o = py
        .detach(|| -> Result<_, Failure> {
            let rec = Recording::open(&path, &fopts)?;
            Ok(req.options(&rec, &path)?)
        })
        .map_err(err)?;
    let ticks = o.pair_ticks();
    let dt = i64::from(o.dt);
    let a = Array2::from_shape_fn((ticks.len(), 2), |(i, j)| ticks[i] as i64 + dt * j as i64);
    Ok(a.into_pyarray(py))
}

/// A count of ticks from Python (any int): at least `min` and within the
/// range of `T`, else a `SpivError` naming the argument.
fn ticks<T: TryFrom<i64>>(name: &str, v: Option<i64>, min: i64) -> PyResult<Option<T>> {
    v.map(|x| {
        if x < min {
            return Err(SpivError::new_err(format!(
                "{name} {x}: expected a whole number of ticks, at least {min}"
            )));
        }
        T::try_from(x).map_err(|_| SpivError::new_err(format!("{name} {x}: too many ticks")))
    })
    .transpose()
}

/// The `.dat` reading options of `flow` and `flow_pairs`.
fn file_options(
    width: Option<u16>,
    height: Option<u16>,
    flip: bool,
    strip_head: u16,
) -> PyResult<FileOptions> {
    if width.is_some() != height.is_some() {
        return Err(SpivError::new_err("give both width and height, or neither"));
    }
    Ok(FileOptions {
        width,
        height,
        dat: DatOptions {
            flip,
            strip_head,
            allow_truncated: false,
        },
    })
}

/// The robust mean field of a flow dict's pairs (`x`, `y`, `u`, `v`,
/// `flags`, `sigma_u`, `sigma_v`, as `flow` returns them, pairs stacked
/// along the first axis; `pixel_size`, `tick_hz` and `ticks` for the m/s
/// arrays): sets `mean_u`, `mean_v`, `mean_flags`, `mean_sigma_u`,
/// `mean_sigma_v`, `mean_pairs` (and `mean_u_m_s`, `mean_v_m_s` when
/// calibrated) in the dict, as `flow` computes them, and returns it. This
/// is how `spiv.dask` joins the pairs of several workers.
#[pyfunction]
fn flow_mean<'py>(d: Bound<'py, PyDict>) -> PyResult<Bound<'py, PyDict>> {
    let get = |name: &str| -> PyResult<Bound<'py, PyAny>> {
        d.get_item(name)?
            .ok_or_else(|| SpivError::new_err(format!("flow dict without {name}")))
    };
    let f64s = |name: &str| -> PyResult<Array3<f64>> {
        let a = contiguous(&get(name)?, "float64")?;
        Ok(a.extract::<PyReadonlyArray3<f64>>()?.as_array().to_owned())
    };
    let (u, v, su, sv) = (f64s("u")?, f64s("v")?, f64s("sigma_u")?, f64s("sigma_v")?);
    let flags = contiguous(&get("flags")?, "uint8")?
        .extract::<PyReadonlyArray3<u8>>()?
        .as_array()
        .to_owned();
    let x2 = |name: &str| -> PyResult<Array2<f64>> {
        let a = contiguous(&get(name)?, "float64")?;
        Ok(a.extract::<PyReadonlyArray2<f64>>()?.as_array().to_owned())
    };
    let (x, y) = (x2("x")?, x2("y")?);
    let (p, ny, nx) = u.dim();
    let shapes = [v.dim(), su.dim(), sv.dim(), flags.dim()];
    if shapes.iter().any(|&s| s != (p, ny, nx)) || x.dim() != (ny, nx) || y.dim() != (ny, nx) {
        return Err(SpivError::new_err(
            "flow dict: u, v, flags, sigma_u, sigma_v must be (pairs, ny, nx) and x, y (ny, nx)",
        ));
    }
    let state = |f: u8| match f {
        0 => Ok(State::Valid),
        1 => Ok(State::Replaced),
        2 => Ok(State::Invalid),
        _ => Err(SpivError::new_err(format!("flag {f}: expected 0, 1 or 2"))),
    };
    let mut fields = Vec::with_capacity(p);
    for i in 0..p {
        let mut vectors = Vec::with_capacity(ny * nx);
        let mut sigma = Vec::with_capacity(ny * nx);
        for r in 0..ny {
            for c in 0..nx {
                vectors.push(Vector {
                    x: x[[r, c]],
                    y: y[[r, c]],
                    u: u[[i, r, c]],
                    v: v[[i, r, c]],
                    state: state(flags[[i, r, c]])?,
                });
                sigma.push((su[[i, r, c]], sv[[i, r, c]]));
            }
        }
        fields.push((vectors, sigma));
    }
    let refs: Vec<_> = fields
        .iter()
        .map(|(v, s)| (v.as_slice(), s.as_slice()))
        .collect();
    let mean = MeanField::of(&refs);
    mean_items(&d, &mean, (ny, nx))?;
    let number = |name: &str| -> PyResult<Option<f64>> {
        d.get_item(name)?.map(|a| a.extract()).transpose()
    };
    let calibration = match (number("pixel_size")?, number("tick_hz")?) {
        (Some(mm), Some(hz)) => {
            Some(Calibration::new(mm, hz).map_err(|e| SpivError::new_err(e.to_string()))?)
        }
        _ => None,
    };
    if calibration.is_some() {
        let ticks = get("ticks")?;
        let t = contiguous(&ticks, "int64")?
            .extract::<PyReadonlyArray2<i64>>()?
            .as_array()
            .to_owned();
        let dt = t
            .row(0)
            .get(1)
            .zip(t.row(0).first())
            .map_or(0, |(b, a)| b - a);
        if p == 0 || dt <= 0 {
            return Err(SpivError::new_err(
                "flow dict: ticks must hold the pairs' (first, second) ticks",
            ));
        }
        calibrated_means(&d, calibration, dt as f64)?;
    }
    Ok(d)
}

/// The mean field's arrays in a flow dict: `mean_u`, `mean_v`,
/// `mean_flags`, `mean_sigma_u`, `mean_sigma_v`, `mean_pairs`.
fn mean_items(d: &Bound<'_, PyDict>, mean: &MeanField, (ny, nx): (usize, usize)) -> PyResult<()> {
    let py = d.py();
    let (_, _, mu, mv, mf) = field_arrays_of(&mean.vectors, (ny, nx));
    let (msu, msv) = sigma_arrays(&mean.sigma, (ny, nx));
    let mpairs = Array2::from_shape_fn((ny, nx), |(r, c)| {
        mean.pairs.get(r * nx + c).copied().unwrap_or(0)
    });
    d.set_item("mean_u", mu.into_pyarray(py))?;
    d.set_item("mean_v", mv.into_pyarray(py))?;
    d.set_item("mean_flags", mf.into_pyarray(py))?;
    d.set_item("mean_sigma_u", msu.into_pyarray(py))?;
    d.set_item("mean_sigma_v", msv.into_pyarray(py))?;
    d.set_item("mean_pairs", mpairs.into_pyarray(py))?;
    Ok(())
}

/// With a calibration: `pixel_size` (mm), `tick_hz`, and every u, v
/// array again in m/s as `*_m_s` (pairs `dt` ticks apart); without one,
/// `pixel_size` and `tick_hz` are None.
fn calibrated(d: &Bound<'_, PyDict>, calibration: Option<Calibration>, dt: f64) -> PyResult<()> {
    let Some(c) = calibration else {
        d.set_item("pixel_size", None::<f64>)?;
        d.set_item("tick_hz", None::<f64>)?;
        return Ok(());
    };
    d.set_item("pixel_size", c.pixel_mm)?;
    d.set_item("tick_hz", c.tick_hz)?;
    in_m_s(d, &["u", "v", "mean_u", "mean_v"], c, dt)
}

/// The mean field's m/s arrays (`mean_u_m_s`, `mean_v_m_s`).
fn calibrated_means(
    d: &Bound<'_, PyDict>,
    calibration: Option<Calibration>,
    dt: f64,
) -> PyResult<()> {
    match calibration {
        Some(c) => in_m_s(d, &["mean_u", "mean_v"], c, dt),
        None => Ok(()),
    }
}

/// `name_m_s` = `name` (px per pair, pairs `dt` ticks apart) in m/s.
fn in_m_s(d: &Bound<'_, PyDict>, names: &[&str], c: Calibration, dt: f64) -> PyResult<()> {
    let k = c.m_per_s(1.0, dt);
    for &name in names {
        if let Some(a) = d.get_item(name)? {
            d.set_item(format!("{name}_m_s"), a.call_method1("__mul__", (k,))?)?;
        }
    }
    Ok(())
}

/// [`flow`]'s dict: the pairs' fields stacked along the first axis, the
/// mean field, and the mean dense field if there is one.
fn flow_dict(py: Python<'_>, out: spiv_host::flow::FlowOutcome) -> PyResult<Bound<'_, PyDict>> {
    let grid = &out.grid;
    let (ny, nx) = (grid.ny, grid.nx);
    let p = out.pairs.len();
    let mut us = Array3::<f64>::zeros((p, ny, nx));
    let mut vs = Array3::<f64>::zeros((p, ny, nx));
    let mut fs = Array3::<u8>::zeros((p, ny, nx));
    let mut sus = Array3::<f64>::zeros((p, ny, nx));
    let mut svs = Array3::<f64>::zeros((p, ny, nx));
    let mut ticks = Array2::<i64>::zeros((p, 2));
    let mut methods = Vec::with_capacity(p);
    let axis = numpy::ndarray::Axis(0);
    for (i, pr) in out.pairs.iter().enumerate() {
        let (_, _, u, v, f) = field_arrays(&pr.vectors, grid);
        us.index_axis_mut(axis, i).assign(&u);
        vs.index_axis_mut(axis, i).assign(&v);
        fs.index_axis_mut(axis, i).assign(&f);
        let (su, sv) = sigma_arrays(&pr.sigma, (ny, nx));
        sus.index_axis_mut(axis, i).assign(&su);
        svs.index_axis_mut(axis, i).assign(&sv);
        ticks[[i, 0]] = pr.ticks[0] as i64;
        ticks[[i, 1]] = pr.ticks[1] as i64;
        methods.push(pr.method.name());
    }
    let mean = out.mean();
    let (x, y, ..) = field_arrays(&mean.vectors, grid);
    let d = PyDict::new(py);
    d.set_item("ticks", ticks.into_pyarray(py))?;
    d.set_item("methods", methods)?;
    d.set_item("x", x.into_pyarray(py))?;
    d.set_item("y", y.into_pyarray(py))?;
    d.set_item("u", us.into_pyarray(py))?;
    d.set_item("v", vs.into_pyarray(py))?;
    d.set_item("flags", fs.into_pyarray(py))?;
    d.set_item("sigma_u", sus.into_pyarray(py))?;
    d.set_item("sigma_v", svs.into_pyarray(py))?;
    mean_items(&d, &mean, (ny, nx))?;
    if let Some(m) = out.mean_dense {
        let (h, w) = (m.height, m.width);
        d.set_item("mean_dense_u", array2((h, w), m.u)?.into_pyarray(py))?;
        d.set_item("mean_dense_v", array2((h, w), m.v)?.into_pyarray(py))?;
    }
    Ok(d)
}

/// `spiv receive`: frames from a sidecar — a file of recorded messages
/// (`file`) or a sidecar listening at `tcp` ("host:port") — with PIV on
/// every pair (`windows`, px per pass; `None`: no PIV). With `control`,
/// the live closed loop: each pair's measured motion goes back to the
/// sidecar, on the TCP connection (`control=True`) or into a file or FIFO
/// (`control="path"`). `out` receives every frame (PNG) and the vectors.
/// Frames larger than `max_frame` (width, height) are counted as corrupt.
///
/// Returns a dict of counts: `bytes`, `messages`, `corrupted`,
/// `lost_messages`, `late_messages`, `frames`, `lost_frames`, `pairs`,
/// `broken_pairs`, `truncated_tail`, `vectors`, and with `control` also
/// `controls_sent`, `controls_with_motion`, `controls_with_grid`,
/// `controls_failed`.
#[pyfunction]
#[pyo3(signature = (file=None, tcp=None, windows=Some(vec![64, 32, 32]), control=None, out=None, max_frame=(8192, 8192)))]
#[allow(clippy::too_many_arguments)]
fn receive<'py>(
    py: Python<'py>,
    file: Option<PathBuf>,
    tcp: Option<String>,
    windows: Option<Vec<usize>>,
    control: Option<&Bound<'py, PyAny>>,
    out: Option<PathBuf>,
    max_frame: (u16, u16),
) -> PyResult<Bound<'py, PyDict>> {
    let spec = match (file, tcp) {
        (Some(f), None) => Spec::File(f),
        (None, Some(t)) => Spec::Tcp(t),
        _ => return Err(SpivError::new_err("give one of file or tcp")),
    };
    // control: None, True (back on the link) or a path.
    let control: Option<Option<PathBuf>> = match control {
        None => None,
        Some(c) if c.is_instance_of::<pyo3::types::PyBool>() => {
            if c.extract::<bool>()? {
                Some(None)
            } else {
                None
            }
        }
        Some(c) => Some(Some(c.extract::<PathBuf>()?)),
    };
    if control.is_some() && windows.is_none() {
        return Err(SpivError::new_err("control needs PIV: give windows"));
    }
    let opts = LiveOptions {
        max_frame: FrameLimit {
            width: max_frame.0,
            height: max_frame.1,
        },
        piv_windows: windows,
        out,
        motion_model: Default::default(),
        ladder: Default::default(),
    };
    let report = py
        .detach(|| {
            let mut source = spiv_host::receive::source::open(&spec)?;
            let downlink = match &control {
                None => None,
                Some(path) => Some(open_downlink(source.as_ref(), path.as_deref())?),
            };
            run_live(source.as_mut(), &opts, downlink, |_| {})
        })
        .map_err(err)?;
    let d = PyDict::new(py);
    let r = report.received;
    for (k, v) in [
        ("bytes", r.bytes),
        ("messages", r.messages),
        ("corrupted", r.corrupted),
        ("lost_messages", r.lost_messages),
        ("late_messages", r.late_messages),
        ("frames", r.frames),
        ("lost_frames", r.lost_frames),
        ("pairs", r.pairs),
        ("broken_pairs", r.broken_pairs),
        ("truncated_tail", r.truncated_tail),
    ] {
        d.set_item(k, v)?;
    }
    d.set_item("vectors", report.vectors)?;
    if let Some(c) = report.downlink {
        d.set_item("controls_sent", c.sent)?;
        d.set_item("controls_with_motion", c.with_motion)?;
        d.set_item("controls_with_grid", c.with_grid)?;
        d.set_item("controls_failed", c.failed)?;
    }
    Ok(d)
}

/// spiv: particle image velocimetry with spike cameras.
#[pymodule]
fn spiv(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SpivError", m.py().get_type::<SpivError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(read_dat, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(piv, m)?)?;
    m.add_function(wrap_pyfunction!(dense, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(flow, m)?)?;
    m.add_function(wrap_pyfunction!(flow_pairs, m)?)?;
    m.add_function(wrap_pyfunction!(flow_mean, m)?)?;
    m.add("FLOW_SEGMENT", spiv_host::flow::CHAIN)?;
    m.add_function(wrap_pyfunction!(receive, m)?)?;
    Ok(())
}
