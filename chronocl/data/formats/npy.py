"""numpy .npy files: ingest a (T, Z, Y, X) array, export steps as one (W, Z, Y, X) array.

The input is read memory-mapped, one step at a time; the export is written through a memory
map into a temporary sibling that is renamed when complete.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronocl.core.atomic import atomic_file
from chronocl.core.errors import InputNotFoundError, InvalidDataError
from chronocl.core.progress import track
from chronocl.data.formats.contract import (
    Exporter,
    Reader,
    StepExport,
    has_suffix,
    time_attrs,
)
from chronocl.data.series import write_steps
from chronocl.data.steps import Steps
from chronocl.data.timeseries import TimeSeries


def ingest_npy(
    path: str | os.PathLike,
    out: str | os.PathLike,
    spacing: Sequence[float] | None = None,
    times: Sequence | None = None,
    nan_fill: float | None = None,
    overwrite: bool = False,
    progress: bool = False,
    time_unit: str | None = None,
) -> TimeSeries:
    """A .npy of shape (T, Z, Y, X) with voxel `spacing` (dx, dy, dz), x first, read
    memory-mapped one step at a time."""
    steps = npy_steps(path, spacing, times, time_unit)
    return write_steps(out, steps, overwrite=overwrite, progress=progress, nan_fill=nan_fill)


def npy_steps(
    path: str | os.PathLike,
    spacing: Sequence[float] | None = None,
    times: Sequence | None = None,
    time_unit: str | None = None,
) -> Steps:
    """The steps of a (T, Z, Y, X) .npy, checked: `ingest_npy` before it writes."""
    p = Path(path)
    if not p.is_file():
        raise InputNotFoundError(f"input file {str(p)!r} does not exist")
    try:
        arr = np.load(p, mmap_mode="r", allow_pickle=False)
    except ValueError as exc:
        raise InvalidDataError(f"{p.name} is not a readable .npy file ({exc})") from None
    if arr.ndim != 4:
        raise InvalidDataError(
            f"{p.name} has shape {arr.shape}; a .npy series must be 4D (T, Z, Y, X)"
        )
    if arr.shape[0] == 0:
        raise InvalidDataError(f"{p.name} has zero time steps; a series needs at least one")
    return Steps(
        lambda: (np.asarray(arr[t]) for t in range(arr.shape[0])),
        n_steps=arr.shape[0],
        volume_shape=arr.shape[1:],
        dtype=arr.dtype.newbyteorder("="),
        spacing=(1.0, 1.0, 1.0) if spacing is None else tuple(spacing),  # type: ignore[arg-type]
        times=times,
        attrs=time_attrs(time_unit),
        source=f"npy: {p}",
    )


def export_npy(job: StepExport) -> list[Path]:
    """Write the steps as one (W, z1 - z0, Y, X) array."""
    series, steps = job.series, job.steps
    shape = (len(steps), job.z1 - job.z0, *series.shape[2:])
    with atomic_file(job.target, job.overwrite) as tmp:
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=series.dtype, shape=shape)
        try:
            for i, s in enumerate(track(steps, len(steps), "exporting .npy", job.progress)):
                out[i] = job.read(s)
            out.flush()
        finally:
            del out
    return [job.target]


READER = Reader(
    "npy",
    ingest_npy,
    options={"spacing": None, "times": None, "time_unit": None},
    recognises=has_suffix(".npy"),
    single=True,
    steps=npy_steps,
)
EXPORTER = Exporter("npy", export_npy)
