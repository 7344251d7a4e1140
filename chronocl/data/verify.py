"""`chronocl verify`: read a whole store back and check it, as a file-system check would.

Opening a store already checks its metadata; this also reads every chunk of every variable
(missing and undecodable chunks raise StoreCorruptError) and recomputes each step's minimum,
maximum and mean against the statistics stored at ingest, which catches values changed on disk
in stores without chunk checksums. The coarse levels, when the store has them, are checked the
same way against their own statistics.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from chronocl.core.errors import StoreFormatError
from chronocl.core.progress import track
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.integrity import damaged
from chronocl.data.pyramid import POOLS
from chronocl.data.series import TimeSeries, open_series


def verify(
    path: str | os.PathLike, progress: bool = False, storage_options: dict | None = None
) -> dict:
    """Check the series or chronovolume at `path` (a local path, or an http(s):// or s3:// URL
    read with `storage_options`); returns a summary, raises when damaged."""
    try:
        series = open_series(path, storage_options=storage_options)
    except StoreFormatError:
        cv = Chronovolume.load(path, storage_options)  # reads and checks every chunk
        return {
            "chronovolume": str(path),
            "dims (x, y, z)": list(cv.dims),
            "shape (Z, Y, X)": list(cv.shape),
            "status": "ok",
        }
    summary = {"series": str(path), "steps checked": series.n_steps}
    for name in [None, *series.variables[1:]]:  # every variable of a multi-variable store
        one = series if name is None else series.variable(name)
        _check_steps(one, progress)
        for n in range(1, one.n_levels):
            for pool in POOLS:
                _check_steps(one.level(n, pool), progress, f"verifying level {n} {pool}")
    if len(series.variables) > 1:
        summary["variables checked"] = ", ".join(series.variables)
    if series.n_levels > 1:
        summary["levels checked"] = f"1..{series.n_levels - 1} ({', '.join(POOLS)})"
    return {**summary, "status": "ok"}


def _check_steps(series: TimeSeries, progress: bool, what: str = "verifying steps") -> None:
    stats, path = series.stats, Path(series.path or series.meta.get("url") or "array")
    level = f"level {series.level_index} " if series.level_index else ""
    for t in track(range(series.n_steps), series.n_steps, what, progress):
        step = series.read([t])[0]
        got = (float(step.min()), float(step.max()), float(step.mean(dtype=np.float64)))
        want = (stats.step_min[t], stats.step_max[t], stats.step_mean[t])
        if got[:2] != want[:2] or not math.isclose(got[2], want[2], rel_tol=1e-9, abs_tol=1e-12):
            raise damaged(
                path,
                f"{level}step {t} holds values in [{got[0]}, {got[1]}] (mean {got[2]}) but its "
                f"statistics say [{want[0]}, {want[1]}] (mean {want[2]})",
            )
