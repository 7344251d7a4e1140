"""Headerless raw volumes: ingest one file per time step, export steps as raw files.

Raw files are x fastest then y then z, as the classic vortex and jet data sets are shipped.
Files come as globs or a list and are sorted naturally (step2 before step10); every size is
checked before the first byte is written. An export writes a folder OUT of
``<stem>_t{step:05d}.raw`` files (little-endian) and ``<stem>.json`` with dims, dtype,
endianness and spacing, so ``chronocl ingest 'OUT/<stem>_t*.raw' --dims NX NY NZ ...`` reads
them back.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from chronocl.core.atomic import atomic_directory
from chronocl.core.errors import (
    ChronoclWarning,
    InvalidDataError,
    InvalidParameterError,
    UnknownNameError,
)
from chronocl.core.progress import track
from chronocl.core.tuning import TUNING
from chronocl.data.formats.contract import Exporter, Reader, StepExport, time_attrs
from chronocl.data.formats.raw_reading import ENDIANS, Reading, likelier_reading
from chronocl.data.inputs import expand_inputs
from chronocl.data.metadata import SUPPORTED_DTYPES
from chronocl.data.series import write_steps
from chronocl.data.steps import Steps
from chronocl.data.timeseries import TimeSeries


def ingest_raw(
    inputs: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    dims: Sequence[int] | None = None,
    dtype: str = "float32",
    endian: str = "little",
    spacing: Sequence[float] | None = None,
    times: Sequence | None = None,
    nan_fill: float | None = None,
    overwrite: bool = False,
    progress: bool = False,
    time_unit: str | None = None,
) -> TimeSeries:
    """One raw file per time step; `dims` is (NX, NY, NZ) and `spacing` (dx, dy, dz), x first."""
    steps = raw_steps(inputs, dims, dtype, endian, spacing, times, time_unit)
    return write_steps(out, steps, overwrite=overwrite, progress=progress, nan_fill=nan_fill)


def raw_steps(
    inputs: Sequence[str | os.PathLike],
    dims: Sequence[int] | None = None,
    dtype: str = "float32",
    endian: str = "little",
    spacing: Sequence[float] | None = None,
    times: Sequence | None = None,
    time_unit: str | None = None,
) -> Steps:
    """The steps of raw files, every size checked: `ingest_raw` before it writes."""
    if dims is None:
        raise InvalidParameterError(
            "raw input needs --dims NX NY NZ (and --dtype, --endian if not float32 little-endian)"
        )
    if dtype not in SUPPORTED_DTYPES:
        raise UnknownNameError(
            f"unknown dtype {dtype!r}; choose one of {', '.join(SUPPORTED_DTYPES)}"
        )
    if endian not in ENDIANS:
        raise UnknownNameError(f"unknown endianness {endian!r}; choose little or big")
    if len(dims) != 3 or any(int(n) < 1 for n in dims):
        raise InvalidParameterError(
            f"dims {list(dims)} must be three positive sizes NX NY NZ (e.g. --dims 128 128 128)"
        )
    nx, ny, nz = (int(n) for n in dims)
    files = expand_inputs(inputs)
    file_dtype = np.dtype(dtype).newbyteorder("<" if endian == "little" else ">")
    expected = nx * ny * nz * file_dtype.itemsize
    sizes = {f: f.stat().st_size for f in files}
    distinct = sorted(set(sizes.values()))
    if len(distinct) > 1:
        a = next(f for f in files if sizes[f] == distinct[0])
        b = next(f for f in files if sizes[f] == distinct[-1])
        raise InvalidDataError(
            f"input files differ in size ({a.name}: {sizes[a]} bytes, {b.name}: {sizes[b]} "
            "bytes); every time step must have the same dims"
        )
    if distinct[0] != expected:
        raise InvalidDataError(
            f"{files[0].name} has {distinct[0]} bytes but --dims {nx} {ny} {nz} --dtype {dtype} "
            f"needs {expected}; check --dims and --dtype"
        )

    # A wrong type or byte order first: the check of the dims order below assumes the values.
    given = Reading(dtype, endian, (nx, ny, nz))
    check_reading(files[0], np.memmap(files[0], dtype=np.uint8, mode="r"), given)
    # The check reads the first file's first slabs only (enough for every order's neighbours).
    pair = max(a * b for a, b in itertools.combinations((nx, ny, nz), 2))
    head = np.fromfile(
        files[0], dtype=file_dtype, count=min(nx * ny * nz, 2 * pair + TUNING.raw_dims_samples)
    )
    better = likelier_dims(head, (nx, ny, nz))
    if better is not None:
        warnings.warn(
            f"{files[0].name} reads as a smooth volume with --dims {' '.join(map(str, better))}"
            f" but not with --dims {nx} {ny} {nz} (x fastest): check the order of --dims",
            ChronoclWarning,
            stacklevel=2,
        )

    def steps() -> Iterator[np.ndarray]:
        for f in files:
            raw = np.fromfile(f, dtype=file_dtype, count=nx * ny * nz)
            check_reading(f, raw.view(np.uint8), given)
            yield raw.reshape(nz, ny, nx).astype(np.dtype(dtype), copy=False)

    return Steps(
        steps,
        n_steps=len(files),
        volume_shape=(nz, ny, nx),
        dtype=np.dtype(dtype),
        spacing=(1.0, 1.0, 1.0) if spacing is None else tuple(spacing),  # type: ignore[arg-type]
        times=times,
        attrs=time_attrs(time_unit),
        source=f"raw: {files[0].parent}/{files[0].name} .. {files[-1].name} ({len(files)} files)",
        labels=[f"{f.name} (step {t})" for t, f in enumerate(files)],
    )


def check_reading(path: Path, raw: np.ndarray, given: Reading) -> None:
    """Refuse a step whose bytes clearly read as data in another type or byte order than the
    given one (`raw_reading`), naming the flags that read it."""
    found = likelier_reading(raw, given)
    if found is None:
        return
    better, why = found
    flags = better.flags(given)
    raise InvalidDataError(
        f"{path.name} reads as {why} with --dtype {given.dtype} --endian {given.endian} but as "
        f"smooth data with {flags}; pass {flags}"
    )


def likelier_dims(values: np.ndarray, dims: tuple[int, int, int]) -> tuple[int, ...] | None:
    """Another order of `dims` (NX, NY, NZ) under which the flat step `values` is clearly
    smoother, or None.

    Read with the wrong row length, a smooth field's y and z neighbours lie far apart in it
    (the volume comes out sheared into copies); the mean step between neighbours along y and z
    shows it. Only clear cases count (less than half the given order's), so noise, constant
    data and volumes with equal sizes give None.
    """
    flat = np.asarray(values).ravel()
    if len(set(dims)) == 1 or min(dims) < TUNING.raw_dims_min_side:
        return None  # one order only, or too thin to tell a neighbour from a copy

    def roughness(order: tuple[int, ...]) -> float:
        nx, ny = order[0], order[1]
        total = 0.0
        for offset in (nx, nx * ny):
            n = flat.size - offset
            if n <= 0:
                return math.inf
            stride = max(1, n // TUNING.raw_dims_samples)
            a = flat[:n:stride].astype(np.float64)
            b = flat[offset : offset + n : stride].astype(np.float64)
            total += float(np.mean(np.abs(b - a)))
        return total

    given = roughness(dims)
    if not math.isfinite(given) or given == 0:
        return None
    scores = {order: roughness(order) for order in set(itertools.permutations(dims))}
    best = min(scores, key=scores.get)  # type: ignore[arg-type]
    if best != tuple(dims) and scores[best] < 0.5 * given:
        return best
    return None


def export_raw(job: StepExport) -> list[Path]:
    """Write each step as a raw file and the .json that says how to read them back."""
    series, target, steps = job.series, job.target, job.steps
    names = [job.step_name(s, ".raw") for s in steps]
    little = series.dtype.newbyteorder("<")
    _, _, ny, nx = series.shape
    dx, dy, dz = series.spacing
    dims = [nx, ny, job.z1 - job.z0]
    sidecar = {
        "format": "chronocl.raw",
        "version": 1,
        "dims": dims,
        "dims_order": "x y z (x fastest)",
        "dtype": series.dtype.name,
        "endian": "little",
        "spacing": {"x": dx, "y": dy, "z": dz},
        "origin": {"x": 0.0, "y": 0.0, "z": job.z0 * dz},
        "z_slab": [job.z0, job.z1],
        "steps": list(steps),
        "times": [series.times[s] for s in steps],
        "files": names,
        "ingest": (
            f"chronocl ingest '{job.stem}_t*.raw' -o {job.stem}.zarr --dims {nx} {ny} "
            f"{job.z1 - job.z0} --dtype {series.dtype.name} --endian little "
            f"--spacing {dx!r} {dy!r} {dz!r}"
        ),
    }
    with atomic_directory(target, job.overwrite) as tmp:
        tmp.mkdir(parents=True)
        for s, name in zip(
            track(steps, len(steps), "exporting .raw", job.progress), names, strict=True
        ):
            data = np.ascontiguousarray(job.read(s), dtype=little)
            with open(tmp / name, "wb") as f:
                f.write(memoryview(data.reshape(-1).view(np.uint8)))
        (tmp / f"{job.stem}.json").write_text(
            json.dumps(sidecar, indent=2) + "\n", encoding="utf-8"
        )
    return [target / f"{job.stem}.json", *(target / n for n in names)]


READER = Reader(
    "raw",
    ingest_raw,
    options={
        "dims": None,
        "dtype": "float32",
        "endian": "little",
        "spacing": None,
        "times": None,
        "time_unit": None,
    },
    recognises=None,  # headerless: any file that no other reader recognises
    steps=raw_steps,
)
EXPORTER = Exporter("raw", export_raw)
