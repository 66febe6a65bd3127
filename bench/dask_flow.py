#!/usr/bin/env python3
"""spiv.dask.flow's throughput on a LocalCluster of 1 and of 2 worker
processes (one thread each, RAYON_NUM_THREADS=1, so the workers are the
only parallelism), against spiv.flow on one process; speed against error:
every run's Dataset must equal the one-process run's, and the mean field's
error against the simulator's truth is printed beside the times.

    python3 -m venv bench/.venv && MATURIN_PEP517_ARGS="--features sim" bench/.venv/bin/pip install './python[dask]'
    bench/.venv/bin/python bench/dask_flow.py [--ticks 2000] [--seed 101]

The recording is `spiv.simulate("paper-linear")` at sensor size (400x250),
`--ticks` planes (pairs every 52 ticks, 13 apart: the defaults).
"""
import argparse
import os
import pathlib
import tempfile
import time

# One thread per process, set before spiv's first parallel call (rayon
# reads it once); the workers inherit it.
os.environ["RAYON_NUM_THREADS"] = "1"

import numpy as np
import xarray as xr
from dask.distributed import Client, LocalCluster

import spiv
import spiv.dask


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ticks", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=101)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sim = spiv.simulate("paper-linear", seed=args.seed, ticks=args.ticks, out=tmp)
        path = pathlib.Path(tmp) / "spikes.dat"
        t0 = time.perf_counter()
        want = spiv.flow(path, as_xarray=True)
        one = time.perf_counter() - t0
        pairs = want.sizes["t"]
        err = mean_error(want, sim)
        print(f"{args.ticks} planes 400x250, {pairs} pairs; mean-field error vs truth "
              f"{err:.4f} px per pair (valid nodes)")
        print("| run | wall time | s per pair | planes per s | same Dataset |")
        print("|---|---|---|---|---|")
        print(f"| spiv.flow, 1 process | {one:.1f} s | {one / pairs:.2f} | "
              f"{args.ticks / one:.0f} | (reference) |")
        for workers in (1, 2):
            with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster, Client(cluster) as client:
                client.run(lambda: None)  # workers up before the clock starts
                t0 = time.perf_counter()
                got = spiv.dask.flow(path, client)
                wall = time.perf_counter() - t0
            try:
                xr.testing.assert_identical(got, want)
                same = "yes"
            except AssertionError:
                same = "NO"
            print(f"| spiv.dask.flow, {workers} worker{'s' if workers > 1 else ''} | "
                  f"{wall:.1f} s | {wall / pairs:.2f} | {args.ticks / wall:.0f} | {same} |")


def mean_error(ds, sim):
    """RMS end-point error of the mean field's valid nodes against the
    truth on the same grid, px per pair."""
    t = sim["truth"]
    ok = ds.mean_chc.values == 0
    per = 0.02e-3 * 20000.0 / 13  # (m/s) per (px per pair): scene.json's
    du = ds.mean_u.values / per - t["u"]
    dv = ds.mean_v.values / per - t["v"]
    return float(np.sqrt(np.mean(du[ok] ** 2 + dv[ok] ** 2)))


if __name__ == "__main__":
    main()
