"""A numpy, dask or xarray array checked as a series, for `TimeSeries.from_array`.

An xarray DataArray has its dimensions mapped by name and its spacing and time labels read
from its coordinates (`chronocl.data.labelled`); any array is checked for shape, dtype and
finite values, and its per-step statistics are computed in one dask pass. No copy is made.
"""

from __future__ import annotations

from collections.abc import Sequence

import dask.array as da
import numpy as np

from chronocl.core.errors import InvalidDataError, InvalidParameterError
from chronocl.core.times_meta import check_time_unit
from chronocl.data.labelled import dataarray_layout
from chronocl.data.metadata import (
    check_dtype,
    check_shape,
    parse_spacing,
    parse_times,
    stats_from_steps,
)


def array_fields(
    array: object,
    spacing: Sequence[float] | None,
    times: Sequence | None,
    source: str,
    resample: str | None,
    time_unit: str | None,
) -> dict:
    """The `TimeSeries` fields of `array` (T, Z, Y, X): data, stats, spacing, times, source,
    meta (the arguments as `TimeSeries.from_array` documents them)."""
    meta: dict = {}
    if type(array).__module__.startswith("xarray"):
        array, coord_spacing, coord_times, notes = dataarray_layout(array, resample=resample)
        spacing = coord_spacing if spacing is None else spacing
        times = coord_times if times is None else times
        if notes:
            meta["resampled"] = notes
    spacing = (1.0, 1.0, 1.0) if spacing is None else spacing
    if time_unit is not None:  # checked before the statistics pass reads the data
        if times is None:
            raise InvalidParameterError(
                f"time_unit={time_unit!r} needs the steps' times; give times= as well"
            )
        meta["time_unit"] = check_time_unit(time_unit)
    if not isinstance(array, da.Array):
        try:
            array = np.asarray(array)
        except (ValueError, TypeError) as exc:
            raise InvalidDataError(
                f"{source} is not a rectangular array ({exc}); pass a (T, Z, Y, X) array"
            ) from None
    check_shape(array.shape, "array")
    check_dtype(array.dtype)
    arr = array if isinstance(array, da.Array) else da.from_array(array)
    finite = da.isfinite(arr).all() if arr.dtype.kind == "f" else da.from_array(True)
    smin, smax, smean, ok = da.compute(
        arr.min(axis=(1, 2, 3)), arr.max(axis=(1, 2, 3)), arr.mean(axis=(1, 2, 3)), finite
    )
    if not ok:
        bad = int(np.argmax(~np.isfinite(smin + smax)))
        raise InvalidDataError(
            f"time step {bad} of {source} holds NaN or infinite values; "
            "replace them first (e.g. numpy.nan_to_num) so the value range is defined"
        )
    stats = stats_from_steps(smin, smax, smean)
    return {
        "data": arr,
        "host": array if isinstance(array, np.ndarray) else None,
        "stats": stats,
        "spacing": parse_spacing(spacing),
        "times": parse_times(times, arr.shape[0]),
        "source": source,
        "meta": meta,
    }
