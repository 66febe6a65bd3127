"""`spiv.dask.flow` on a LocalCluster of 2 worker processes gives exactly
the Dataset `spiv.flow(..., segment=FLOW_SEGMENT)` gives on one machine."""

import numpy as np
import pytest
import xarray as xr
from dask.distributed import Client, LocalCluster, get_task_stream

import spiv
import spiv.dask


@pytest.fixture(scope="module")
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def long_recording(tmp_path_factory):
    """paper-linear, 128x128, 900 ticks: with pairs every 26 ticks, 3
    segments of pairs."""
    d = tmp_path_factory.mktemp("long")
    spiv.simulate("paper-linear", seed=4, width=128, height=128, ticks=900, out=d)
    return d / "spikes.dat"


def test_two_workers_give_the_one_machine_dataset(client, long_recording):
    want = spiv.flow(long_recording, every=26, segment=spiv.FLOW_SEGMENT, as_xarray=True)
    assert want.sizes["t"] > 2 * spiv.FLOW_SEGMENT  # three segments, three tasks
    with get_task_stream(client) as ts:
        got = spiv.dask.flow(long_recording, client, every=26)
    assert len({t["worker"] for t in ts.data}) == 2  # both workers measured
    xr.testing.assert_identical(got, want)
    assert got.attrs["units"] == ["m", "m", "m/s", "m/s"]  # scene.json's calibration
    assert (got.mean_chc == 0).sum() > 0 and float(abs(got.mean_u).max()) > 0


def test_a_list_of_recordings_and_a_tick_range(client, long_recording, recording):
    got = spiv.dask.flow([long_recording, recording / "spikes.dat"], client,
                         segments_per_task=2, end=700)
    assert isinstance(got, list) and len(got) == 2
    seg = spiv.FLOW_SEGMENT
    xr.testing.assert_identical(
        got[0], spiv.flow(long_recording, end=700, segment=seg, as_xarray=True))
    xr.testing.assert_identical(
        got[1], spiv.flow(recording / "spikes.dat", end=700, segment=seg, as_xarray=True))


def test_flow_mean_joins_pairs_as_flow_does(long_recording):
    d = spiv.flow(long_recording, end=700)
    means = [k for k in d if k.startswith("mean_")]
    assert "mean_u_m_s" in means and "mean_pairs" in means
    bare = {k: v for k, v in d.items() if not k.startswith("mean_")}
    joined = spiv.flow_mean(bare)
    for k in means:
        np.testing.assert_array_equal(joined[k], d[k], err_msg=k)


def test_bad_options_are_refused(client, long_recording):
    with pytest.raises(ValueError, match="dense is not an option"):
        spiv.dask.flow(long_recording, client, dense=True)
    with pytest.raises(ValueError, match="segments_per_task 0"):
        spiv.dask.flow(long_recording, client, segments_per_task=0)
    with pytest.raises(spiv.SpivError, match="the schedule has pairs"):
        spiv.flow(long_recording, pairs=(1000, 1001))
    with pytest.raises(OSError):
        spiv.dask.flow(long_recording.parent / "missing.dat", client, dt=13,
                       width=128, height=128)
