"""Ingest one variable of a NetCDF (3 or 4) or HDF5 file into a chronocl store, a step at a time.

The file is opened lazily with xarray (h5netcdf first for HDF5-based files,
netCDF4 as the fallback), so only one time step is in memory at once. The
variable is picked by name or as the only one with four or more dimensions;
its time dimension by name (``time``, ``t``), by a CF ``axis`` attribute or by
a datetime coordinate; its other three dimensions are mapped to (z, y, x) by
name or kept in file order. Plain HDF5 data sets without dimension names
(h5netcdf calls them ``phony_dim_N``) are taken as (T, Z, Y, X) in file order.
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
from chronocl.data.series import SUPPORTED_DTYPES, TimeSeries, write_series

HDF5_SUFFIXES = (".nc", ".nc4", ".h5", ".hdf5", ".he5", ".hdf")
TIME_NAMES = ("time", "t")
AXIS_NAMES = {
    "z": ("z", "depth", "lev", "level", "height", "altitude", "bottom_top"),
    "y": ("y", "lat", "latitude", "south_north"),
    "x": ("x", "lon", "longitude", "west_east"),
}


def ingest_netcdf(
    path: str | os.PathLike,
    out: str | os.PathLike,
    *,
    var: str | None = None,
    time_dim: str | None = None,
    dims_order: str | Sequence[str] | None = None,
    nan_fill: float | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> TimeSeries:
    """Write variable `var` of a NetCDF/HDF5 file as a (T, Z, Y, X) store at `out`.

    `dims_order` names the file's dimensions in the order time, z, y, x (``"time,lev,lat,lon"``
    or a list). Spacing comes from uniform z/y/x coordinates, time labels from the time
    coordinate. Non-finite values (including decoded fill values) need `nan_fill`.
    """
    p = Path(path)
    if not p.is_file():
        raise InputNotFoundError(f"input file {str(p)!r} does not exist")
    check_output(out, overwrite)
    ds = _open(p)
    try:
        name = _pick_variable(ds, var, p.name)
        v = ds[name]
        tdim, zyx, squeeze = _map_dims(ds, v, name, time_dim, dims_order)
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
        n_steps = int(v.sizes[tdim])
        shape = tuple(int(v.sizes[d]) for d in zyx)

        def steps() -> Iterator[np.ndarray]:
            for t in range(n_steps):
                try:
                    step = v.isel({tdim: t}).transpose(*zyx).values
                except ChronoclError:
                    raise
                except Exception as exc:  # the backends raise many kinds on damaged data
                    raise _unreadable(p, exc) from None
                yield np.asarray(step).astype(dtype, copy=False)

        return write_series(
            out,
            steps(),
            n_steps=n_steps,
            volume_shape=shape,
            dtype=dtype,
            spacing=tuple(_spacing(ds, d) for d in zyx),
            times=_time_labels(ds, tdim),
            source=f"netcdf: {p}:{name}",
            overwrite=overwrite,
            progress=progress,
            nan_fill=nan_fill,
            labels=[f"{p.name}:{name} step {t}" for t in range(n_steps)],
        )
    finally:
        ds.close()


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


def _is_datetime(ds, dim: str) -> bool:
    if dim not in ds.coords:
        return False
    c = ds[dim]
    if c.dtype.kind == "M":
        return True
    return c.dtype.kind == "O" and c.size > 0 and hasattr(c.values.flat[0], "isoformat")


def _axis_attr(ds, dim: str) -> str:
    return str(ds[dim].attrs.get("axis", "")).lower() if dim in ds.coords else ""


def _map_dims(ds, v, name: str, time_dim, dims_order):
    """Return (time dim, [z, y, x] dims, length-1 dims to squeeze)."""
    dims = [str(d) for d in v.dims]
    shown = f"{name}({', '.join(f'{d}={v.sizes[d]}' for d in dims)})"
    if dims_order is not None:
        order = _parse_order(dims_order)
        unknown = [d for d in order if d not in dims]
        if unknown:
            raise InvalidParameterError(
                f"dims_order names {', '.join(unknown)}, which {shown} does not have"
            )
        if time_dim is not None and time_dim != order[0]:
            raise InvalidParameterError(
                f"time_dim {time_dim!r} and dims_order {','.join(order)} disagree; "
                "dims_order starts with the time dimension"
            )
        tdim, zyx = order[0], order[1:]
    else:
        tdim = _find_time(ds, dims, shown, time_dim)
        zyx = _spatial(ds, v, [d for d in dims if d != tdim], shown)
    rest = [d for d in dims if d != tdim and d not in zyx]
    big = [d for d in rest if v.sizes[d] != 1]
    if big:
        raise InvalidDataError(
            f"{shown} has the extra dimension(s) {', '.join(big)} besides time, z, y, x; "
            "only extra dimensions of length 1 can be dropped"
        )
    return tdim, zyx, rest


def _parse_order(dims_order) -> list[str]:
    items = dims_order.split(",") if isinstance(dims_order, str) else list(dims_order)
    order = [str(d).strip() for d in items]
    if len(order) != 4 or len(set(order)) != 4 or not all(order):
        raise InvalidParameterError(
            f"dims_order {dims_order!r} must name four different dimensions: time, z, y, x "
            "(e.g. 'time,depth,lat,lon')"
        )
    return order


def _find_time(ds, dims: list[str], shown: str, time_dim: str | None) -> str:
    if time_dim is not None:
        if time_dim not in dims:
            raise InvalidParameterError(f"time_dim {time_dim!r} is not a dimension of {shown}")
        return time_dim
    found = [d for d in dims if d.lower() in TIME_NAMES]
    found = found or [d for d in dims if _axis_attr(ds, d) == "t" or _is_datetime(ds, d)]
    if not found and dims and all(d.startswith("phony_dim_") for d in dims):
        found = dims[:1]  # plain HDF5 without dimension names: (T, Z, Y, X) in file order
    if len(found) == 1:
        return found[0]
    if found:
        raise InvalidParameterError(
            f"{shown} has several time-like dimensions ({', '.join(found)}); "
            "pick one with --time-dim"
        )
    raise InvalidDataError(
        f"{shown} has no time dimension; a time dimension (time, t or datetime values) is "
        "expected; name it with --time-dim"
    )


def _spatial(ds, v, others: list[str], shown: str) -> list[str]:
    if len(others) > 3:
        # Drop length-1 dims, those not recognised as z/y/x first, until three are left.
        known = {d for d in others if _role(ds, d)}
        ones = [d for d in others if v.sizes[d] == 1]
        ones.sort(key=lambda d: d in known)
        drop = set(ones[: len(others) - 3])
        others = [d for d in others if d not in drop]
    if len(others) != 3:
        raise InvalidDataError(
            f"{shown} has {len(others)} dimension(s) besides time; "
            "a series needs three (z, y, x) plus length-1 extras"
        )
    roles = {d: _role(ds, d) for d in others}
    by_role = {r: [d for d in others if roles[d] == r] for r in AXIS_NAMES}
    if all(len(ds_) == 1 for ds_ in by_role.values()):
        return [by_role[r][0] for r in AXIS_NAMES]
    return others


def _role(ds, dim: str) -> str | None:
    low = dim.lower()
    for role, names in AXIS_NAMES.items():
        if low in names or _axis_attr(ds, dim) == role:
            return role
    return None


def _spacing(ds, dim: str) -> float:
    """The coordinate step of `dim` when its values are numeric and uniform, else 1.0."""
    if dim not in ds.coords or ds[dim].ndim != 1 or ds[dim].size < 2:
        return 1.0
    values = ds[dim].values
    if values.dtype.kind not in "iuf":
        return 1.0
    steps = np.abs(np.diff(values.astype(np.float64)))
    if not np.all(np.isfinite(steps)) or steps.min() <= 0:
        return 1.0
    if steps.max() - steps.min() > 1e-6 * steps.max():
        return 1.0
    return float(steps.mean())


def _time_labels(ds, tdim: str) -> list | None:
    if tdim not in ds.coords or ds[tdim].ndim != 1:
        return None
    values = ds[tdim].values
    if values.dtype.kind == "M":
        return [str(s) for s in np.datetime_as_string(values)]
    if values.dtype.kind == "m":
        return [float(s) for s in values / np.timedelta64(1, "s")]
    if values.dtype.kind in "iuf":
        return [float(s) for s in values]
    return [s.isoformat() if hasattr(s, "isoformat") else str(s) for s in values]


def dataarray_layout(
    array, time_dim: str | None = None, dims_order: str | Sequence[str] | None = None
) -> tuple[object, tuple[float, float, float], list | None]:
    """An xarray DataArray with a time dimension as (T, Z, Y, X): (the transposed DataArray, a
    view where the data allow, its spacing (dz, dy, dx) from uniform coordinates, time labels)."""
    name = str(array.name) if array.name is not None else "data"
    ds = array.to_dataset(name=name)
    tdim, zyx, squeeze = _map_dims(ds, array, name, time_dim, dims_order)
    view = array.isel(dict.fromkeys(squeeze, 0)) if squeeze else array
    view = view.transpose(tdim, *zyx)
    spacing = tuple(_spacing(ds, d) for d in zyx)
    return view, spacing, _time_labels(ds, tdim)  # type: ignore[return-value]
