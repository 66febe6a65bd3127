#!/usr/bin/env python3
"""spiv against OpenPIV's multi-pass windef on the same image pairs.

For every case folder (frame_a.png, frame_b.png, truth.csv as `spiv simulate`
writes them) this runs OpenPIV's first_pass + multipass_img_deform (the
pipeline of windef.process_image_pair: validation, replacement, symmetric
deformation, cubic interpolation) and `spiv piv` with the same windows and
overlap, and prints one table: RMS error against the truth, vectors used,
and the median wall time of the correlation (images already loaded, no
file output, warm) over --repeat interleaved rounds of OpenPIV and spiv.
Both engines use the threads this process's environment gives them
(RAYON_NUM_THREADS for spiv and OpenPIV's Rust backend, OMP_NUM_THREADS
and OPENBLAS_NUM_THREADS for numpy): bench/openpiv_compare.sh runs the
table on one thread and on two.

Both engines use the same windows, so vector k of each is compared to truth
vector k (OpenPIV labels a window's centre half a pixel lower-right than the
pixel-centre convention of docs/formats.md; the windows are identical).
"""
import argparse
import csv
import json
import os
import pathlib
import re
import statistics
import subprocess
import sys
import time

import numpy as np


def read_truth(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    x = np.array([float(r["x"]) for r in rows])
    y = np.array([float(r["y"]) for r in rows])
    u = np.array([float(r["u"]) for r in rows])
    v = np.array([float(r["v"]) for r in rows])
    return x, y, u, v


def read_spiv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    u = np.array([float(r["u"]) for r in rows])
    v = np.array([float(r["v"]) for r in rows])
    flag = np.array([int(r["flag"]) for r in rows])
    return u, v, flag


def openpiv_run(a, b, windows, overlap):
    import contextlib
    import io
    with contextlib.redirect_stdout(io.StringIO()):
        return _openpiv_run(a, b, windows, overlap)


def _openpiv_run(a, b, windows, overlap):
    from openpiv import windef, validation, filters
    from openpiv.settings import PIVSettings

    s = PIVSettings()
    s.windowsizes = tuple(windows)
    s.overlap = tuple(int(w * overlap) for w in windows)
    s.num_iterations = len(windows)
    s.show_all_plots = False
    x, y, u, v, s2n = windef.first_pass(a, b, s)
    mask = np.zeros_like(u, dtype=bool)
    u = np.ma.masked_array(u, mask=mask)
    v = np.ma.masked_array(v, mask=mask)
    flags = validation.typical_validation(u, v, s2n, s)
    u, v = filters.replace_outliers(
        u, v, flags, method=s.filter_method,
        max_iter=s.max_filter_iteration, kernel_size=s.filter_kernel_size)
    for i in range(1, s.num_iterations):
        u = np.ma.masked_array(u, np.ma.nomask)
        v = np.ma.masked_array(v, np.ma.nomask)
        x, y, u, v, grid_mask, flags = windef.multipass_img_deform(
            a, b, i, x, y, u, v, s)
    u = np.ma.filled(u, np.nan)
    v = np.ma.filled(v, np.nan)
    return x, y, np.asarray(u), np.asarray(v)


def load(path):
    import imageio.v3 as iio
    return iio.imread(path).astype(np.float64)


def rms(du, dv):
    ok = np.isfinite(du) & np.isfinite(dv)
    if not ok.any():
        return float("nan"), 0
    return float(np.sqrt(np.mean(du[ok] ** 2 + dv[ok] ** 2))), int(ok.sum())


def epe(du, dv):
    """Mean end-point error over the vectors used (optical-flow benchmarks' EPE)."""
    ok = np.isfinite(du) & np.isfinite(dv)
    return float(np.mean(np.hypot(du[ok], dv[ok]))) if ok.any() else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("cases", nargs="+", type=pathlib.Path)
    ap.add_argument("--spiv", default="target/release/spiv")
    ap.add_argument("--windows", default="64,32,32")
    ap.add_argument("--overlap", type=float, default=0.5)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--json", type=pathlib.Path)
    ap.add_argument("--spiv-args", default="", help="extra options for spiv piv")
    args = ap.parse_args()
    windows = [int(w) for w in args.windows.split(",")]
    try:
        import openpiv
        version = getattr(openpiv, "__version__", "?")
    except ImportError:
        sys.exit("openpiv is not installed: run bench/openpiv_compare.sh --install")
    from openpiv import pyprocess
    if not getattr(pyprocess, "HAS_RUST", False):
        sys.exit("OpenPIV's Rust backend is missing: run bench/openpiv_compare.sh --install")

    out = []
    hdr = (f"{'case':<22}{'size':>11}{'vectors':>9}{'OpenPIV rms px':>16}{'spiv rms px':>13}"
           f"{'OpenPIV EPE':>13}{'spiv EPE':>10}{'spiv used':>11}"
           f"{'OpenPIV ms':>12}{'spiv ms':>9}{'speed-up':>10}")
    print(f"OpenPIV {version} windef (Rust backend) vs spiv, windows {args.windows}, overlap {args.overlap}; "
          f"medians of {args.repeat} interleaved rounds; "
          f"threads {os.environ.get('RAYON_NUM_THREADS', 'all')}")
    print(hdr)
    print("-" * len(hdr))
    for case in args.cases:
        a, b = load(case / "frame_a.png"), load(case / "frame_b.png")
        tx, ty, tu, tv = read_truth(case / "truth.csv")
        vec = case / "spiv_vectors.csv"

        def spiv_ms():
            # One process, the images read once, the PIV run 5 times: the
            # median of warm runs (spiv piv --repeat), OpenPIV likewise warm.
            r = subprocess.run(
                [args.spiv, "piv", str(case / "frame_a.png"), str(case / "frame_b.png"),
                 "-o", str(vec), "--windows", args.windows, "--overlap", str(args.overlap),
                 "--repeat", "5"] + args.spiv_args.split(),
                check=True, capture_output=True, text=True)
            return float(re.search(r"([0-9.]+) ms", r.stdout).group(1))

        # Interleaved rounds, so that load on a shared machine falls on
        # both alike.
        o_times, s_times = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            ox, oy, ou, ov = openpiv_run(a, b, windows, args.overlap)
            o_times.append(time.perf_counter() - t0)
            s_times.append(spiv_ms())
        o_ms = statistics.median(o_times) * 1e3
        s_ms = statistics.median(s_times)
        ou, ov = ou.ravel(), ov.ravel()
        if ou.size != tu.size:
            sys.exit(f"{case}: OpenPIV gave {ou.size} vectors, truth has {tu.size}")
        o_rms, o_n = rms(ou - tu, ov - tv)
        su, sv, flag = read_spiv(vec)
        du, dv = su - tu, sv - tv
        du[flag == 2] = np.nan
        s_rms, s_n = rms(du, dv)
        h, w = a.shape
        o_epe, s_epe = epe(ou - tu, ov - tv), epe(du, dv)
        print(f"{case.name:<22}{f'{w}x{h}':>11}{tu.size:>9}{o_rms:>16.4f}{s_rms:>13.4f}"
              f"{o_epe:>13.4f}{s_epe:>10.4f}{s_n:>11}"
              f"{o_ms:>12.1f}{s_ms:>9.1f}{o_ms / s_ms:>9.1f}x")
        out.append(dict(case=case.name, width=w, height=h, vectors=int(tu.size),
                        openpiv_rms=o_rms, openpiv_used=o_n, spiv_rms=s_rms, spiv_used=s_n,
                        openpiv_epe=o_epe, spiv_epe=s_epe,
                        openpiv_ms=o_ms, spiv_ms=s_ms,
                        threads=os.environ.get("RAYON_NUM_THREADS", "all")))
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
