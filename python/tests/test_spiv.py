"""The Python module against the `spiv` command line on the same input
(same spikes, frames and vectors), against ground truth on known shifts,
and on bad input (the CLI's messages, never a crash)."""

import csv
import json
import os
import subprocess
import struct
import threading
import warnings
import zlib

import numpy as np
import pytest

import spiv


def read_csv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    keys = ("x", "y", "u", "v", "flag", "peak_ratio", "correlation", "sigma_u", "sigma_v",
            "u_m_s", "v_m_s", "pairs")
    cols = {k: np.array([float(r[k]) for r in rows]) for k in keys if k in rows[0]}
    return cols


def write_png(path, a):
    """An 8-bit grayscale PNG of `a` (2-D uint8), with the standard library."""
    h, w = a.shape
    raw = b"".join(b"\x00" + a[r].tobytes() for r in range(h))
    chunk = lambda t, b: (struct.pack(">I", len(b)) + t + b
                          + struct.pack(">I", zlib.crc32(t + b) & 0xFFFFFFFF))
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def cli_error(res):
    """The CLI's one error line, without its `spiv: error: ` prefix."""
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("spiv: error: ")
    return lines[0][len("spiv: error: "):]


def test_simulate_and_read_dat_match_the_cli(recording):
    spikes = spiv.read_dat(recording / "spikes.dat")
    sim = spiv.simulate("uniform", seed=3, width=128, height=128, shift=(2.0, 1.0))
    assert spikes.dtype == np.uint8 and spikes.shape == sim["spikes"].shape
    assert spikes.shape[1:] == (128, 128)
    np.testing.assert_array_equal(spikes, sim["spikes"])
    assert set(np.unique(spikes)) <= {0, 1}
    truth = read_csv(recording / "truth.csv")
    t = sim["truth"]
    np.testing.assert_allclose(t["x"].ravel(), truth["x"])
    np.testing.assert_allclose(t["y"].ravel(), truth["y"])
    np.testing.assert_allclose(t["u"].ravel(), truth["u"], atol=1e-6)
    np.testing.assert_allclose(t["v"].ravel(), truth["v"], atol=1e-6)
    # The same files as the CLI's, when asked for.
    again = spiv.simulate("uniform", seed=3, width=128, height=128, shift=(2.0, 1.0),
                          out=recording.parent / "again")
    np.testing.assert_array_equal(again["spikes"], spikes)
    assert (recording.parent / "again" / "spikes.dat").read_bytes() == (
        recording / "spikes.dat").read_bytes()
    # A window of the file, by start and count.
    part = spiv.read_dat(recording / "spikes.dat", start=10, count=5)
    np.testing.assert_array_equal(part, spikes[10:15])


@pytest.mark.parametrize("method", ["adaptive", "tfp", "tfi"])
def test_reconstruct_matches_the_cli(cli, recording, tmp_path, method):
    spikes = spiv.read_dat(recording / "spikes.dat")
    at = 64
    cli("reconstruct", recording / "spikes.dat", "--at", at, "--method", method,
        "-o", tmp_path / "f.png")
    want = spiv.read_image(tmp_path / "f.png")
    got = spiv.reconstruct(spikes, at, method=method)
    assert got.dtype == np.uint16 and got.shape == (128, 128)
    np.testing.assert_array_equal(got, want)
    assert got.max() > 0


def test_piv_gives_the_cli_vectors(cli, recording, tmp_path):
    spikes = spiv.read_dat(recording / "spikes.dat")
    for k, name in [(64, "a.png"), (77, "b.png")]:
        cli("reconstruct", recording / "spikes.dat", "--at", k, "--method", "tfp",
            "-o", tmp_path / name)
    a, b = spiv.read_image(tmp_path / "a.png"), spiv.read_image(tmp_path / "b.png")
    cli("piv", tmp_path / "a.png", tmp_path / "b.png", "-o", tmp_path / "v.csv",
        "--windows", "32,16", "--overlap", "0.5")
    want = read_csv(tmp_path / "v.csv")
    x, y, u, v, flags = spiv.piv(a, b, windows=(32, 16), overlap=0.5)
    assert x.shape == y.shape == u.shape == v.shape == flags.shape
    np.testing.assert_array_equal(x.ravel(), want["x"])
    np.testing.assert_array_equal(y.ravel(), want["y"])
    np.testing.assert_array_equal(flags.ravel(), want["flag"])
    # The CSV holds 6 decimals.
    np.testing.assert_allclose(u.ravel(), want["u"], atol=5.1e-7, rtol=0)
    np.testing.assert_allclose(v.ravel(), want["v"], atol=5.1e-7, rtol=0)
    # Each vector's confidence, as the CSV's columns (4 decimals there).
    *field, ratio, corr = spiv.piv(a, b, windows=(32, 16), overlap=0.5, confidence=True)
    np.testing.assert_array_equal(field[2], u)
    assert ratio.shape == corr.shape == u.shape
    np.testing.assert_allclose(ratio.ravel(), want["peak_ratio"], atol=5.1e-5, rtol=0)
    np.testing.assert_allclose(corr.ravel(), want["correlation"], atol=5.1e-5, rtol=0)
    assert np.all((corr >= -1) & (corr <= 1)) and np.all(ratio >= 0)
    # Any numeric dtype gives the same field.
    x2, _, u2, _, _ = spiv.piv(a.astype(np.float64), b.astype(np.int32), windows=(32, 16))
    np.testing.assert_array_equal(u2, u)


