"""Labelled (xarray) dimensions mapped to a series' (T, Z, Y, X), with spacing and time labels.

Shared by `TimeSeries.from_array` (an xarray DataArray) and the NetCDF/HDF5 reader (a variable
of a Dataset). The time dimension is found by name (``time``, ``t``), by a CF ``axis``
attribute or by a datetime coordinate; the other three dimensions are mapped to (z, y, x) by
name or kept in their order. Plain HDF5 data sets without dimension names (h5netcdf calls them
``phony_dim_N``) are taken as (T, Z, Y, X) in order. Spacing comes from uniform numeric
coordinates, time labels from the time coordinate.
"""

from __future__ import annotations

from collections.abc import Sequence

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


def coordinate_spacing(ds, dim: str) -> float:
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
    array, time_dim: str | None = None, dims_order: str | Sequence[str] | None = None
) -> tuple[object, tuple[float, float, float], list | None]:
    """An xarray DataArray with a time dimension as (T, Z, Y, X): (the transposed DataArray, a
    view where the data allow, its spacing (dz, dy, dx) from uniform coordinates, time labels)."""
    name = str(array.name) if array.name is not None else "data"
    ds = array.to_dataset(name=name)
    tdim, zyx, squeeze = map_dims(ds, array, name, time_dim, dims_order)
    view = array.isel(dict.fromkeys(squeeze, 0)) if squeeze else array
    view = view.transpose(tdim, *zyx)
    spacing = tuple(coordinate_spacing(ds, d) for d in zyx)
    return view, spacing, time_labels(ds, tdim)  # type: ignore[return-value]
