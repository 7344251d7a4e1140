"""Ingest a variable of a NetCDF (3 or 4) or HDF5 file into a chronocl store, a step at a time
(or several variables side by side, or the magnitude of two or three: `chronocl.data.variables`).

The file is opened lazily with xarray (h5netcdf first for HDF5-based files,
netCDF4 as the fallback), so only one time step is in memory at once. The
variable is picked by name or as the only one with four or more dimensions;
its dimensions are mapped to (T, Z, Y, X) as `chronocl.data.labelled` maps
those of any xarray array, which also refuses a non-uniform coordinate or resamples it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from chronocl.core.errors import (
    ChronoclError,
    InputNotFoundError,
    InvalidDataError,
    InvalidParameterError,
)
from chronocl.core.paths import check_output
from chronocl.data.formats.contract import Reader, has_suffix
from chronocl.data.labelled import (
    RESAMPLE,
    axis_grid,
    map_dims,
    resample_step,
    resampled_dtype,
    time_labels,
)
from chronocl.data.metadata import SUPPORTED_DTYPES
from chronocl.data.series import write_steps
from chronocl.data.steps import Steps
from chronocl.data.timeseries import TimeSeries
from chronocl.data.variables import magnitude_steps, split_names, write_variables

HDF5_SUFFIXES = (".nc", ".nc4", ".h5", ".hdf5", ".he5", ".hdf")


def ingest_netcdf(
    path: str | os.PathLike,
    out: str | os.PathLike,
    *,
    var: str | None = None,
    variables: str | Sequence[str] | None = None,
    magnitude: str | Sequence[str] | None = None,
    time_dim: str | None = None,
    dims_order: str | Sequence[str] | None = None,
    resample: str | None = None,
    nan_fill: float | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> TimeSeries:
    """Write variable `var` of a NetCDF/HDF5 file as a (T, Z, Y, X) store at `out`.

    `variables` ('a,b' or a list) writes each as a variable of one store instead
    (`chronocl.data.variables`); `magnitude` ('u,v,w') the magnitude of those two or three.
    `dims_order` names the file's dimensions in the order time, z, y, x (``"time,lev,lat,lon"``
    or a list). Spacing comes from the z/y/x coordinates: a non-uniform one is refused unless
    `resample` is ``"uniform"``. Time labels come from the time coordinate. Non-finite values
    (including decoded fill values) need `nan_fill`.
    """
    p = Path(path)
    if not p.is_file():
        raise InputNotFoundError(f"input file {str(p)!r} does not exist")
    given = [
        f for f, v in (("--var", var), ("--variables", variables), ("--magnitude", magnitude)) if v
    ]
    if len(given) > 1:
        raise InvalidParameterError(f"{' and '.join(given)} exclude each other; give one")
    if resample is not None and resample not in RESAMPLE:
        raise InvalidParameterError(f"unknown resample {resample!r}; choose uniform")
    check_output(out, overwrite)
    common = dict(overwrite=overwrite, progress=progress, nan_fill=nan_fill)
    ds = _open(p)
    try:

        def steps(name: str) -> Steps:
            return variable_steps(ds, p, name, time_dim, dims_order, resample)

        if magnitude:
            names = split_names(magnitude, "--magnitude", (2, 3))
            parts = [steps(_pick_variable(ds, n, p.name)) for n in names]
            return write_steps(out, magnitude_steps(parts, names, f"netcdf: {p}"), **common)
        if variables:
            names = split_names(variables, "--variables")
            parts = [(n, steps(_pick_variable(ds, n, p.name))) for n in names]
            return write_variables(out, parts, **common)
        return write_steps(out, steps(_pick_variable(ds, var, p.name)), **common)
    finally:
        ds.close()


def variable_steps(
    ds, p: Path, name: str, time_dim=None, dims_order=None, resample: str | None = None
) -> Steps:
    """The steps of variable `name` of the open dataset `ds` (of file `p`), checked."""
    v = ds[name]
    tdim, zyx, squeeze = map_dims(ds, v, name, time_dim, dims_order)
    if squeeze:
        v = v.isel(dict.fromkeys(squeeze, 0))
    dtype = v.dtype.newbyteorder("=")
    if dtype.kind not in "biuf":
        raise InvalidDataError(
            f"variable {name} of {p.name} has data type {dtype.name}; a series needs numbers"
        )
    if dtype.name not in SUPPORTED_DTYPES:
        # write_series takes few dtypes; float32 holds int8/int32/float16/bool exactly
        # (int32 beyond 2**24 is rounded).
        dtype = np.dtype(np.float32)
    grids = [axis_grid(ds, d, resample) for d in zyx]
    n_steps = int(v.sizes[tdim])

    def read() -> Iterator[np.ndarray]:
        for t in range(n_steps):
            try:
                step = v.isel({tdim: t}).transpose(*zyx).values
            except ChronoclError:
                raise
            except Exception as exc:  # the backends raise many kinds on damaged data
                raise _unreadable(p, exc) from None
            yield resample_step(np.asarray(step).astype(dtype, copy=False), grids)

    notes = [g.note for g in grids if g.note]
    return Steps(
        read,
        n_steps=n_steps,
        volume_shape=tuple(int(v.sizes[d]) for d in zyx),
        dtype=resampled_dtype(dtype, grids),
        spacing=tuple(g.spacing for g in reversed(grids)),  # type: ignore[arg-type]  # x first
        times=time_labels(ds, tdim),
        source=f"netcdf: {p}:{name}",
        labels=[f"{p.name}:{name} step {t}" for t in range(n_steps)],
        attrs={"variable": name, "resampled": notes},
    )


def _open(p: Path):
    import xarray as xr

    engines = ["h5netcdf", "netcdf4"]
    with open(p, "rb") as fh:
        classic = fh.read(3) == b"CDF"  # NetCDF 3 magic: only netCDF4 reads it
    if classic or p.suffix.lower() not in HDF5_SUFFIXES:
        engines.reverse()
    first: Exception | None = None
    end = _classic_data_end(p) if classic else None
    if end is not None and end > p.stat().st_size:
        raise _unreadable(
            p, f"truncated: the data need {end} bytes, the file has {p.stat().st_size}"
        )
    for engine in engines:
        # phony_dims lets h5netcdf open plain HDF5 data sets that have no dimension scales.
        kwargs = {"phony_dims": "sort"} if engine == "h5netcdf" else {}
        try:
            return xr.open_dataset(p, engine=engine, cache=False, **kwargs)
        except Exception as exc:  # a missing engine, a non-HDF5 file, or a damaged one
            first = first or exc
    raise _unreadable(p, first)


# Sizes of the classic NetCDF data types 1..11 (byte, char, short, int, float, double, then the
# CDF-5 ubyte, ushort, uint, int64, uint64).
_CLASSIC_SIZES = (0, 1, 1, 2, 4, 4, 8, 1, 2, 4, 8, 8)


def _classic_data_end(p: Path) -> int | None:
    """Bytes a classic (CDF-1/2/5) file needs for all its data, from its header; else None.

    netCDF-C reads the missing tail of a truncated classic file as zeros instead of failing,
    so the size is checked against the header before anything is written.
    """
    import struct

    with open(p, "rb") as fh:
        head = fh.read(4)
        if head[:3] != b"CDF" or head[3] not in (1, 2, 5):
            return None
        version = head[3]
        count = ">Q" if version == 5 else ">I"
        offset = ">I" if version == 1 else ">Q"

        def read(fmt: str) -> int:
            size = struct.calcsize(fmt)
            raw = fh.read(size)
            if len(raw) != size:
                raise EOFError
            return struct.unpack(fmt, raw)[0]

        def skip_name() -> None:
            n = read(count)
            fh.seek(n + (-n % 4), 1)

        def skip_attrs() -> None:
            read(">I")
            for _ in range(read(count)):
                skip_name()
                kind = read(">I")
                n = read(count) * _CLASSIC_SIZES[kind]
                fh.seek(n + (-n % 4), 1)

        try:
            numrecs = read(count)
            read(">I")
            dims = []
            for _ in range(read(count)):
                skip_name()
                dims.append(read(count))
            skip_attrs()
            read(">I")
            fixed, records = [], []
            for _ in range(read(count)):
                skip_name()
                ids = [read(count) for _ in range(read(count))]
                skip_attrs()
                size = _CLASSIC_SIZES[read(">I")]
                read(count)  # vsize: recomputed below, it saturates for huge variables
                begin = read(offset)
                lengths = [dims[i] for i in ids]
                if lengths and lengths[0] == 0:
                    records.append((begin, size * math.prod(lengths[1:])))
                else:
                    fixed.append(begin + size * math.prod(lengths))
        except (EOFError, IndexError, struct.error):
            return None
    if numrecs == (2**64 - 1 if version == 5 else 2**32 - 1):
        return None  # streaming: the record count is not in the header
    ends = list(fixed)
    if records and numrecs:
        # Records interleave all record variables; each padded to 4 bytes unless alone.
        recsize = records[0][1] if len(records) == 1 else sum(n + (-n % 4) for _, n in records)
        ends += [begin + (numrecs - 1) * recsize + n for begin, n in records]
    return max(ends, default=0)


def _unreadable(p: Path, exc: BaseException | None) -> InvalidDataError:
    reason = " ".join(str(exc).split()) if exc is not None else "unknown error"
    if len(reason) > 120:
        reason = reason[:117] + "..."
    return InvalidDataError(f"cannot read {p.name} as NetCDF/HDF5 ({reason})")


def _listing(ds) -> str:
    return ", ".join(f"{n}({', '.join(map(str, ds[n].dims))})" for n in ds.data_vars)


def _pick_variable(ds, var: str | None, fname: str) -> str:
    if var is not None:
        if var not in ds.data_vars:
            raise InvalidParameterError(
                f"{fname} has no variable {var!r}; found: {_listing(ds) or 'no variables'}"
            )
        return var
    candidates = [str(n) for n in ds.data_vars if ds[n].ndim >= 4]
    if len(candidates) == 1:
        return candidates[0]
    if not candidates:
        raise InvalidDataError(
            f"{fname} has no variable with 4 dimensions (time, z, y, x); "
            f"found: {_listing(ds) or 'no variables'}"
        )
    raise InvalidParameterError(f"choose the variable with --var; found: {_listing(ds)}")


READER = Reader(
    "netcdf",
    ingest_netcdf,
    options={
        "var": None,
        "variables": None,
        "magnitude": None,
        "time_dim": None,
        "dims_order": None,
        "resample": None,
    },
    recognises=has_suffix(".nc", ".nc4", ".cdf", ".netcdf", ".h5", ".hdf5", ".he5"),
    single=True,
)