def particles(h, w, n, seed):
    """Gaussian particles (σ 1 px) at random places, as float64."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    img = np.zeros((h, w))
    for py, px in zip(rng.uniform(0, h, n), rng.uniform(0, w, n)):
        img += 200 * np.exp(-((xx - px) ** 2 + (yy - py) ** 2) / 2.0)
    return img


def test_conventions_on_a_known_shift():
    # Independent of the simulator: a particle image rolled 3 px right
    # and 2 px down (periodic, so every window sees the same shift).
    a = particles(128, 160, 400, seed=1)
    b = np.roll(a, shift=(2, 3), axis=(0, 1))
    x, y, u, v, flags = spiv.piv(a, b)
    inner = flags == 0
    assert inner.sum() > 0.8 * flags.size
    np.testing.assert_allclose(u[inner], 3.0, atol=0.05)
    np.testing.assert_allclose(v[inner], 2.0, atol=0.05)  # v positive down the rows
    assert (np.diff(x, axis=1) > 0).all() and (np.diff(x, axis=0) == 0).all()
    assert (np.diff(y, axis=0) > 0).all() and (np.diff(y, axis=1) == 0).all()
    assert x.shape[1] > x.shape[0]  # (ny, nx): 160 px wide, 128 high


def test_simulated_pair_measures_the_truth():
    sim = spiv.simulate("uniform", seed=5, width=192, height=128, shift=(-1.5, 0.75))
    fa, fb = sim["frames"]
    x, y, u, v, flags = spiv.piv(fa, fb)
    t = sim["truth"]
    assert u.shape == t["u"].shape
    ok = flags < 2
    assert np.sqrt(np.mean((u[ok] - t["u"][ok]) ** 2 + (v[ok] - t["v"][ok]) ** 2)) < 0.1
    np.testing.assert_allclose(x, t["x"])


def test_a_spectral_member_is_the_clis_and_its_own(cli, tmp_path):
    # The member of seed 107: dim, slow; the same recording as the CLI's.
    kw = dict(seed=107, width=64, height=64, ticks=40)
    sim = spiv.simulate("spectral-turbulence", member=107, **kw)
    cli("simulate", "--scene", "spectral-turbulence", "--member", "107", "--seed", "107",
        "--width", "64", "--height", "64", "--ticks", "40", "--out", tmp_path / "m")
    got = spiv.read_dat(tmp_path / "m" / "spikes.dat")
    np.testing.assert_array_equal(np.asarray(got), sim["spikes"])
    meta = json.loads((tmp_path / "m" / "scene.json").read_text())
    assert abs(meta["scene"]["params"]["particle_peak"] - 0.106) < 5e-4
    # Another member of the same scene is another recording.
    other = spiv.simulate("spectral-turbulence", member=108, **kw)
    assert not np.array_equal(other["spikes"], sim["spikes"])
    with pytest.raises(spiv.SpivError, match="--member"):
        spiv.simulate("turbulence", member=1, ticks=40)


def test_flow_gives_the_cli_mean_field(cli, tmp_path):
    d = tmp_path / "rec"
    cli("simulate", "--scene", "paper-linear", "--width", "128", "--height", "128",
        "--ticks", "400", "--seed", "2", "--out", d)
    cli("flow", d / "spikes.dat", "--out", tmp_path / "out")
    want = read_csv(tmp_path / "out" / "mean.csv")
    got = spiv.flow(d / "spikes.dat")
    pairs = got["u"].shape[0]
    assert pairs >= 2 and got["ticks"].shape == (pairs, 2) and len(got["methods"]) == pairs
    assert got["methods"][-1] == "ladder"
    np.testing.assert_array_equal(got["x"].ravel(), want["x"])
    np.testing.assert_array_equal(got["mean_flags"].ravel(), want["flag"])
    # Where a node has no valid vector, the arrays hold NaN and the CSV
    # u = v = 0 (its flag is authoritative) with NaN in its m/s columns.
    none = want["flag"] == 2
    assert np.all(np.isnan(got["mean_u"].ravel()[none]))
    np.testing.assert_allclose(got["mean_u"].ravel()[~none], want["u"][~none], atol=5.1e-7, rtol=0)
    np.testing.assert_allclose(got["mean_v"].ravel()[~none], want["v"][~none], atol=5.1e-7, rtol=0)
    assert np.abs(got["mean_u"][got["mean_flags"] == 0]).max() > 0.5  # it flows
    # Every vector's uncertainty, as mean.csv's columns; finite where valid.
    assert got["sigma_u"].shape == got["u"].shape == got["sigma_v"].shape
    assert np.all(np.isfinite(got["sigma_u"][got["flags"] == 0]))
    assert np.all(np.isinf(got["sigma_u"][got["flags"] == 2]))
    np.testing.assert_allclose(got["mean_sigma_u"].ravel(), want["sigma_u"], atol=5.1e-7, rtol=0)
    np.testing.assert_array_equal(got["mean_pairs"].ravel(), want["pairs"])
    # Calibrated by scene.json: m/s beside px per pair, as the CLI's columns.
    assert got["pixel_size"] == 0.02 and got["tick_hz"] == 20000.0
    np.testing.assert_allclose(got["mean_u_m_s"].ravel(), want["u_m_s"], atol=5.1e-7, rtol=0)
    k = 0.02e-3 * 20000.0 / 13
    np.testing.assert_allclose(got["u_m_s"], got["u"] * k, rtol=1e-12)


def test_flow_as_xarray_is_pivpys_layout_and_pivpy_computes_on_it(cli, tmp_path):
    from pivpy import pivpy  # noqa: F401  (registers the .piv accessor)

    d = tmp_path / "rec"
    cli("simulate", "--scene", "paper-linear", "--width", "128", "--height", "128",
        "--ticks", "400", "--seed", "2", "--out", d)
    got = spiv.flow(d / "spikes.dat")
    ds = spiv.flow(d / "spikes.dat", as_xarray=True)
    yxt = lambda a: np.transpose(a, (1, 2, 0))
    k = 0.02e-3 * 20000.0 / 13  # (m/s) per (px per pair)
    assert ds.u.dims == ("y", "x", "t") and ds.attrs["units"] == ["m", "m", "m/s", "m/s"]
    np.testing.assert_allclose(ds.u.values, yxt(got["u"]) * k, rtol=1e-12)
    np.testing.assert_array_equal(ds.chc.values, yxt(got["flags"]))
    np.testing.assert_allclose(ds.x.values, got["x"][0] * 0.02e-3, rtol=1e-12)
    np.testing.assert_allclose(ds.t.values, got["ticks"].mean(axis=1) / 20000.0)
    # pivpy's vorticity is numpy's central differences of the same field.
    w = ds.piv.vorticity()["w"].values
    want = (np.gradient(ds.v.values, ds.x.values, axis=1)
            - np.gradient(ds.u.values, ds.y.values, axis=0))
    np.testing.assert_allclose(w, want, rtol=1e-9, atol=1e-12)
    # Against the truth's own vorticity (truth.csv, the same grid), away
    # from the glare rows at the bottom wall.
    t = read_csv(d / "truth.csv")
    ny, nx = got["u"].shape[1:]
    tu, tv = t["u"].reshape(ny, nx) * k, t["v"].reshape(ny, nx) * k
    tw = (np.gradient(tv, ds.x.values, axis=1) - np.gradient(tu, ds.y.values, axis=0))
    truth_w, measured_w = np.median(tw[1:4, 1:-1]), np.nanmedian(w[1:4, 1:-1, :])
    assert truth_w != 0 and abs(measured_w / truth_w - 1) < 0.1, (measured_w, truth_w)
    # Invalid vectors are NaN, so pivpy's average is the NaN-aware mean of
    # what was measured, not pulled towards 0 by what was not.
    assert np.all(np.isnan(ds.u.values[ds.chc.values == 2]))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN nodes
        nanmean = np.nanmean(ds.u.values, axis=2)
    np.testing.assert_allclose(ds.piv.average.u.values, nanmean, rtol=1e-12)


def test_invalid_is_nan_in_every_output(cli, tmp_path):
    """A masked body makes nodes invalid in every pair: every output holds
    NaN there (the CSVs keep u = v = 0 with flag 2, as the vector format
    says, and NaN in their m/s columns), and pivpy's average of the
    Dataset is the NaN-aware mean."""
    import xarray as xr
    from pivpy import pivpy  # noqa: F401  (registers the .piv accessor)

    d = tmp_path / "rec"
    cli("simulate", "--scene", "paper-linear", "--width", "128", "--height", "128",
        "--ticks", "400", "--seed", "2", "--out", d)
    mask = np.zeros((128, 128), dtype=bool)
    mask[32:80, 40:90] = True
    write_png(tmp_path / "mask.png", mask.astype(np.uint8) * 255)
    cli("flow", d / "spikes.dat", "--mask", tmp_path / "mask.png", "--out", tmp_path / "out")
    got = spiv.flow(d / "spikes.dat", mask=mask)
    invalid = got["flags"] == 2
    assert invalid[:, mask[got["y"].round().astype(int), got["x"].round().astype(int)]].all()
    # numpy
    for name in ("u", "v", "u_m_s", "v_m_s"):
        assert np.all(np.isnan(got[name][invalid])), name
        assert np.all(np.isfinite(got[name][~invalid])), name
    none = got["mean_flags"] == 2
    assert none.any()
    for name in ("mean_u", "mean_v", "mean_u_m_s", "mean_v_m_s"):
        assert np.all(np.isnan(got[name][none])), name
    # CSVs
    for i in range(got["u"].shape[0]):
        c = read_csv(tmp_path / "out" / f"vectors_{i:05}.csv")
        bad = c["flag"] == 2
        np.testing.assert_array_equal(bad, invalid[i].ravel())
        assert np.all(c["u"][bad] == 0) and np.all(c["v"][bad] == 0)
        assert np.all(np.isnan(c["u_m_s"][bad])) and np.all(np.isnan(c["v_m_s"][bad]))
        assert np.all(np.isfinite(c["u_m_s"][~bad]))
    c = read_csv(tmp_path / "out" / "mean.csv")
    assert np.all(np.isnan(c["u_m_s"][c["flag"] == 2]))
    # flow.nc
    with xr.open_dataset(tmp_path / "out" / "flow.nc") as nc:
        for name in ("u", "v", "u_m_s", "v_m_s", "sigma_u"):
            assert np.all(np.isnan(nc[name].values[invalid])), name
        assert np.all(np.isnan(nc["mean_u"].values[none]))
    # as_xarray, and pivpy on it
    ds = spiv.flow(d / "spikes.dat", mask=mask, as_xarray=True)
    bad = ds.chc.values == 2
    for name in ("u", "v", "sigma_u", "sigma_v"):
        assert np.all(np.isnan(ds[name].values[bad])), name
        assert np.all(np.isfinite(ds[name].values[~bad])), name
    assert np.all(np.isnan(ds.mean_u.values[none]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN nodes
        nanmean = np.nanmean(ds.u.values, axis=2)
    np.testing.assert_allclose(ds.piv.average.u.values, nanmean, rtol=1e-12)
    assert np.all(np.isnan(ds.piv.average.u.values[none]))


def test_y_up_flips_y_and_v_and_the_sign_of_vorticity(cli, tmp_path):
    """y_up=True: y from the bottom row's centre, v positive up, the same
    in the CLI's files; pivpy's vorticity is the y-down one negated
    (positive counterclockwise)."""
    import xarray as xr
    from pivpy import pivpy  # noqa: F401  (registers the .piv accessor)

    d = tmp_path / "rec"
    cli("simulate", "--scene", "vortex-array", "--width", "128", "--height", "96",
        "--ticks", "300", "--seed", "2", "--out", d)
    down = spiv.flow(d / "spikes.dat")
    up = spiv.flow(d / "spikes.dat", y_up=True)
    assert up["y_up"] and not down["y_up"]
    np.testing.assert_array_equal(up["y"], 95 - down["y"])
    np.testing.assert_array_equal(up["u"], down["u"])
    np.testing.assert_array_equal(up["v"], -down["v"])
    np.testing.assert_array_equal(up["mean_v"], -down["mean_v"])
    w_down = spiv.flow(d / "spikes.dat", as_xarray=True).piv.vorticity()["w"].values
    ds = spiv.flow(d / "spikes.dat", as_xarray=True, y_up=True)
    assert ds.attrs["y_axis"] == "up" and "up" in ds.v.attrs["long_name"]
    np.testing.assert_allclose(ds.piv.vorticity()["w"].values, -w_down, rtol=1e-12, atol=1e-15)
    cli("flow", d / "spikes.dat", "--y-up", "--out", tmp_path / "up")
    c = read_csv(tmp_path / "up" / "vectors_00000.csv")
    np.testing.assert_array_equal(c["y"], up["y"].ravel())
    ok = c["flag"] < 2
    np.testing.assert_allclose(c["v"][ok], up["v"][0].ravel()[ok], atol=5.1e-7, rtol=0)
    with xr.open_dataset(tmp_path / "up" / "flow.nc") as nc:
        assert nc.attrs["y_axis"] == "up"
        np.testing.assert_array_equal(nc.y_px.values, up["y"][:, 0])
    xr.testing.assert_allclose(spiv.open_flow(tmp_path / "up" / "flow.nc"),
                               spiv.flow(d / "spikes.dat", as_xarray=True, y_up=True),
                               rtol=1e-12, atol=1e-15)


def test_flow_mask_leaves_a_body_invalid(cli, tmp_path):
    d = tmp_path / "rec"
    cli("simulate", "--scene", "paper-linear", "--width", "128", "--height", "128",
        "--ticks", "400", "--seed", "2", "--out", d)
    mask = np.zeros((128, 128), dtype=bool)
    mask[32:80, 40:90] = True
    got = spiv.flow(d / "spikes.dat", mask=mask)
    x, y = got["x"].round().astype(int), got["y"].round().astype(int)
    inside = mask[y, x]
    assert inside.sum() >= 4
    assert np.all(got["flags"][:, inside] == 2) and np.all(got["mean_pairs"][inside] == 0)
    with pytest.raises(spiv.SpivError, match="mask is 10x10 px"):
        spiv.flow(d / "spikes.dat", mask=np.zeros((10, 10), dtype=bool))


def test_flow_nc_opens_in_xarray_with_the_fields_and_units(cli, tmp_path):
    import xarray as xr

    d = tmp_path / "rec"
    cli("simulate", "--scene", "paper-linear", "--width", "128", "--height", "128",
        "--ticks", "400", "--seed", "2", "--out", d)
    cli("flow", d / "spikes.dat", "--out", tmp_path / "out")
    got = spiv.flow(d / "spikes.dat")
    with xr.open_dataset(tmp_path / "out" / "flow.nc") as ds:
        pairs, ny, nx = got["u"].shape
        assert dict(ds.sizes) == {"t": pairs, "y": ny, "x": nx}
        assert ds.u.dims == ("t", "y", "x") and ds.mean_u.dims == ("y", "x")
        assert ds.u.attrs["units"] == "1" and ds.u_m_s.attrs["units"] == "m s-1"
        assert ds.attrs["Conventions"] == "CF-1.8" and ds.attrs["dt_ticks"] == 13
        # Calibrated: x, y in m, the pixels beside them.
        assert ds.x.attrs["units"] == "m"
        np.testing.assert_allclose(ds.x.values, got["x"][0] * 0.02e-3, rtol=1e-12)
        np.testing.assert_array_equal(ds.x_px.values, got["x"][0])
        np.testing.assert_array_equal(ds.y_px.values, got["y"][:, 0])
        assert ds.mean_pairs.dtype.kind == "i"
        assert ds.sigma_u.attrs["long_name"] != ds.sigma_v.attrs["long_name"]
        np.testing.assert_array_equal(ds.flag.values, got["flags"])
        measured = got["flags"] < 2
        np.testing.assert_array_equal(ds.u.values[measured], got["u"][measured])
        assert np.all(np.isnan(ds.u.values[~measured]))
        np.testing.assert_array_equal(ds.mean_pairs.values, got["mean_pairs"])
        np.testing.assert_allclose(ds.u_m_s.values[measured], got["u_m_s"][measured], rtol=1e-12)
        # Seconds since the first plane: each pair's midpoint tick / 20 kHz.
        np.testing.assert_allclose(ds.t.values, got["ticks"].mean(axis=1) / 20000.0)
    # The file in pivpy's layout: pivpy's vorticity of it is that of the
    # run's own Dataset.
    from pivpy import pivpy  # noqa: F401  (registers the .piv accessor)

    want = spiv.flow(d / "spikes.dat", as_xarray=True)
    piv = spiv.open_flow(tmp_path / "out" / "flow.nc")
    assert piv.u.dims == ("y", "x", "t") and piv.attrs["units"] == want.attrs["units"]
    xr.testing.assert_allclose(piv, want, rtol=1e-12, atol=1e-15)
    w = piv.piv.vorticity()["w"].values
    np.testing.assert_allclose(w, want.piv.vorticity()["w"].values, rtol=1e-9, atol=1e-12)
    assert np.isfinite(w).any() and np.abs(w[np.isfinite(w)]).max() > 0


def test_flow_nc_passes_the_cf_checker(cli, tmp_path):
    """flow.nc, calibrated and not, with y up, and spiv piv's .nc: no error
    from the CF checker (compliance-checker, CF 1.8)."""
    from compliance_checker.runner import CheckSuite, ComplianceChecker

    d = tmp_path / "rec"
    cli("simulate", "--scene", "paper-linear", "--width", "128", "--height", "128",
        "--ticks", "300", "--seed", "2", "--out", d)
    cli("flow", d / "spikes.dat", "--out", tmp_path / "cal")
    lone = tmp_path / "lone.dat"
    lone.write_bytes((d / "spikes.dat").read_bytes())
    cli("flow", lone, "--width", 128, "--height", 128, "--dt", 13, "--out", tmp_path / "raw")
    cli("flow", d / "spikes.dat", "--y-up", "--out", tmp_path / "up")
    cli("piv", tmp_path / "cal" / "pair_a.png", tmp_path / "cal" / "pair_b.png",
        "-o", tmp_path / "p.nc")
    CheckSuite.load_all_available_checkers()
    for nc in (tmp_path / "cal" / "flow.nc", tmp_path / "raw" / "flow.nc",
               tmp_path / "up" / "flow.nc", tmp_path / "p.nc"):
        report = tmp_path / "report.txt"
        ok, errors = ComplianceChecker.run_checker(
            str(nc), ["cf:1.8"], 0, "normal", output_filename=str(report), output_format="text")
        assert not errors and ok, report.read_text()


@pytest.mark.skipif(not os.environ.get("SPIV_BIN_NETCDF4"),
                    reason="needs SPIV_BIN_NETCDF4: spiv built with --features netcdf4 (CI)")
def test_flow_nc_as_netcdf4_opens_in_xarray(tmp_path):
    import xarray as xr

    exe = os.environ["SPIV_BIN_NETCDF4"]
    d = tmp_path / "rec"
    subprocess.run([exe, "simulate", "--scene", "paper-linear", "--width", "128", "--height",
                    "128", "--ticks", "400", "--seed", "2", "--out", d], check=True,
                   capture_output=True)
    subprocess.run([exe, "flow", d / "spikes.dat", "--out", tmp_path / "out"], check=True,
                   capture_output=True)
    nc = tmp_path / "out" / "flow.nc"
    assert nc.read_bytes()[:8] == b"\x89HDF\r\n\x1a\n"  # netCDF-4 is HDF5
    got = spiv.flow(d / "spikes.dat")
    with xr.open_dataset(nc, engine="netcdf4") as ds:
        assert ds.u.encoding["zlib"] and ds.u.encoding["chunksizes"][0] == 1
        assert ds.u.dims == ("t", "y", "x") and ds.attrs["Conventions"] == "CF-1.8"
        measured = got["flags"] < 2
        np.testing.assert_array_equal(ds.flag.values, got["flags"])
        np.testing.assert_array_equal(ds.u.values[measured], got["u"][measured])
        assert np.all(np.isnan(ds.u.values[~measured]))
        np.testing.assert_array_equal(ds.mean_pairs.values, got["mean_pairs"])
        np.testing.assert_allclose(ds.u_m_s.values[measured], got["u_m_s"][measured], rtol=1e-12)


def test_bad_input_raises_the_cli_message(cli, recording, tmp_path):
    spikes = spiv.read_dat(recording / "spikes.dat")
    cli("reconstruct", recording / "spikes.dat", "--at", 64, "-o", tmp_path / "a.png")
    msg = cli_error(cli("piv", tmp_path / "a.png", tmp_path / "a.png", "--windows", "2000",
                        "-o", tmp_path / "v.csv", check=False))
    a = spiv.read_image(tmp_path / "a.png")
    with pytest.raises(spiv.SpivError) as e:
        spiv.piv(a, a, windows=(2000,))
    assert str(e.value) == msg
    msg = cli_error(cli("piv", tmp_path / "a.png", tmp_path / "a.png", "--clip", "x",
                        "-o", tmp_path / "v.csv", check=False))
    with pytest.raises(spiv.SpivError, match="^--clip x") as e:
        spiv.piv(a, a, clip="x")
    assert str(e.value) == msg
    msg = cli_error(cli("reconstruct", recording / "spikes.dat", "--at", 100000,
                        "-o", tmp_path / "x.png", check=False))
    with pytest.raises(spiv.SpivError) as e:
        spiv.reconstruct(spikes, 100000)
    assert str(e.value) == msg
    msg = cli_error(cli("simulate", "--width", 3, "--height", 3, "--out", tmp_path / "s",
                        check=False))
    with pytest.raises(spiv.SpivError) as e:
        spiv.simulate(width=3, height=3)
    assert str(e.value) == msg

    with pytest.raises(spiv.SpivError, match="differ in size"):
        spiv.piv(a, a[:, :64])
    with pytest.raises(spiv.SpivError, match="2-D"):
        spiv.piv(spikes, spikes)
    with pytest.raises(spiv.SpivError, match="3-D"):
        spiv.reconstruct(a, 0)
    with pytest.raises(spiv.SpivError, match="method nope"):
        spiv.reconstruct(spikes, 64, method="nope")
    with pytest.raises(spiv.SpivError, match="predicted motion"):
        spiv.reconstruct(spikes, 64, method="mc")
    with pytest.raises(spiv.SpivError, match="makes pairs"):
        spiv.reconstruct(spikes, 64, method="ladder")
    with pytest.raises(spiv.SpivError, match="multiple of 8"):
        spiv.reconstruct(np.zeros((4, 3, 3), np.uint8), 1)
    with pytest.raises(OSError):
        spiv.read_dat(tmp_path / "missing.dat", width=128, height=128)
    with pytest.raises(spiv.SpivError, match="both width and height"):
        spiv.read_dat(recording / "spikes.dat", width=128)
    with pytest.raises(spiv.SpivError, match="start"):
        spiv.read_dat(recording / "spikes.dat", start=10**9)
    with pytest.raises(spiv.SpivError, match="^dt 0: expected a whole number of ticks"):
        spiv.flow(recording / "spikes.dat", dt=0)
    with pytest.raises(TypeError):
        spiv.piv(a)


def test_flow_checks_inputs_against_what_they_claim(recording, tmp_path):
    """Each bad input is named in one line, before any work: a missing
    file, a file that is no recording, a size against scene.json, half a
    calibration, a dt of no ticks, an empty pair range, growing windows."""
    dat = recording / "spikes.dat"
    with pytest.raises(OSError, match="missing.dat: No such file"):
        spiv.flow(tmp_path / "missing.dat")
    for name, body in (("notes.txt", b"x,y\n"), ("frame.png", b"\x89PNG\r\n\x1a\n"),
                       ("frame.dat", b"\x89PNG\r\n\x1a\n")):
        (tmp_path / name).write_bytes(body)
        with pytest.raises(spiv.SpivError, match=f"{name}: not a spike recording"):
            spiv.flow(tmp_path / name, width=128, height=128)
    with pytest.raises(spiv.SpivError, match="300x256 px given, but scene.json beside it says 128x128"):
        spiv.flow(dat, width=300, height=256)
    lone = tmp_path / "lone.dat"  # no scene.json beside it
    lone.write_bytes(dat.read_bytes())
    with pytest.raises(spiv.SpivError, match="half a calibration: the tick rate"):
        spiv.flow(lone, width=128, height=128, dt=13, pixel_size=0.02)
    with pytest.raises(spiv.SpivError, match="half a calibration: the pixel size"):
        spiv.flow(lone, width=128, height=128, dt=13, tick_hz=20000.0)
    with pytest.raises(spiv.SpivError, match="^dt -5: expected a whole number of ticks, at least 1"):
        spiv.flow(dat, dt=-5)
    with pytest.raises(spiv.SpivError, match="^pairs 0..0: an empty range"):
        spiv.flow(dat, pairs=(0, 0))
    with pytest.raises(spiv.SpivError, match="indices start at 0"):
        spiv.flow(dat, pairs=(-1, 2))
    with pytest.raises(spiv.SpivError, match="^window -1: expected a whole number"):
        spiv.flow(dat, window=-1)
    with pytest.raises(spiv.SpivError, match="windows 32 then 64 px"):
        spiv.flow(dat, windows=(32, 64))
    a = np.zeros((128, 128), np.float32)
    with pytest.raises(spiv.SpivError, match="windows 32 then 64 px"):
        spiv.piv(a, a, windows=(32, 64))


def test_ctrl_c_stops_flow_between_pairs_and_keeps_them(cli, tmp_path):
    """Ctrl-C (here `_thread.interrupt_main`, from the progress callback once
    the first pair is done) stops the run within one pair per worker: a
    clean KeyboardInterrupt, no panic, and the pairs done on it, each the
    same as a whole run's."""
    import _thread
    import signal

    d = tmp_path / "rec"
    cli("simulate", "--scene", "uniform", "--width", "128", "--height", "96",
        "--ticks", "1600", "--seed", "4", "--out", d)
    total = len(spiv.flow_pairs(d / "spikes.dat"))
    seen = []

    def interrupt(done, n):
        seen.append((done, n))
        if len(seen) == 1:
            _thread.interrupt_main()

    # Ctrl-C as a user's interpreter takes it: `interrupt_main` does
    # nothing while SIGINT is ignored or left to the system, as another
    # library in the process may leave it.
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt) as e:
            spiv.flow(d / "spikes.dat", progress=interrupt)
    finally:
        signal.signal(signal.SIGINT, handler)
    part = e.value.partial
    assert part is not None and seen[0][1] == total
    got = part["u"].shape[0]
    assert 1 <= got < total and got <= seen[0][0] + (os.cpu_count() or 1), (got, seen)
    calls = []
    whole = spiv.flow(d / "spikes.dat", progress=lambda done, n: calls.append((done, n)))
    assert calls[-1] == (total, total) and all(a[0] < b[0] for a, b in zip(calls, calls[1:]))
    rows = [int(np.flatnonzero(whole["ticks"][:, 0] == t)[0]) for t in part["ticks"][:, 0]]
    np.testing.assert_array_equal(part["u"], whole["u"][rows])
    np.testing.assert_array_equal(part["flags"], whole["flags"][rows])


