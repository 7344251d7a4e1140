"""What `chronocl.show` accepts, as the viewer's data sets: a TimeSeries, a store's path or
URL (opened as `chronocl view` opens it), or a numpy, dask or xarray array with a time axis
(T, Z, Y, X; an xarray DataArray's dimensions mapped by name: `TimeSeries.from_array`)."""

from __future__ import annotations

import os

from chronocl.core.errors import InvalidParameterError
from chronocl.data.series import TimeSeries
from chronocl.viewer.datasets import Dataset, open_datasets


def as_dataset(
    data: object,
    name: str | None = None,
    storage_options: dict | None = None,
    **array_options,
) -> Dataset:
    """`data` as one named data set; `array_options` (spacing, times, time_unit, resample)
    apply to an array. InvalidParameterError for anything else, naming what it takes."""
    if isinstance(data, str | os.PathLike):
        if array_options:
            raise InvalidParameterError(
                f"{', '.join(sorted(array_options))} apply to an array, not to a store "
                "(its own metadata give them)"
            )
        (dataset,) = open_datasets([data], storage_options)
    elif isinstance(data, TimeSeries):
        path = data.path or data.meta.get("url")
        dataset = Dataset(_name(data, path), data, None if path is None else str(path))
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


def _name(series: TimeSeries, path: object) -> str:
    if path is not None:
        base = str(path).rstrip("/").rsplit("/", 1)[-1].removesuffix(".zarr")
        if base:
            return base
    return str(series.source or "series")
