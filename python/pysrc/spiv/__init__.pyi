"""spiv: particle image velocimetry with spike cameras (type stubs).

Conventions: images and spike planes are upright arrays, row 0 at the top,
indexed [row, column] (spikes [tick, row, column]). Vector fields are 2-D
arrays (ny, nx) on the PIV grid: x to the right and y down the rows, in
pixels (pixel centres on integers); u and v in pixels per pair, v positive
down the rows, as in `spiv piv`'s CSV and OpenPIV's windef output before
tools.transform_coordinates. Flags: 0 valid, 1 replaced from neighbours,
2 masked or invalid (then u = v = NaN). Ticks are spike planes (1/20 000 s at 20 kHz).
"""

from os import PathLike
from typing import Any, Callable, Dict, Literal, Optional, Sequence, Tuple, TypedDict, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str

class SpivError(ValueError):
    """A value spiv refuses; the message is the `spiv` CLI's one line."""

_Path = Union[str, PathLike]
_F64 = npt.NDArray[np.float64]

def read_dat(
    path: _Path,
    width: Optional[int] = None,
    height: Optional[int] = None,
    flip: bool = True,
    strip_head: int = 0,
    start: int = 0,
    count: Optional[int] = None,
) -> npt.NDArray[np.uint8]:
    """Spike planes of a Vidar .dat: uint8 0/1, (ticks, height, width - strip_head), upright.

    width, height: px (default: the scene.json beside the file).
    flip: False for files whose rows are stored upright.
    strip_head: columns dropped at the right of every row (16 for 416-wide captures).
    start, count: the planes (ticks) to read. At most 2**31 bytes are returned.
    """

def read_image(path: _Path) -> npt.NDArray[np.uint16]:
    """A gray PNG/TIFF/BMP (8- or 16-bit) as uint16 (height, width)."""

def reconstruct(
    spikes: npt.ArrayLike,
    at: int,
    method: str = "adaptive",
    window: Optional[int] = None,
    full_scale: int = 255,
) -> npt.NDArray[np.uint16]:
    """One frame from spikes (ticks, height, width; nonzero = spike) at tick `at`.

    method: "adaptive" (the paper's), "tfp" or "tfi".
    window: TFP window or adaptive/TFI n_max, ticks (default 8 for TFP, else 128).
    Returns gray levels 0..=full_scale, (height, width), upright.
    """

@overload
def piv(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    windows: Sequence[int] = (64, 32, 32),
    overlap: float = 0.5,
    mask: Optional[npt.ArrayLike] = None,
    interp: str = "bspline",
    median_threshold: float = 2.0,
    clip: str = "auto",
    highpass: float = 3.0,
    subpixel: str = "parabolic",
    min_peak_ratio: float = 1.5,
    dense_fallback: bool = True,
    confidence: Literal[False] = False,
) -> Tuple[_F64, _F64, _F64, _F64, npt.NDArray[np.uint8]]:
    """PIV on an image pair (height, width), as `spiv piv`: returns (x, y, u, v, flags), each (ny, nx).

    windows: window side of each pass, px (4..=1024). overlap: 0..=0.9.
    mask: nonzero pixels are excluded. interp: bspline, bspline5, bicubic, bilinear.
    median_threshold: normalised median test (0 off). clip: "auto", "off" or a gray level.
    highpass: background blur sigma, px (0 off). subpixel: parabolic, gaussian, gaussian2d.
    min_peak_ratio: correlation peak ratio floor (1 off).
    dense_fallback: where the last pass fails as a whole, the dense stage's vectors (flag 1).
    x, y: window centres, px; u, v: px per pair (v down); flags 0/1/2.
    confidence: also return peak_ratio and correlation (float64, (ny, nx); 0 where no peak),
    as the CSV's columns: (x, y, u, v, flags, peak_ratio, correlation).
    """

@overload
def piv(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    windows: Sequence[int] = (64, 32, 32),
    overlap: float = 0.5,
    mask: Optional[npt.ArrayLike] = None,
    interp: str = "bspline",
    median_threshold: float = 2.0,
    clip: str = "auto",
    highpass: float = 3.0,
    subpixel: str = "parabolic",
    min_peak_ratio: float = 1.5,
    dense_fallback: bool = True,
    *,
    confidence: Literal[True],
) -> Tuple[_F64, _F64, _F64, _F64, npt.NDArray[np.uint8], _F64, _F64]: ...