def test_heavy_work_releases_the_gil():
    # Two PIV runs from two threads finish and agree (the GIL is released
    # inside, so they overlap; correctness, not timing, is tested here).
    a = particles(256, 256, 800, seed=2)
    b = np.roll(a, shift=(1, 2), axis=(0, 1))
    out = [None, None]

    def run(i):
        out[i] = spiv.piv(a, b)[2]

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    np.testing.assert_array_equal(out[0], out[1])


def test_quickstart_runs(tmp_path):
    # The README's quick start: simulate, read the .dat, a TFP pair, PIV
    # (and a plot when matplotlib is there).
    import pathlib
    import subprocess
    import sys

    script = pathlib.Path(__file__).resolve().parents[2] / "examples" / "quickstart.py"
    res = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                         text=True, check=True)
    assert "vectors" in res.stdout
    assert (tmp_path / "quickstart" / "spikes.dat").exists()
    top = [float(line.split("u =")[1].split()[0]) for line in res.stdout.splitlines()
           if line.strip().startswith("y =")]
    assert top and top[0] > 10.0 > top[-1] > 0.0  # the linear profile: fast at the top


def test_dense_measures_turbulence_where_window_piv_cannot():
    sim = spiv.simulate("turbulence", seed=4, width=192, height=192)
    fa, fb = sim["frames"]
    t = sim["truth_dense"]
    assert t["u"].shape == (192, 192) and t["u"].dtype == np.float32
    mean = np.hypot(t["u"], t["v"]).mean()
    u, v, mode = spiv.dense(fa, fb)
    assert mode == "pyramid" and u.shape == (192, 192)
    epe = np.hypot(u - t["u"], v - t["v"]).mean()
    assert epe < 0.45 * mean, (epe, mean)  # measured 2.9 of 8.1 px
    # Window PIV alone reports nothing; with the fallback (the default)
    # the dense vectors, flagged 1.
    *_, flags = spiv.piv(fa, fb, dense_fallback=False)
    assert (flags == 2).all()
    x, y, u1, v1, flags = spiv.piv(fa, fb)
    assert (flags == 1).sum() > 0.9 * flags.size


