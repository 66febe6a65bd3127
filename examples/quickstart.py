"""spiv from Python: read a spike recording, reconstruct a frame pair, run
PIV, and plot the field (with matplotlib, if it is installed).

    python examples/quickstart.py            # simulates one first (paper-linear)
    python examples/quickstart.py SPIKES.dat --width 400 --height 250 --at 64 --dt 13

Install the module first (README, "Python"; simulating needs the simulator):
    MATURIN_PEP517_ARGS="--features sim" pip install ./python
"""

import argparse
import pathlib

import numpy as np

import spiv



def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dat", nargs="?", type=pathlib.Path,
                    help="Vidar .dat (default: simulate the paper's linear scene into quickstart/)")
    ap.add_argument("--width", type=int, help="px (default: scene.json beside the file)")
    ap.add_argument("--height", type=int)
    ap.add_argument("--at", type=int, default=64, help="tick of the first frame")
    ap.add_argument("--dt", type=int, default=13, help="ticks between the two frames")
    ap.add_argument("--method", default="tfp",
                    help="tfp (8 ticks), adaptive (the paper's, n_max 128: fast particles "
                         "streak; `spiv.flow` compensates them) or tfi")
    ap.add_argument("--out", default="quickstart.png", help="plot file")
    a = ap.parse_args()

    if a.dat is None:
        # spiv simulate's files: spikes.dat with scene.json beside it.
        spiv.simulate("paper-linear", seed=1, out="quickstart")
        a.dat = pathlib.Path("quickstart") / "spikes.dat"
    spikes = spiv.read_dat(a.dat, width=a.width, height=a.height)
    ticks, h, w = spikes.shape
    print(f"{a.dat.name}: {ticks} planes of {w}x{h} px, "
          f"{spikes.mean():.4f} spikes per pixel and tick")

    frame_a = spiv.reconstruct(spikes, a.at, method=a.method)
    frame_b = spiv.reconstruct(spikes, a.at + a.dt, method=a.method)

    # Small images get small windows: the last pass sets the grid.
    windows = (64, 32, 32) if min(h, w) >= 128 else (32, 16, 16)
    x, y, u, v, flags = spiv.piv(frame_a, frame_b, windows=windows)
    ok = flags < 2
    print(f"{x.size} vectors ({x.shape[1]} x {x.shape[0]}), {ok.sum()} measured; "
          f"mean u {u[ok].mean():+.3f} px, v {v[ok].mean():+.3f} px per pair (v down)")
    for r in range(0, y.shape[0], max(1, y.shape[0] // 8)):
        row = ok[r]
        if row.any():
            print(f"  y = {y[r, 0]:5.0f} px: u = {u[r][row].mean():+.3f} px per pair")

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return
    fig, ax = plt.subplots(figsize=(8, 8 * h / w + 0.5))
    ax.imshow(frame_a, cmap="gray")
    # Image axes (y down), so v is drawn as it was measured.
    ax.quiver(x[ok], y[ok], u[ok], v[ok], color="yellow", angles="xy",
              scale_units="xy", scale=0.5)
    ax.set_title(f"{a.dat.name}: {a.method} frames at {a.at}, {a.at + a.dt}")
    fig.savefig(a.out, dpi=100, bbox_inches="tight")
    print(f"-> {a.out}")


if __name__ == "__main__":
    main()