def dense(
    a: npt.ArrayLike, b: npt.ArrayLike
) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], str]:
    """The dense flow, one vector per pixel, as `spiv piv --dense`: (u, v, mode).

    u, v: float32 (height, width), px per pair, v down. mode: "refine" (from the
    PIV field, which measured at least half its vectors) or "pyramid" (from rest).
    """

class Truth(TypedDict):
    x: _F64
    y: _F64
    u: _F64
    v: _F64

class DenseTruth(TypedDict):
    u: npt.NDArray[np.float32]
    v: npt.NDArray[np.float32]

class Simulation(TypedDict):
    spikes: npt.NDArray[np.uint8]
    frames: npt.NDArray[np.uint16]
    frame_full_scale: int
    pair: Tuple[int, int]
    truth: Truth
    truth_dense: DenseTruth

def simulate(
    scene: str = "paper-linear",
    seed: int = 1,
    width: Optional[int] = None,
    height: Optional[int] = None,
    ticks: Optional[int] = None,
    dt: Optional[int] = None,
    shift: Optional[Tuple[float, float]] = None,
    spacing: Optional[float] = None,
    out: Optional[_Path] = None,
    speed: Optional[float] = None,
    flow_seed: Optional[int] = None,
) -> Simulation:
    """A simulated recording, as `spiv simulate`.

    scene: paper-linear, paper-quadratic, paper-log, blasius, uniform, vortex, turbulence, large-shift.
    width, height: px. ticks: planes. dt: ticks between the pair's frames.
    shift: the uniform scene's (u, v), px per pair. spacing: minimum particle spacing, px.
    out: a folder to also write `spiv simulate`'s files to (spikes.dat, scene.json, ...).
    Returns spikes uint8 (ticks, height, width), the frame camera's pair uint16
    (2, height, width) with frame_full_scale, the pair's ticks, and the truth
    (x, y, u, v on the 32-px grid with a 16-px step, px per pair) and truth_dense
    (u, v per pixel, float32 (height, width)).
    """

class Flow(TypedDict):
    ticks: npt.NDArray[np.int64]
    methods: list
    x: _F64
    y: _F64
    u: _F64
    v: _F64
    flags: npt.NDArray[np.uint8]
    sigma_u: _F64
    sigma_v: _F64
    mean_u: _F64
    mean_v: _F64
    mean_flags: npt.NDArray[np.uint8]
    mean_sigma_u: _F64
    mean_sigma_v: _F64
    mean_pairs: npt.NDArray[np.uint32]
    mean_dense_u: npt.NDArray[np.float32]  # only with dense=True
    mean_dense_v: npt.NDArray[np.float32]
    pixel_size: Optional[float]  # mm; None when uncalibrated
    tick_hz: Optional[float]
    u_m_s: _F64  # only when calibrated; m/s, v down
    v_m_s: _F64
    mean_u_m_s: _F64
    mean_v_m_s: _F64

