"""OME-Zarr: read an image (OME-NGFF 0.4 on zarr v2, 0.5 on zarr v3) as a TimeSeries in place,
and write a chronovolume as an image (NGFF 0.4 on zarr v2) that napari can open.

Reading. NGFF 0.4 keeps ``multiscales`` in the group attributes; 0.5 nests it (and
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

Writing. Layout of the written group::

    .zattrs        multiscales (axes c, z, y, x; one level "0" whose scale is
                   the chronovolume's spacing), omero (channels red, green,
                   blue, alpha, windows 0..1) and chronocl (metadata)
    0/             float32 (4, Z, Y, X): the RGBA channels, premultiplied by
                   alpha exactly as the chronovolume holds them
    labels/        present when the chronovolume has a t_index:
      t_index/0    int32 (Z, Y, X) label image (-1 where no step contributed)

NGFF 0.4 on zarr v2 (chunk keys separated by "/") is what napari-ome-zarr and
most other OME-Zarr readers read today. `load_chronovolume_omezarr` reads the
file back.
"""

from __future__ import annotations

import dataclasses
import os
import re
import sys
from collections.abc import Sequence
from pathlib import Path

import dask.array as da
import numpy as np
import zarr
from dask.diagnostics import ProgressBar

from chronocl.core.atomic import atomic_directory
from chronocl.core.errors import (
    InvalidDataError,
    InvalidParameterError,
    StoreFormatError,
    UnknownNameError,
)
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.formats.contract import Output, Reader
from chronocl.data.metadata import parse_spacing
from chronocl.data.pyramid import lazy_stats, level_shapes
from chronocl.data.stores import open_group
from chronocl.data.timeseries import TimeSeries
from chronocl.data.variables import split_names, write_variables

SPATIAL = ("z", "y", "x")
FORMAT = "chronocl.chronovolume.omezarr"
NGFF_VERSION = "0.4"
CHANNELS = (("red", "FF0000"), ("green", "00FF00"), ("blue", "0000FF"), ("alpha", "FFFFFF"))
_SPACE_AXES = [{"name": n, "type": "space"} for n in SPATIAL]


def is_omezarr(path: str | os.PathLike) -> bool:
    """True when `path` is a zarr group whose metadata holds NGFF ``multiscales`` (0.4 or 0.5)."""
    p = Path(path)
    if not p.is_dir():
        return False
    try:
        group = zarr.open_group(store=str(p), mode="r")
    except Exception:  # not a zarr group (or unreadable): not an OME-Zarr image
        return False
    return _multiscales(dict(group.attrs)) is not None


def open_omezarr(
    path: str | os.PathLike, *, channel: int = 0, level: int = 0, progress: bool = False
) -> TimeSeries:
    """Open one channel and resolution level of an OME-Zarr image as a lazy (T, Z, Y, X) series.

    Nothing is copied: the series reads the image's own chunks. Statistics
    (global and per-step min/max/mean) are computed in one dask pass.
    """
    p = Path(path)
    group = open_group(p, "OME-Zarr image")
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
    fast = tuple(axes) == ("t", *SPATIAL) and arr.chunks[0] == 1
    series = series.stored_in(p, arr if fast else None)
    if c_axis is not None and arr.shape[c_axis] > 1:  # the channels are the variables
        names = channel_names(dict(group.attrs), int(arr.shape[c_axis]))
        series.meta = {"variable": names[channel], "variables": names}
        series._variable = lambda name: open_omezarr(
            p, channel=names.index(name), level=level, progress=progress
        )
    series._lazy_levels = True
    if level == 0:
        _adopt_levels(series, group, datasets, index, order)
    return series


def _adopt_levels(series: TimeSeries, group, datasets: list, index: list, order: list) -> None:
    """Use the image's own resolution levels, read in place, as the series' "mean" levels
    where their shapes are those of chronocl's rule (docs/levels.md); the other levels and
    pools are pooled on the fly."""
    shapes = level_shapes(series.volume_shape)
    for ds in datasets[1:]:
        arr = group.get(str(ds.get("path", "")))
        if not isinstance(arr, zarr.Array) or arr.dtype != series.dtype:
            continue
        data = da.from_zarr(arr)[tuple(index)].transpose(order)
        if data.shape[0] != series.n_steps or tuple(data.shape[1:]) not in shapes:
            continue
        n = shapes.index(tuple(data.shape[1:])) + 1
        extent = [s * a for s, a in zip(series.spacing, series.dims, strict=True)]  # x first
        spacing = tuple(e / b for e, b in zip(extent, data.shape[:0:-1], strict=True))
        stats = lazy_stats(data, series.vmin, series.vmax)
        series._levels[n, "mean"] = dataclasses.replace(
            series,
            data=data,
            stats=stats,
            spacing=spacing,
            _zarr=None,
            level_index=n,
            _root=series,
            _levels={},
        )


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


