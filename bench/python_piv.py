#!/usr/bin/env python3
"""spiv.piv called from Python against OpenPIV's windef, on the same numpy
arrays in the same process: median wall time and RMS error against the
truth, speed against error.

    python3 -m venv bench/.venv && bench/.venv/bin/pip install ./python openpiv
    bench/.venv/bin/python bench/python_piv.py [--size 1024] [--repeat 5]

The pair is the frame camera's of `spiv.simulate("uniform")` (2.6, 1.4 px
per pair); both engines run windows 64, 32, 32 at 50 % overlap (the same
grid as the truth). OpenPIV runs as in bench/openpiv_compare.py (first
pass, validation, replacement, two deformation passes).
"""
import argparse
import json
import pathlib
import statistics
import sys
import time

import numpy as np

import spiv

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from openpiv_compare import openpiv_run  # noqa: E402


def rms(u, v, tu, tv, ok):
    du, dv = (u - tu)[ok], (v - tv)[ok]
    return float(np.sqrt(np.mean(du ** 2 + dv ** 2))), int(ok.sum())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", type=pathlib.Path)
    a = ap.parse_args()
    sim = spiv.simulate("uniform", seed=5, width=a.size, height=a.size, shift=(2.6, 1.4))
    fa, fb = (f.astype(np.float64) for f in sim["frames"])
    t = sim["truth"]
    windows = [64, 32, 32]
    s_times, o_times = [], []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        x, y, u, v, flags = spiv.piv(fa, fb, windows=windows, overlap=0.5)
        s_times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ox, oy, ou, ov = openpiv_run(fa, fb, windows, 0.5)
        o_times.append(time.perf_counter() - t0)
    s_ms, o_ms = statistics.median(s_times) * 1e3, statistics.median(o_times) * 1e3
    if ou.shape != t["u"].shape:
        sys.exit(f"OpenPIV gave a {ou.shape} grid, the truth is {t['u'].shape}")
    s_rms, s_n = rms(u, v, t["u"], t["v"], flags < 2)
    o_rms, o_n = rms(ou, ov, t["u"], t["v"], np.isfinite(ou) & np.isfinite(ov))
    import openpiv
    print(f"{a.size}x{a.size} px, windows 64,32,32, 50 % overlap, median of {a.repeat}; "
          f"OpenPIV {getattr(openpiv, '__version__', '?')}")
    print(f"{'engine':<24}{'ms':>10}{'RMS px':>10}{'vectors':>9}")
    print(f"{'spiv.piv (Python)':<24}{s_ms:>10.1f}{s_rms:>10.4f}{s_n:>9}")
    print(f"{'openpiv windef':<24}{o_ms:>10.1f}{o_rms:>10.4f}{o_n:>9}")
    print(f"spiv is {o_ms / s_ms:.1f}x faster")
    if a.json:
        a.json.write_text(json.dumps(dict(size=a.size, spiv_ms=s_ms, spiv_rms=s_rms,
                                          openpiv_ms=o_ms, openpiv_rms=o_rms,
                                          speedup=o_ms / s_ms), indent=2))


if __name__ == "__main__":
    main()
