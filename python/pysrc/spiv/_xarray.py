"""`spiv.flow(..., as_xarray=True)`: the flow dict as an xarray Dataset in
pivpy's layout (dimensions y, x, t; variables u, v, chc), so that pivpy's
`.piv` accessor (vorticity, averages, plots) works on it directly; the
robust mean field rides along as `mean_*` variables on (y, x)."""

import numpy as np


def to_xarray(d):
    try:
        import xarray as xr
    except ImportError as e:  # pragma: no cover - the message is the point
        raise ImportError("as_xarray=True needs xarray: pip install 'spiv[xarray]'") from e
    cal = d.get("tick_hz") is not None
    mid = d["ticks"].mean(axis=1)
    dt = float(np.diff(d["ticks"], axis=1).mean())  # ticks per pair
    if cal:
        k = d["pixel_size"] * 1e-3  # m per px
        per = k * d["tick_hz"] / dt  # (m/s) per (px per pair)
        t, dt = mid / d["tick_hz"], dt / d["tick_hz"]
        units = ["m", "m", "m/s", "m/s"]
    else:
        k, per, t = 1.0, 1.0, mid
        units = ["pix", "pix", "pix/dt", "pix/dt"]
    # NaN where nothing was measured (flag 2), so that NaN-aware means
    # (pivpy's averages) skip those nodes; an infinite uncertainty too.
    finite = lambda a: np.where(np.isfinite(a), a, np.nan)
    u, v = (d[n] * per for n in ("u", "v"))
    su, sv = (finite(d[n]) * per for n in ("sigma_u", "sigma_v"))
    up = bool(d.get("y_up", False))
    vdir = "positive up" if up else "positive down"
    yxt, yx = ("y", "x", "t"), ("y", "x")
    tr = lambda a: np.transpose(a, (1, 2, 0))
    ds = xr.Dataset(
        {
            "u": (yxt, tr(u), {"units": units[2]}),
            "v": (yxt, tr(v), {"units": units[3], "long_name": f"v, {vdir}"}),
            "chc": (yxt, tr(d["flags"]).astype(np.int32),
                    {"long_name": "0 valid, 1 replaced, 2 invalid"}),
            "sigma_u": (yxt, tr(su), {"units": units[2]}),
            "sigma_v": (yxt, tr(sv), {"units": units[3]}),
            "mean_u": (yx, d["mean_u"] * per, {"units": units[2],
                       "long_name": "median of the valid u over t"}),
            "mean_v": (yx, d["mean_v"] * per, {"units": units[3],
                       "long_name": f"median of the valid v over t, {vdir}"}),
            "mean_chc": (yx, d["mean_flags"].astype(np.int32),
                         {"long_name": "0 valid, 2 no valid vector"}),
            "mean_sigma_u": (yx, finite(d["mean_sigma_u"]) * per, {"units": units[2]}),
            "mean_sigma_v": (yx, finite(d["mean_sigma_v"]) * per, {"units": units[3]}),
            "mean_pairs": (yx, d["mean_pairs"].astype(np.int32),
                           {"long_name": "pairs with a valid vector"}),
        },
        coords={
            "x": ("x", d["x"][0, :] * k, {"units": units[0]}),
            "y": ("y", d["y"][:, 0] * k, {"units": units[1], "long_name": "y, up" if up else "y, down"}),
            "t": ("t", t, {"units": "s" if cal else "ticks"}),
        },
    )
    ds.attrs["variables"] = ["x", "y", "u", "v"]
    ds.attrs["units"] = units
    ds.attrs["dt"] = dt
    ds.attrs["y_axis"] = "up" if up else "down"
    ds.attrs["files"] = []
    return ds


def open_flow(path):
    """`spiv flow`'s `flow.nc` as the Dataset `spiv.flow(path,
    as_xarray=True)` gives: pivpy's layout, SI units when calibrated."""
    try:
        import xarray as xr
    except ImportError as e:  # pragma: no cover - the message is the point
        raise ImportError("open_flow needs xarray: pip install 'spiv[xarray]'") from e
    with xr.open_dataset(path) as f:
        f = f.load()
    a = f.attrs
    dt = float(a["dt_ticks"])
    cal = "tick_hz" in a and "pixel_size_mm" in a
    # flow.nc is (t, y, x) with `flag`, x and y in m when calibrated (px in
    # x_px, y_px); the Dataset is pivpy's (y, x, t) with `chc`.
    mid = f.t.values * float(a["tick_hz"]) if cal else f.t.values
    ny, nx = f.sizes["y"], f.sizes["x"]
    xs = f.x_px.values if "x_px" in f.variables else f.x.values
    ys = f.y_px.values if "y_px" in f.variables else f.y.values
    measured = lambda name: f[name].values
    sigma = lambda name: np.nan_to_num(f[name].values, nan=np.inf)
    d = {
        "ticks": np.stack([mid - dt / 2, mid + dt / 2], axis=1),
        "x": np.broadcast_to(xs, (ny, nx)),
        "y": np.broadcast_to(ys[:, None], (ny, nx)),
        "u": measured("u"), "v": measured("v"), "flags": f.flag.values,
        "sigma_u": sigma("sigma_u"), "sigma_v": sigma("sigma_v"),
        "mean_u": measured("mean_u"), "mean_v": measured("mean_v"),
        "mean_flags": f.mean_flag.values, "mean_pairs": f.mean_pairs.values,
        "mean_sigma_u": sigma("mean_sigma_u"), "mean_sigma_v": sigma("mean_sigma_v"),
        "y_up": a.get("y_axis") == "up",
        "pixel_size": float(a["pixel_size_mm"]) if cal else None,
        "tick_hz": float(a["tick_hz"]) if cal else None,
    }
    return to_xarray(d)
