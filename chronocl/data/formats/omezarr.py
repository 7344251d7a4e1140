"""OME-Zarr: read an image (OME-NGFF 0.4 on zarr v2, 0.5 on zarr v3) as a TimeSeries in place.

NGFF 0.4 keeps ``multiscales`` in the group attributes; 0.5 nests it (and
``version``) under ``attributes["ome"]``. The image must have a time axis
(name ``t`` or type ``time``), the spatial axes ``z``, ``y``, ``x`` and at most
one channel axis (name ``c`` or type ``channel``), in any order. One
resolution level (``multiscales[0].datasets[level]``) and one channel are
picked; the level array is wrapped with ``dask.array.from_zarr`` and
transposed to (T, Z, Y, X) without copying anything.

Voxel spacing (dx, dy, dz) comes from the dataset's ``scale`` transformation
times the multiscale's top-level ``scale`` when present; a time scale ``dt``
other than 1 makes the time labels ``t * dt``. Translations are ignored.

When the array is exactly (t, z, y, x) and chunked one time step per chunk,
the series also keeps the zarr array for the fast step-read path. Otherwise
reads go through dask, which works for any chunking but reads whole chunks;
``chronocl ingest`` rewrites such an image into a chronocl store chunked one
step per chunk.

A chronovolume is written as an OME-Zarr image by `chronocl.data.formats.omezarr_chronovolume`.
"""

from __future__ import annotations

import dataclasses
import os
import re
import sys
from collections.abc import Sequence
from pathlib import Path

import dask.array as da
import zarr
from dask.diagnostics import ProgressBar

from chronocl.core.errors import (
    InputNotFoundError,
    InvalidDataError,
    InvalidParameterError,
    StoreFormatError,
    UnknownNameError,
)
from chronocl.data.formats.contract import Reader
from chronocl.data.level_sources import POOLED, AdoptedLevels
from chronocl.data.metadata import parse_spacing
from chronocl.data.pyramid import level_shapes
from chronocl.data.remote_store import Url, is_url
from chronocl.data.stores import open_group
from chronocl.data.timeseries import TimeSeries
from chronocl.data.variables import split_names, write_variables

SPATIAL = ("z", "y", "x")


def is_omezarr(path: str | os.PathLike, storage_options: dict | None = None) -> bool:
    """True when `path` is a zarr group whose metadata holds NGFF ``multiscales`` (0.4 or 0.5);
    `path` may be an http(s):// or s3:// URL (a network failure is raised, not False)."""
    if is_url(path):
        try:
            group = open_group(path, "OME-Zarr image", storage_options=storage_options)
        except (StoreFormatError, InputNotFoundError):
            return False
        return _multiscales(dict(group.attrs)) is not None
    p = Path(path)
    if not p.is_dir():
        return False
    try:
        group = zarr.open_group(store=str(p), mode="r")
    except Exception:  # not a zarr group (or unreadable): not an OME-Zarr image
        return False
    return _multiscales(dict(group.attrs)) is not None