# -- writing a chronovolume -------------------------------------------------------------


def save_chronovolume_omezarr(
    cv: Chronovolume, path: str | os.PathLike, overwrite: bool = False
) -> Path:
    """Write `cv` as an OME-Zarr image (NGFF 0.4, zarr v2) atomically; returns the path."""
    rgba = np.asarray(cv.rgba, dtype=np.float32)
    if rgba.ndim != 4 or rgba.shape[3] != 4:
        raise StoreFormatError(f"chronovolume rgba has shape {rgba.shape}; expected (Z, Y, X, 4)")
    z, y, x, _ = rgba.shape
    zc = max(1, min(z, (8 * 2**20) // max(1, y * x * 4)))
    scale = [float(s) for s in cv.spacing_zyx]  # the axes are z, y, x
    with atomic_directory(path, overwrite) as tmp:
        root = zarr.open_group(store=str(tmp), mode="w", zarr_format=2)
        _create(root, "0", np.moveaxis(rgba, 3, 0), (1, zc, y, x))
        root.attrs.update(
            {
                "multiscales": [
                    {
                        "version": NGFF_VERSION,
                        "name": "chronovolume",
                        "axes": [{"name": "c", "type": "channel"}, *_SPACE_AXES],
                        "datasets": [_dataset([1.0, *scale])],
                        "type": "none",
                        "metadata": {"description": "RGBA premultiplied by alpha"},
                    }
                ],
                "omero": {
                    "version": NGFF_VERSION,
                    "name": "chronovolume",
                    "rdefs": {"model": "color", "defaultZ": z // 2, "defaultT": 0},
                    "channels": [_channel(label, color) for label, color in CHANNELS],
                },
                "chronocl": {
                    "format": FORMAT,
                    "version": 1,
                    "premultiplied": True,
                    "channels": [label for label, _ in CHANNELS],
                    "metadata": cv.metadata,
                },
            }
        )
        if cv.t_index is not None:
            t_index = np.asarray(cv.t_index, dtype=np.int32)
            if t_index.shape != (z, y, x):
                raise StoreFormatError(
                    f"chronovolume t_index has shape {t_index.shape}; expected {(z, y, x)}"
                )
            labels = root.create_group("labels")
            labels.attrs["labels"] = ["t_index"]
            label = labels.create_group("t_index")
            _create(label, "0", t_index, (zc, y, x))
            label.attrs.update(
                {
                    "multiscales": [
                        {
                            "version": NGFF_VERSION,
                            "name": "t_index",
                            "axes": list(_SPACE_AXES),
                            "datasets": [_dataset(scale)],
                        }
                    ],
                    "image-label": {"version": NGFF_VERSION, "source": {"image": "../../"}},
                }
            )
    return Path(path)


def load_chronovolume_omezarr(path: str | os.PathLike) -> Chronovolume:
    """Read a chronovolume written by `save_chronovolume_omezarr`."""
    p = Path(path)
    root = open_group(p, "OME-Zarr chronovolume")
    attrs = dict(root.attrs).get("chronocl", {})
    if not isinstance(attrs, dict) or attrs.get("format") != FORMAT or "0" not in root:
        raise StoreFormatError(f"{str(p)!r} is not a chronovolume exported as OME-Zarr by chronocl")
    rgba = np.ascontiguousarray(np.moveaxis(np.asarray(root["0"][...]), 0, 3), dtype=np.float32)
    t_index = None
    if "labels" in root and "t_index" in root["labels"]:
        t_index = np.asarray(root["labels"]["t_index"]["0"][...], dtype=np.int32)
    return Chronovolume(rgba=rgba, t_index=t_index, metadata=dict(attrs.get("metadata", {})))


def _create(group: zarr.Group, name: str, data: np.ndarray, chunks: tuple[int, ...]) -> None:
    """A zarr v2 array with "/"-separated chunk keys, as NGFF 0.4 asks."""
    arr = group.create_array(
        name,
        shape=data.shape,
        dtype=data.dtype,
        chunks=chunks,
        chunk_key_encoding={"name": "v2", "separator": "/"},
    )
    arr[...] = data


def _dataset(scale: list[float]) -> dict:
    return {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": scale}]}


def _channel(label: str, color: str) -> dict:
    return {
        "label": label,
        "color": color,
        "active": label != "alpha",
        "coefficient": 1,
        "family": "linear",
        "inverted": False,
        "window": {"start": 0.0, "end": 1.0, "min": 0.0, "max": 1.0},
    }


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
OUTPUT = Output(".ome.zarr", "napari", save_chronovolume_omezarr)
