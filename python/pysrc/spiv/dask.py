"""`spiv.flow` over a Dask cluster: the pairs of each recording are split
into segments (`spiv.FLOW_SEGMENT` pairs measured in one loop, each pair
made from what the pair before measured, the first from nothing after
its own warm-up pairs), each run of segments is measured by a task on a
worker, and the runs are joined into one xarray Dataset along time.

Because a segment never reads another's field, a task's vectors are
exactly those of the same pairs in `spiv.flow(..., segment=FLOW_SEGMENT)`
on one machine, and so is the joined Dataset. Each task opens the recording by its path and reads
only the planes its pairs' windows need (they reach beyond its own tick
range by the time ladder's longest separation), so every worker must see
the recording at the same path: a shared file system on a cluster, as
with fluidimage's executors.

Needs `pip install 'spiv[dask]'` (dask.distributed, xarray, scipy)."""

import os

import numpy as np

from . import _xarray
from .spiv import FLOW_SEGMENT, flow_mean, flow_pairs
from .spiv import flow as _flow

#: The `spiv.flow` keywords that decide which pairs there are.
_SCHEDULE = ("dt", "every", "start", "end", "method", "width", "height", "flip", "strip_head")
#: Arrays stacked along the pairs; the others are the recording's.
_PER_PAIR = ("ticks", "u", "v", "flags", "sigma_u", "sigma_v", "u_m_s", "v_m_s")


def flow(recordings, client, segments_per_task=1, **options):
    """Runs `spiv.flow(path, segment=FLOW_SEGMENT, **options)` for each
    recording on the Dask `client`'s cluster, `segments_per_task` segments
    of pairs per task.

    `recordings` is one path (returns one xarray Dataset along time, the
    one `spiv.flow(path, segment=FLOW_SEGMENT, as_xarray=True, **options)`
    returns) or a list of paths (returns a list of them, in order).
    `options` are `spiv.flow`'s keywords but `as_xarray`, `pairs`,
    `segment` and `dense`; `start` and `end` take a tick range of one long
    recording.
    """
    for k in ("as_xarray", "pairs", "segment", "dense"):
        if k in options:
            raise ValueError(f"spiv.dask.flow: {k} is not an option here")
    if not (isinstance(segments_per_task, int) and segments_per_task >= 1):
        raise ValueError(f"segments_per_task {segments_per_task!r}: expected an integer >= 1")
    single = isinstance(recordings, (str, os.PathLike))
    paths = [os.fspath(recordings)] if single else [os.fspath(p) for p in recordings]
    schedule = {k: v for k, v in options.items() if k in _SCHEDULE}
    step = FLOW_SEGMENT * segments_per_task
    tasks = []
    for path in paths:
        n = len(flow_pairs(path, **schedule))
        runs = [(a, min(a + step, n)) for a in range(0, n, step)]
        tasks.append([client.submit(_measure, path, run, options, pure=False) for run in runs])
    out = [_xarray.to_xarray(_join(client.gather(t))) for t in tasks]
    return out[0] if single else out


def _measure(path, pairs, options):
    """One task: `spiv.flow` on pairs `pairs[0]..pairs[1]` of `path`, in
    segments of `FLOW_SEGMENT`."""
    return _flow(path, pairs=pairs, segment=FLOW_SEGMENT, **options)


def _join(parts):
    """The flow dict of all pairs from the tasks' dicts (in time order):
    the per-pair arrays concatenated, the mean field computed again over
    all of them."""
    d = dict(parts[0])
    for k in _PER_PAIR:
        if k in d:
            d[k] = np.concatenate([p[k] for p in parts], axis=0)
    d["methods"] = [m for p in parts for m in p["methods"]]
    return flow_mean(d)
