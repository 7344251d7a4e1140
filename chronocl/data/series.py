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
from chronocl.data.timeseries import TimeSeries, open_store
from chronocl.data.writer import write_store

__all__ = ["TimeSeries", "open_series", "write_series"]


def open_series(path: str | os.PathLike) -> TimeSeries:
    """Open a chronocl store (zarr v3 or v2), a bare (T, Z, Y, X) zarr array or an OME-Zarr
    image (in place: channel 0, full resolution)."""
    p = Path(path)
    if is_omezarr(p):
        return open_omezarr(p)
    return open_store(p)


def write_series(
    path: str | os.PathLike, steps: Iterable[np.ndarray], **options: object
) -> TimeSeries:
    """Write steps (each (Z, Y, X)) to a new store atomically and open it.

    The options (n_steps, volume_shape and dtype required; spacing, times, source, overwrite,
    progress, nan_fill, labels, chunk_bytes, compressor, checksum) are `write_store`'s.
    """
    write_store(path, steps, **options)  # type: ignore[arg-type]
    return open_store(path)
