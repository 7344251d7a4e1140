"""Labelled (xarray) dimensions mapped to a series' (T, Z, Y, X), with spacing and time labels.

Shared by `TimeSeries.from_array` (an xarray DataArray) and the NetCDF/HDF5 reader (a variable
of a Dataset). The time dimension is found by name (``time``, ``t``), by a CF ``axis``
attribute or by a datetime coordinate; the other three dimensions are mapped to (z, y, x) by
name or kept in their order. Plain HDF5 data sets without dimension names (h5netcdf calls them
``phony_dim_N``) are taken as (T, Z, Y, X) in order. Spacing comes from uniform numeric
coordinates; a non-uniform one is refused, or resampled linearly to uniform spacing on request
(``--resample uniform``). Time labels come from the time coordinate.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import dask.array as da
import numpy as np

from chronocl.core.errors import InvalidDataError, InvalidParameterError

TIME_NAMES = ("time", "t")
AXIS_NAMES = {
    "z": ("z", "depth", "lev", "level", "height", "altitude", "bottom_top"),
    "y": ("y", "lat", "latitude", "south_north"),
    "x": ("x", "lon", "longitude", "west_east"),
}


def _is_datetime(ds, dim: str) -> bool:
    if dim not in ds.coords:
        return False
    c = ds[dim]
    if c.dtype.kind == "M":
        return True
    return c.dtype.kind == "O" and c.size > 0 and hasattr(c.values.flat[0], "isoformat")


def _axis_attr(ds, dim: str) -> str:
    return str(ds[dim].attrs.get("axis", "")).lower() if dim in ds.coords else ""


def map_dims(ds, v, name: str, time_dim, dims_order):
    """(time dim, [z, y, x] dims, length-1 dims to squeeze) of variable `v` named `name` of `ds`.

    `time_dim` names the time dimension, `dims_order` all four (time, z, y, x); None: found.
    """
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


RESAMPLE = ("uniform",)
# Relative spread of a coordinate's steps up to which the coordinate counts as uniform.
UNIFORM_TOLERANCE = 1e-3


@dataclass(frozen=True)
class AxisGrid:
    """How one spatial axis maps to the store: its spacing and, for a non-uniform coordinate
    resampled to uniform spacing, the source index `lo` and `weight` of each output sample
    (value = a[lo] + weight * (a[lo + 1] - a[lo]))."""

    dim: str
    spacing: float = 1.0
    lo: np.ndarray | None = None
    weight: np.ndarray | None = None
    note: str = ""


def axis_grid(ds, dim: str, resample: str | None = None) -> AxisGrid:
    """The grid of dimension `dim`: the step of a uniform numeric coordinate (1.0 without one).

    A non-uniform coordinate (steps differing by more than UNIFORM_TOLERANCE of their mean) is
    refused unless `resample` is ``"uniform"``, which interpolates it linearly onto as many
    uniformly spaced samples over the same range.
    """
    if resample is not None and resample not in RESAMPLE:
        raise InvalidParameterError(f"unknown resample {resample!r}; choose uniform")
    if dim not in ds.coords or ds[dim].ndim != 1 or ds[dim].size < 2:
        return AxisGrid(dim)
    values = ds[dim].values
    if values.dtype.kind not in "iuf":
        return AxisGrid(dim)
    values = values.astype(np.float64)
    steps = np.diff(values)
    if not np.all(np.isfinite(values)) or not (np.all(steps > 0) or np.all(steps < 0)):
        raise InvalidDataError(
            f"coordinate {dim} is not strictly increasing or decreasing finite numbers; "
            "sort or fix it before ingesting"
        )
    steps = np.abs(steps)
    mean = float(abs(values[-1] - values[0]) / (values.size - 1))
    if steps.max() - steps.min() <= UNIFORM_TOLERANCE * mean:
        return AxisGrid(dim, mean)
    spread = f"steps {steps.min():g} to {steps.max():g}"
    if resample is None:
        raise InvalidDataError(
            f"coordinate {dim} is not uniformly spaced ({spread}); pass --resample uniform "
            "(resample='uniform') to interpolate it onto uniform spacing"
        )
    target = np.linspace(values[0], values[-1], values.size)
    order = np.argsort(values)
    index = np.interp(target, values[order], np.arange(values.size, dtype=np.float64)[order])
    lo = np.minimum(np.floor(index).astype(np.intp), values.size - 2)
    note = f"{dim}: non-uniform coordinate ({spread}) resampled linearly to spacing {mean:g}"
    return AxisGrid(dim, mean, lo, (index - lo).astype(np.float32), note)


def resample_step(step: np.ndarray, grids: Sequence[AxisGrid], first_axis: int = 0) -> np.ndarray:
    """`step` with each resampled grid applied along its axis (grids[i] to axis first_axis + i);
    float32 (float64 stays float64) where any axis is resampled, else `step` itself."""
    for i, grid in enumerate(grids):
        if grid.lo is None:
            continue
        axis = first_axis + i
        if step.dtype != np.float64:
            step = step.astype(np.float32, copy=False)
        shape = [1] * step.ndim
        shape[axis] = -1
        a = np.take(step, grid.lo, axis=axis)
        b = np.take(step, grid.lo + 1, axis=axis)
        step = a + (b - a) * grid.weight.reshape(shape).astype(step.dtype)
    return step


def resampled_dtype(dtype: np.dtype, grids: Sequence[AxisGrid]) -> np.dtype:
    """The dtype of steps after `resample_step` with `grids`."""
    if any(g.lo is not None for g in grids) and np.dtype(dtype) != np.float64:
        return np.dtype(np.float32)
    return np.dtype(dtype)


def time_labels(ds, tdim: str) -> list | None:
    """Labels of the time coordinate (ISO dates, seconds or numbers), None without one."""
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
    array, resample: str | None = None
) -> tuple[object, tuple[float, float, float], list | None, list[str]]:
    """An xarray DataArray with a time dimension as (T, Z, Y, X): (its data, a view where the
    data allow, resampled lazily when `resample` is ``"uniform"`` and a coordinate is not
    uniform; its spacing (dx, dy, dz), x first, from the coordinates; time labels; resampling
    notes)."""
    name = str(array.name) if array.name is not None else "data"
    ds = array.to_dataset(name=name)
    tdim, zyx, squeeze = map_dims(ds, array, name, time_dim=None, dims_order=None)
    view = array.isel(dict.fromkeys(squeeze, 0)) if squeeze else array
    view = view.transpose(tdim, *zyx)
    grids = [axis_grid(ds, d, resample) for d in zyx]
    data = view.data
    if any(g.lo is not None for g in grids):
        lazy = da.asarray(data).rechunk({1: -1, 2: -1, 3: -1})
        apply = functools.partial(resample_step, grids=grids, first_axis=1)
        data = lazy.map_blocks(apply, dtype=resampled_dtype(lazy.dtype, grids))
    spacing = tuple(g.spacing for g in reversed(grids))  # grids are z, y, x
    notes = [g.note for g in grids if g.note]
    return data, spacing, time_labels(ds, tdim), notes  # type: ignore[return-value]
