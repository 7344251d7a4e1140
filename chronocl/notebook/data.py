"""What `chronocl.show` accepts, as the viewer's data sets: a TimeSeries, a store's path or
URL (opened as `chronocl view` opens it), or a numpy, dask or xarray array with a time axis
(T, Z, Y, X; an xarray DataArray's dimensions mapped by name: `TimeSeries.from_array`)."""

from __future__ import annotations

import json
import os
from pathlib import Path

from chronocl.core.errors import InvalidParameterError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.remote_store import check_storage_options, check_url, is_url
from chronocl.data.series import TimeSeries
from chronocl.notebook.kernel import KERNEL
from chronocl.viewer.datasets import Dataset, open_datasets


def check_store(data: object, storage_options: object) -> object:
    """`data` as `show` opens it, checked before anything is opened (as `chronocl.open` checks
    it, but before the widget is made): a store's URL with its scheme in lower case (http://,
    https://, s3://), anything else as it is; InvalidParameterError in one line for another
    scheme, a URL without a host or bucket, storage options that are not a dict, or storage
    options for anything but a URL."""
    checked = check_url(os.fspath(data) if isinstance(data, os.PathLike) else data)
    check_storage_options(checked, storage_options)
    return data if isinstance(data, os.PathLike) else checked


def as_dataset(
    data: object,
    name: str | None = None,
    storage_options: dict | None = None,
    **array_options,
) -> Dataset:
    """`data` as one named data set; `array_options` (spacing, times, time_unit, resample)
    apply to an array. InvalidParameterError for anything else, naming what it takes (for a
    Chronovolume: the call that shows the series it came from)."""
    if isinstance(data, str | os.PathLike):
        if array_options:
            raise InvalidParameterError(
                f"{', '.join(sorted(array_options))} apply to an array, not to a store "
                "(its own metadata give them)"
            )
        key = store_key(data, storage_options)
        series = KERNEL.find_store(key)
        if series is None:  # (another widget showing it: its series, and so its steps)
            (dataset,) = open_datasets([data], storage_options)
        else:
            base = key[0].rstrip("/").rsplit("/", 1)[-1].removesuffix(".zarr")
            dataset = Dataset(base or "series", series, key[0])
    elif isinstance(data, TimeSeries):
        path = data.path or data.meta.get("url")
        dataset = Dataset(_name(data, path), data, None if path is None else str(path))
    elif isinstance(data, Chronovolume):
        raise InvalidParameterError(chronovolume_refused(data))
    elif hasattr(data, "shape") and hasattr(data, "dtype"):
        series = TimeSeries.from_array(data, **array_options)
        dataset = Dataset(_name(series, None), series)
    else:
        raise InvalidParameterError(
            f"cannot show a {type(data).__name__}; give a TimeSeries, a store's path or URL, or "
            "a numpy, dask or xarray array of shape (T, Z, Y, X)"
        )
    if name is not None:
        dataset.name = str(name)
    return dataset


def store_key(data: str | os.PathLike, storage_options: dict | None) -> tuple[str, str]:
    """A store as the kernel's widgets share it: where it is (a URL, or the resolved path)
    and its storage options."""
    where = str(data) if is_url(str(data)) else str(Path(data).resolve())
    return where, json.dumps(storage_options or {}, sort_keys=True, default=str)


def chronovolume_refused(cv: Chronovolume) -> str:
    """Why `show` takes no Chronovolume, and the call that shows the series it came from: the
    viewer integrates its windows as they change, from a series, and draws no volume made
    before (a precomputed RGBA volume would need a view with no series behind it)."""
    meta = cv.metadata
    source = meta.get("store")
    steps = (meta.get("selection") or {}).get("steps") or []
    args = [repr(str(source)) if source else "series"]
    if steps:
        stride = steps[1] - steps[0] if len(steps) > 1 else 1
        regular = stride > 0 and list(steps) == list(range(steps[0], steps[-1] + 1, stride))
        if regular:
            args.append(
                f"window=({steps[0]}, {steps[-1] + 1}" + (f", {stride})" if stride > 1 else ")")
            )
    mode = (meta.get("spec") or {}).get("mode")
    if mode:
        args.append(f"mode={mode!r}")
    return (
        "chronocl.show views a series, integrating its windows as they change, not a "
        "precomputed Chronovolume: show the series it came from, "
        f"chronocl.show({', '.join(args)}), "
        "or picture this one with chronocl.render(cv) (a notebook shows the Chronovolume itself "
        "as a summary with a picture)"
    )


def _name(series: TimeSeries, path: object) -> str:
    if path is not None:
        base = str(path).rstrip("/").rsplit("/", 1)[-1].removesuffix(".zarr")
        if base:
            return base
    return str(series.source or "series")