def open_omezarr(
    path: str | os.PathLike,
    *,
    channel: int = 0,
    level: int = 0,
    progress: bool = False,
    storage_options: dict | None = None,
) -> TimeSeries:
    """Open one channel and resolution level of an OME-Zarr image as a lazy (T, Z, Y, X) series.

    Nothing is copied: the series reads the image's own chunks. Statistics
    (global and per-step min/max/mean) are computed in one dask pass. `path` may be an
    http(s):// or s3:// URL, read in place with `storage_options`.
    """
    remote = is_url(path)
    p = Url(path) if remote else Path(path)
    group = open_group(p, "OME-Zarr image", storage_options=storage_options)
    ms = _multiscales(dict(group.attrs))
    if ms is None:
        raise StoreFormatError(
            f"{str(p)!r} is not an OME-Zarr image (no 'multiscales' in its group metadata)"
        )
    axes = _axis_names(ms.get("axes"), p)
    roles = _roles(axes, p)
    datasets = ms.get("datasets") or []
    if not datasets:
        raise StoreFormatError(f"OME-Zarr image {str(p)!r} lists no datasets in 'multiscales'")
    if not isinstance(level, int) or not 0 <= level < len(datasets):
        raise InvalidParameterError(
            f"level {level} is out of range: {str(p)!r} has {len(datasets)} resolution "
            f"level(s) (0..{len(datasets) - 1})"
        )
    ds = datasets[level]
    ds_path = str(ds.get("path", ""))
    try:
        arr = group[ds_path]
    except KeyError:
        arr = None
    if not isinstance(arr, zarr.Array):
        raise StoreFormatError(
            f"OME-Zarr image {str(p)!r} has no array {ds_path!r} for level {level}"
        )
    if arr.ndim != len(axes):
        raise InvalidDataError(
            f"level {level} of {str(p)!r} has {arr.ndim} dimensions but {len(axes)} axes "
            f"({','.join(axes)})"
        )
    index: list[object] = [slice(None)] * arr.ndim
    c_axis = roles.get("c")
    if c_axis is not None:
        n_ch = int(arr.shape[c_axis])
        if not isinstance(channel, int) or not 0 <= channel < n_ch:
            raise InvalidParameterError(
                f"channel {channel} is out of range: {str(p)!r} has {n_ch} channel(s) "
                f"(0..{n_ch - 1})"
            )
        index[c_axis] = channel
    elif channel != 0:
        raise InvalidParameterError(
            f"channel {channel} is out of range: {str(p)!r} has no channel axis (1 channel, 0)"
        )
    scale = _scale(ms, ds, len(axes), p)
    spacing = parse_spacing([scale[roles[a]] for a in "xyz"])
    dt = scale[roles["t"]]
    times = None
    if dt != 1.0:
        times = [i * dt for i in range(int(arr.shape[roles["t"]]))]

    lazy = da.from_zarr(arr)[tuple(index)]
    kept = [i for i in range(arr.ndim) if i != c_axis]  # axes left after picking the channel
    order = [kept.index(roles[a]) for a in ("t", *SPATIAL)]
    lazy = lazy.transpose(order)
    source = f"{p.name} (OME-Zarr level {level}" + (
        f", channel {channel})" if c_axis is not None else ")"
    )
    if progress:
        with ProgressBar(out=sys.stderr):
            series = TimeSeries.from_array(lazy, spacing=spacing, times=times, source=source)
    else:
        series = TimeSeries.from_array(lazy, spacing=spacing, times=times, source=source)
    meta, open_variable = series.meta, None
    if c_axis is not None and arr.shape[c_axis] > 1:  # the channels are the variables
        names = channel_names(dict(group.attrs), int(arr.shape[c_axis]))
        meta = {"variable": names[channel], "variables": names}

        def open_variable(name: str) -> TimeSeries:
            return open_omezarr(
                path,
                channel=names.index(name),
                level=level,
                progress=progress,
                storage_options=storage_options,
            )

    own = _own_levels(lazy, group, datasets, index, order) if level == 0 else {}
    series = dataclasses.replace(
        series,
        meta=meta,
        level_source=AdoptedLevels(own) if own else POOLED,
        open_variable=open_variable,
    )
    fast = tuple(axes) == ("t", *SPATIAL) and arr.chunks[0] == 1
    return series.stored_in(None if remote else p, arr if fast else None)


def _own_levels(lazy: da.Array, group, datasets: list, index: list, order: list) -> dict:
    """The image's own resolution levels whose shapes are those of chronocl's rule
    (docs/levels.md), by level n, read in place: the series' "mean" levels (`AdoptedLevels`;
    the other levels and pools are pooled on the fly)."""
    shapes = level_shapes(lazy.shape[1:])
    own = {}
    for ds in datasets[1:]:
        arr = group.get(str(ds.get("path", "")))
        if not isinstance(arr, zarr.Array) or arr.dtype != lazy.dtype:
            continue
        data = da.from_zarr(arr)[tuple(index)].transpose(order)
        if data.shape[0] != lazy.shape[0] or tuple(data.shape[1:]) not in shapes:
            continue
        own[shapes.index(tuple(data.shape[1:])) + 1] = data
    return own


def channel_names(attrs: dict, n: int) -> list[str]:
    """Names of an image's `n` channels: its omero labels made fit to name a variable (letters,
    digits, _ . + -; one of each name), else c0, c1, ..."""
    omero = attrs.get("omero") if isinstance(attrs.get("omero"), dict) else {}
    listed = omero.get("channels") if isinstance(omero.get("channels"), list) else []
    names: list[str] = []
    for i in range(n):
        label = listed[i].get("label") if i < len(listed) and isinstance(listed[i], dict) else None
        name = re.sub(r"[^A-Za-z0-9_.+-]", "_", str(label)).strip("._") if label else ""
        if not name or name in names:
            name = f"c{i}"
        names.append(name)
    return names