def flow(
    path: _Path,
    dt: Optional[int] = None,
    every: Optional[int] = None,
    start: Optional[int] = None,
    end: Optional[int] = None,
    method: str = "ladder",
    window: Optional[int] = None,
    dwell_cap: Optional[float] = 8.0,
    windows: Optional[Sequence[int]] = None,
    width: Optional[int] = None,
    height: Optional[int] = None,
    flip: bool = True,
    strip_head: int = 0,
    dense: bool = False,
    pixel_size: Optional[float] = None,
    tick_hz: Optional[float] = None,
    as_xarray: bool = False,
    mask: Optional[npt.ArrayLike] = None,
    pairs: Optional[Tuple[int, int]] = None,
    progress: Union[None, bool, Callable[[int, int], Any]] = None,
    y_up: bool = False,
    segment: Optional[int] = None,
) -> Flow:  # an xarray.Dataset with as_xarray=True
    """The flow job on a .dat or .npz recording, as `spiv flow` (without its files).

    dt: ticks between a pair's frames (default: scene.json's); every: between pairs
    (default 4*dt); start, end: ticks. method: "ladder" (the time ladder, the
    default), "adaptive", "tfp" or "tfi". window: ticks. dwell_cap: px, or None for off.
    windows: PIV passes, px. dense: also the dense stage per pair, averaged.
    Returns per-pair u, v, flags and uncertainties sigma_u, sigma_v (px per pair,
    inf where invalid) (pairs, ny, nx), the grid x, y (ny, nx), each pair's ticks
    and method, the robust mean field (per node the median of the valid vectors,
    its uncertainty and mean_pairs, the count of valid vectors), and with dense
    the mean dense field. pixel_size (mm) and tick_hz calibrate it (default: the
    scene.json beside the file): then u_m_s, v_m_s, mean_u_m_s, mean_v_m_s in m/s.
    as_xarray: an xarray.Dataset in pivpy's layout instead (dims y, x, t; u, v, chc,
    sigma_u, sigma_v; the mean field as mean_u, mean_v, mean_chc, mean_sigma_u,
    mean_sigma_v, mean_pairs on (y, x); m, s and m/s when calibrated), so
    ds.piv.vorticity() works. mask: nonzero pixels (height, width) left out; nodes
    whose centre it covers are invalid in every pair. pairs: (a, b) measures only
    pairs a..b of flow_pairs(). segment: independent loops of that many pairs,
    each from nothing, run in parallel; with segment=FLOW_SEGMENT and pairs from a
    multiple of it, exactly the vectors flow(..., segment=FLOW_SEGMENT) gives them.
    progress: a callable told (pairs done, pairs),
    or True for a tqdm bar. Ctrl-C stops the run between pairs and raises
    KeyboardInterrupt with the pairs measured so far as its .partial (None if none).
    y_up: y up from the bottom row's centre and v positive up, so that vorticity is
    positive counterclockwise and plots with y up show the image upright.
    """

def open_flow(path: _Path) -> Any:
    """spiv flow's flow.nc as the xarray Dataset flow(as_xarray=True) gives
    (pivpy's layout; SI units when calibrated)."""

#: Pairs per segment of `spiv.dask.flow`: a run of pairs from a multiple of it,
#: with segment=FLOW_SEGMENT, matches a whole run with the same segments.
FLOW_SEGMENT: int

def flow_pairs(
    path: _Path,
    dt: Optional[int] = None,
    every: Optional[int] = None,
    start: Optional[int] = None,
    end: Optional[int] = None,
    method: str = "ladder",
    width: Optional[int] = None,
    height: Optional[int] = None,
    flip: bool = True,
    strip_head: int = 0,
) -> npt.NDArray[np.int64]:
    """The pairs flow() measures with these options: their frame ticks (pairs, 2)."""

def flow_mean(d: Flow) -> Flow:
    """Sets the robust mean field (mean_u, mean_v, mean_flags, mean_sigma_u,
    mean_sigma_v, mean_pairs, and mean_*_m_s when calibrated) of a flow dict's
    stacked pairs, as flow() computes it, and returns the dict."""

def receive(
    file: Optional[_Path] = None,
    tcp: Optional[str] = None,
    windows: Optional[Sequence[int]] = (64, 32, 32),
    control: Union[None, bool, _Path] = None,
    out: Optional[_Path] = None,
    max_frame: Tuple[int, int] = (8192, 8192),
) -> Dict[str, int]:
    """Frames from a sidecar, as `spiv receive`: a file of recorded messages or a
    sidecar listening at tcp ("host:port"). windows: PIV passes (px) on every pair,
    None for frames only. control: the live closed loop, each pair's measured motion
    sent back on the TCP connection (True) or into a file or FIFO (a path). out:
    every frame (PNG) and the vectors. Frames larger than max_frame are corrupt.
    Returns the counts: bytes, messages, corrupted, lost_messages, late_messages,
    frames, lost_frames, pairs, broken_pairs, truncated_tail, vectors, and with
    control controls_sent, controls_with_motion, controls_failed.
    """
    ...
