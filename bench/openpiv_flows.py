#!/usr/bin/env python3
"""OpenPIV's windef beside `spiv bench flows`: every scene family's frame
camera pair and TFP 8 pair through OpenPIV 0.26's multi-pass window
deformation (windows 64, 32, 32 at 50 % overlap: the grid of spiv piv's
defaults and of the truth), scored as `spiv bench flows` scores its rows.

    python3 -m venv bench/.venv && MATURIN_PEP517_ARGS="--features sim" bench/.venv/bin/pip install ./python openpiv imageio
    bench/.venv/bin/python bench/openpiv_flows.py [--seeds 101-110] [--families "paper-log 0.3,vortex"]

Per family and seed: the recording is `spiv.simulate` of the family
(host/src/bench/flows.rs `families()`: scene, top speed, planes; flow seed
= seed; the spectral turbulence's member = seed), the pair at its centre. The EPE (px per pair) is the mean over
the measured vectors (finite after OpenPIV's validation and replacement)
in the glare rows (centres within 2 glare sigmas of the wall; the bottom
rows where a scene has no glare) and in the other rows, against the truth
at each vector's centre; "flagged" is the share OpenPIV left without a
vector (all of them where windef raises, as on some large-shift pairs).
`spiv.piv` on the same frames is scored the same way, as a check
that this scoring reproduces `spiv bench flows`' frame camera and TFP 8
columns.
"""
import argparse
import json
import pathlib
import sys
import tempfile

import numpy as np

import spiv

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from openpiv_compare import openpiv_run  # noqa: E402

#: host/src/bench/flows.rs families(): (name, scene, top speed, planes).
FAMILIES = [
    ("paper-linear", "paper-linear", None, 300),
    ("paper-quadratic", "paper-quadratic", None, 300),
    ("paper-log", "paper-log", None, 300),
    ("paper-log 0.3", "paper-log", 0.3, 300),
    ("paper-log 1.0", "paper-log", 1.0, 300),
    ("blasius", "blasius", None, 300),
    ("uniform", "uniform", None, 300),
    ("vortex", "vortex", None, 300),
    ("turbulence", "turbulence", None, 62),
    ("large-shift", "large-shift", None, 62),
    ("vortex-array 0.3", "vortex-array", 0.3, 160),
    ("vortex-array 1.0", "vortex-array", 1.0, 160),
    ("spectral turbulence", "spectral-turbulence", None, 62),
]


def seeds_of(text):
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def score(u, v, measured, truth, h, band):
    """(glare EPE, other EPE, flagged share) of a field against the truth
    on the same grid."""
    e = np.hypot(u - truth["u"], v - truth["v"])
    glare = (h - 0.5 - truth["y"]) < band
    mean = lambda m: float(e[m].mean()) if m.any() else float("nan")
    return mean(measured & glare), mean(measured & ~glare), float(1 - measured.mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", default="101-110")
    ap.add_argument("--families", help="comma-separated family names (all without it)")
    ap.add_argument("--json", type=pathlib.Path)
    args = ap.parse_args()
    only = None if args.families is None else {f.strip() for f in args.families.split(",")}
    families = [f for f in FAMILIES if only is None or f[0] in only]
    if not families:
        sys.exit(f"--families: none of {', '.join(f[0] for f in FAMILIES)}")
    rows = []
    for name, scene, speed, ticks in families:
        for seed in seeds_of(args.seeds):
            with tempfile.TemporaryDirectory() as tmp:
                # The spectral turbulence's seeds are members of their own.
                member = seed if scene == "spectral-turbulence" else None
                sim = spiv.simulate(scene, seed=seed, ticks=ticks, speed=speed, flow_seed=seed,
                                    member=member, out=tmp)
                meta = json.loads((pathlib.Path(tmp) / "scene.json").read_text())
            p = meta["scene"]["params"]
            h, band = p["height"], 2.0 * p["glare_sigma"]
            t = sim["truth"]
            tfp = [spiv.reconstruct(sim["spikes"], k, method="tfp", window=8) for k in sim["pair"]]
            pairs = {"frame camera": sim["frames"], "TFP 8": tfp}
            for method, (a, b) in pairs.items():
                a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
                try:
                    _, _, ou, ov = openpiv_run(a, b, [64, 32, 32], 0.5)
                except ValueError as e:  # windef gives up: no vector at all
                    print(f"{name} seed {seed} {method}: OpenPIV: {e}", file=sys.stderr)
                    ou = ov = np.full(t["u"].shape, np.nan)
                if ou.shape != t["u"].shape:
                    sys.exit(f"{name} {seed}: OpenPIV grid {ou.shape}, truth {t['u'].shape}")
                ok = np.isfinite(ou) & np.isfinite(ov)
                rows.append((name, seed, f"OpenPIV windef, {method}",
                             *score(np.nan_to_num(ou), np.nan_to_num(ov), ok, t, h, band)))
                _, _, su, sv, flags = spiv.piv(a, b)
                rows.append((name, seed, f"spiv piv, {method}",
                             *score(su, sv, flags < 2, t, h, band)))
            print(f"{name} seed {seed}", file=sys.stderr)
    methods = [m for m in dict.fromkeys(r[2] for r in rows)]
    print(f"seeds {args.seeds}; EPE px per pair, glare rows / other rows; flagged")
    print("| family | " + " | ".join(methods) + " |")
    print("|---" * (len(methods) + 1) + "|")
    for name, *_ in families:
        cells = []
        for m in methods:
            rs = [r for r in rows if r[0] == name and r[2] == m]
            g = np.nanmean([r[3] for r in rs]) if any(np.isfinite(r[3]) for r in rs) else np.nan
            o = np.nanmean([r[4] for r in rs])
            f = np.mean([r[5] for r in rs])
            cells.append(f"{g:.3f} / {o:.3f} ({100 * f:.0f} %)")
        print(f"| {name} | " + " | ".join(cells) + " |")
    if args.json:
        keys = ("family", "seed", "method", "glare", "other", "flagged")
        args.json.write_text(json.dumps([dict(zip(keys, r)) for r in rows], indent=2))


if __name__ == "__main__":
    main()