def ingest_omezarr(
    path: str | os.PathLike,
    out: str | os.PathLike,
    *,
    channel: int = 0,
    level: int = 0,
    variables: Sequence[str] | str | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> TimeSeries:
    """Copy one channel and resolution level of an OME-Zarr image into a chronocl store; with
    `variables` (channel names, or "all") several channels, each a variable of the store."""
    series = open_omezarr(path, channel=channel, level=level)
    if not variables:
        return series.save(out, overwrite=overwrite, progress=progress)
    names = split_names(variables, "--variables")
    have = series.variables or ("c0",)
    if names == ["all"]:
        names = list(have)
    missing = [n for n in names if n not in have]
    if missing:
        raise UnknownNameError(
            f"{Path(path).name} has no channel {missing[0]!r}; its channels: {', '.join(have)} "
            "(or give --variables all)"
        )
    parts = []
    for name in names:
        one = series.variable(name) if series.variables else series
        parts.append((name, one.steps()))
    return write_variables(out, parts, overwrite=overwrite, progress=progress)


# -- reading: metadata ------------------------------------------------------------------


def _multiscales(attrs: dict) -> dict | None:
    """The first multiscale of NGFF 0.5 (``attrs['ome']``) or 0.4 (top-level) metadata."""
    for where in (attrs.get("ome"), attrs):
        if isinstance(where, dict):
            ms = where.get("multiscales")
            if isinstance(ms, list) and ms and isinstance(ms[0], dict):
                return ms[0]
    return None


def _axis_names(axes: object, p: Path) -> list[str]:
    """Axis names, lower-cased; a time axis of another name (type 'time') becomes 't'."""
    if not isinstance(axes, list) or not axes:
        raise StoreFormatError(
            f"OME-Zarr image {str(p)!r} has no 'axes' in 'multiscales' (NGFF < 0.4 is not read)"
        )
    names = []
    for a in axes:
        if isinstance(a, str):  # NGFF 0.3 wrote bare names
            name, kind = a, ""
        elif isinstance(a, dict):
            name, kind = str(a.get("name", "")), str(a.get("type", ""))
        else:
            raise StoreFormatError(f"OME-Zarr image {str(p)!r} has a malformed axis {a!r}")
        name = name.lower()
        if kind == "time" and name not in SPATIAL:
            name = "t"
        elif kind == "channel" and name not in SPATIAL:
            name = "c"
        names.append(name)
    return names


def _roles(axes: list[str], p: Path) -> dict[str, int]:
    """Position of each of t, c (optional), z, y, x; a one-line error for anything else."""
    found = ",".join(axes)
    if "t" not in axes:
        raise InvalidDataError(f"{str(p)!r} has axes {found}; a time series needs a t axis")
    allowed = {"t", "c", *SPATIAL}
    if len(set(axes)) != len(axes) or not set(axes) <= allowed or not set(SPATIAL) <= set(axes):
        raise InvalidDataError(
            f"{str(p)!r} has axes {found}; expected t, [c,] z, y, x (one each, c optional)"
        )
    return {name: i for i, name in enumerate(axes)}


def _scale(ms: dict, ds: dict, ndim: int, p: Path) -> list[float]:
    """Per-axis scale: the dataset's ``scale`` times the multiscale's top-level one."""
    out = [1.0] * ndim
    for transforms in (ds.get("coordinateTransformations"), ms.get("coordinateTransformations")):
        for tr in transforms or []:
            if not isinstance(tr, dict) or tr.get("type") != "scale":
                continue
            values = tr.get("scale")
            if values is None and "path" in tr:
                raise InvalidDataError(
                    f"OME-Zarr image {str(p)!r} stores its scale in a separate array; "
                    "only inline 'scale' values are read"
                )
            if not isinstance(values, list) or len(values) != ndim:
                raise InvalidDataError(
                    f"OME-Zarr image {str(p)!r} has a scale {values!r} that does not give "
                    f"one number per axis ({ndim})"
                )
            try:
                out = [o * float(v) for o, v in zip(out, values, strict=True)]
            except (TypeError, ValueError):
                raise InvalidDataError(
                    f"OME-Zarr image {str(p)!r} has a non-numeric scale {values!r}"
                ) from None
    return out


READER = Reader(
    "omezarr",
    ingest_omezarr,
    options={"channel": 0, "level": 0, "variables": None},
    recognises=is_omezarr,  # a folder
    single=True,
    common=("overwrite", "progress"),  # the image is copied as it is: no nan_fill
)