def test_receive_closes_the_loop_as_the_cli_does(cli, messages, tmp_path):
    import json
    res = cli("receive", "--file", messages, "--piv", "--control", tmp_path / "cli.ctl", "--json")
    want = json.loads(res.stdout)
    got = spiv.receive(file=messages, control=tmp_path / "py.ctl", out=tmp_path / "out")
    for k in ("bytes", "messages", "frames", "pairs", "lost_frames", "corrupted"):
        assert got[k] == want[k], k
    assert got["pairs"] == 3 and got["frames"] == 6
    assert got["controls_sent"] == want["downlink"]["sent"] == 3
    # The same control messages, byte for byte, and the vectors written.
    assert (tmp_path / "py.ctl").read_bytes() == (tmp_path / "cli.ctl").read_bytes()
    assert got["vectors"] > 0
    assert len(list((tmp_path / "out").glob("vectors_*.csv"))) == 3
    assert len(list((tmp_path / "out").glob("frame_*.png"))) == 6
    # No PIV: frames only; a bad source says so.
    plain = spiv.receive(file=messages, windows=None)
    assert plain["vectors"] == 0 and plain["frames"] == 6
    with pytest.raises(spiv.SpivError, match="one of file or tcp"):
        spiv.receive()
    with pytest.raises(spiv.SpivError, match="not spiv wire format"):
        junk = tmp_path / "junk.bin"
        junk.write_bytes(bytes(range(256)) * 4)
        spiv.receive(file=junk)
