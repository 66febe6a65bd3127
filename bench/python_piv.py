#!/usr/bin/env python3
"""spiv.piv called from Python against OpenPIV's windef, on the same numpy
arrays in the same process: median wall time and RMS error against the
truth, speed against error, on one core and on two.

    python3 -m venv bench/.venv
    MATURIN_PEP517_ARGS="--features sim" bench/.venv/bin/pip install ./python "openpiv[rust]==0.26.1"
    bench/.venv/bin/python bench/python_piv.py [--size 1024] [--repeat 7] [--threads 1,2]

The pair is the frame camera's of `spiv.simulate("uniform")` (2.6, 1.4 px
per pair); both engines run windows 64, 32, 32 at 50 % overlap (the same
grid as the truth). OpenPIV runs as in bench/openpiv_compare.py (first
pass, validation, replacement, two deformation passes) with its Rust
backend (`openpiv[rust]`); the script stops if that backend is missing.

Each thread count runs in its own process with RAYON_NUM_THREADS,
OMP_NUM_THREADS and OPENBLAS_NUM_THREADS set to it, so both engines (and
numpy under OpenPIV) see the same number of threads: rayon's pool is sized
once per process.
"""
import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from openpiv_compare import openpiv_run  # noqa: E402

THREAD_VARS = ("RAYON_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def rms(u, v, tu, tv, ok):
    du, dv = (u - tu)[ok], (v - tv)[ok]
    return float(np.sqrt(np.mean(du ** 2 + dv ** 2))), int(ok.sum())


def measure(size, repeat):
    """One thread setting, in this process: both engines' medians and RMS."""
    import spiv
    from openpiv import pyprocess

    if not getattr(pyprocess, "HAS_RUST", False):
        sys.exit("OpenPIV's Rust backend is missing: pip install 'openpiv[rust]'")
    sim = spiv.simulate("uniform", seed=5, width=size, height=size, shift=(2.6, 1.4))
    fa, fb = (f.astype(np.float64) for f in sim["frames"])
    t = sim["truth"]
    windows = [64, 32, 32]
    s_times, o_times = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        x, y, u, v, flags = spiv.piv(fa, fb, windows=windows, overlap=0.5)
        s_times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ox, oy, ou, ov = openpiv_run(fa, fb, windows, 0.5)
        o_times.append(time.perf_counter() - t0)
    if ou.shape != t["u"].shape:
        sys.exit(f"OpenPIV gave a {ou.shape} grid, the truth is {t['u'].shape}")
    s_rms, s_n = rms(u, v, t["u"], t["v"], flags < 2)
    o_rms, o_n = rms(ou, ov, t["u"], t["v"], np.isfinite(ou) & np.isfinite(ov))
    import openpiv
    return dict(spiv_ms=statistics.median(s_times) * 1e3, spiv_rms=s_rms, spiv_n=s_n,
                openpiv_ms=statistics.median(o_times) * 1e3, openpiv_rms=o_rms,
                openpiv_n=o_n, openpiv=getattr(openpiv, "__version__", "?"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--threads", default="1,2", help="thread counts, comma-separated")
    ap.add_argument("--json", type=pathlib.Path)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(measure(a.size, a.repeat)))
        return
    rows = []
    for n in (int(x) for x in a.threads.split(",")):
        env = dict(os.environ, **{k: str(n) for k in THREAD_VARS})
        out = subprocess.run(
            [sys.executable, __file__, "--child", "--size", str(a.size), "--repeat", str(a.repeat)],
            env=env, check=True, capture_output=True, text=True).stdout
        rows.append(dict(threads=n, **json.loads(out.strip().splitlines()[-1])))
    print(f"{a.size}x{a.size} px, windows 64,32,32, 50 % overlap, median of {a.repeat}; "
          f"OpenPIV {rows[0]['openpiv']} with its Rust backend")
    print(f"{'threads':>7}{'spiv.piv ms':>13}{'OpenPIV ms':>12}{'ratio':>8}"
          f"{'spiv RMS px':>13}{'OpenPIV RMS px':>16}")
    for r in rows:
        print(f"{r['threads']:>7}{r['spiv_ms']:>13.1f}{r['openpiv_ms']:>12.1f}"
              f"{r['openpiv_ms'] / r['spiv_ms']:>7.1f}x{r['spiv_rms']:>13.4f}{r['openpiv_rms']:>16.4f}")
    if a.json:
        a.json.write_text(json.dumps(dict(size=a.size, rows=rows), indent=2))


if __name__ == "__main__":
    main()
