"""The series API: open and write a (T, Z, Y, X) series, and the names its users need.

`open_series` opens whatever a path holds: an OME-Zarr image in place, else a chronocl store
or a bare (T, Z, Y, X) zarr array. `write_series` writes time steps into a new chronocl store
and opens it. The `TimeSeries` type itself lives in `chronocl.data.timeseries` and is handed
on from here with the functions that make one.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from chronocl.data.formats.omezarr import is_omezarr, open_omezarr
from chronocl.data.remote_store import check_storage_options, check_url, is_url
from chronocl.data.steps import Steps
from chronocl.data.timeseries import TimeSeries, open_store
from chronocl.data.writer import write_store

__all__ = ["TimeSeries", "open_series", "write_series", "write_steps"]


def open_series(
    path: str | os.PathLike,
    variable: str | None = None,
    storage_options: dict | None = None,
) -> TimeSeries:
    """Open a chronocl store (zarr v3 or v2), a bare (T, Z, Y, X) zarr array or an OME-Zarr
    image (in place: channel 0, full resolution).

    A store of several variables opens at its first; `variable` names another
    (`TimeSeries.variables` lists them, `TimeSeries.variable(name)` switches).

    `path` may be an http(s):// or s3:// URL, read in place (`chronocl.data.remote`);
    `storage_options` then go to fsspec (``anon=True`` for a public bucket, ``endpoint_url``).
    """
    path = check_url(path)  # a URL it cannot read: one line, nothing opened
    check_storage_options(path, storage_options)  # (given for a local path, they were ignored)
    if is_url(path):
        from chronocl.data.remote import open_remote

        url = str(path)
        if is_omezarr(url, storage_options):
            series = open_omezarr(url, storage_options=storage_options)
        else:
            series = open_remote(url, storage_options)
        return series if variable is None else series.variable(variable)
    p = Path(path)
    series = open_omezarr(p) if is_omezarr(p) else open_store(p)
    return series if variable is None else series.variable(variable)


def write_series(
    path: str | os.PathLike, steps: Iterable[np.ndarray], **options: object
) -> TimeSeries:
    """Write steps (each (Z, Y, X)) to a new store atomically and open it.

    The options (n_steps, volume_shape (Z, Y, X) and dtype required; spacing (dx, dy, dz), x
    first; times, source, overwrite, progress, nan_fill, labels, chunk_bytes, compressor,
    checksum) are `write_store`'s.
    """
    write_store(path, steps, **options)  # type: ignore[arg-type]
    return open_store(path)


def write_steps(
    path: str | os.PathLike,
    steps: Steps,
    *,
    overwrite: bool = False,
    progress: bool = False,
    nan_fill: float | None = None,
) -> TimeSeries:
    """Write a reader's `steps` to a new store atomically and open it."""
    return write_series(
        path,
        steps.read(),
        **steps.written(),
        overwrite=overwrite,
        progress=progress,
        nan_fill=nan_fill,
    )
