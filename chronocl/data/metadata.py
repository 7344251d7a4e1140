"""What a series' metadata must be: supported dtypes, shape, spacing, time labels, statistics.

Checks shared by everything that makes a series (`TimeSeries.from_array`, the store writer,
the readers), and the check of a chronocl store's stored attributes against its array, which
raises `StoreCorruptError` for anything missing, malformed or inconsistent.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from chronocl.core.errors import ChronoclError, InvalidDataError, InvalidParameterError
from chronocl.core.times_meta import Cadence
from chronocl.data.integrity import damaged

FORMAT = "chronocl.series"
SUPPORTED_DTYPES = ("uint8", "uint16", "int16", "float32", "float64")


@dataclass(frozen=True)
class SeriesStats:
    """Statistics gathered while writing: global range and per-step min/max/mean."""

    vmin: float
    vmax: float
    step_min: tuple[float, ...]
    step_max: tuple[float, ...]
    step_mean: tuple[float, ...]


def stats_from_steps(smin, smax, smean) -> SeriesStats:
    """SeriesStats from per-step minima, maxima and means."""
    return SeriesStats(
        vmin=float(np.min(smin)),
        vmax=float(np.max(smax)),
        step_min=tuple(float(v) for v in smin),
        step_max=tuple(float(v) for v in smax),
        step_mean=tuple(float(v) for v in smean),
    )


def parse_spacing(spacing: Sequence[float]) -> tuple[float, float, float]:
    """Validate a voxel spacing (dx, dy, dz), x first: three finite numbers > 0."""
    try:
        sp = tuple(float(s) for s in spacing)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"spacing {spacing!r} must be three numbers") from None
    if len(sp) != 3 or not all(math.isfinite(s) and s > 0 for s in sp):
        raise InvalidParameterError(
            f"spacing {list(sp)} must be three finite numbers > 0: dx, dy, dz (x first)"
        )
    return sp  # type: ignore[return-value]


def parse_times(times: Sequence | None, n_steps: int) -> tuple:
    """One JSON-friendly label per step (numbers or text) from a list or a `Cadence`; the step
    indices when none given."""
    if isinstance(times, Cadence):
        times = times.times(n_steps)
    if times is None or len(times) == 0:
        return tuple(range(n_steps))
    if len(times) != n_steps:
        where = getattr(times, "found", "") or "--times, times="
        raise InvalidParameterError(
            f"got {len(times)} times for {n_steps} steps; give one time per step ({where})"
        )
    out = []
    for t in times:
        if isinstance(t, np.generic):
            t = t.item()
        if isinstance(t, float) and not math.isfinite(t):
            raise InvalidParameterError(f"time label {t} is not finite")
        out.append(t if isinstance(t, int | float | str) else str(t))
    return tuple(out)


def check_shape(shape: Sequence[int], what: str) -> None:
    """Raise unless `shape` is a non-empty 4D (T, Z, Y, X)."""
    if len(shape) != 4:
        raise InvalidDataError(
            f"{what} has {len(shape)} dimensions {tuple(shape)}; a series is 4D (T, Z, Y, X)"
        )
    if shape[0] == 0:
        raise InvalidDataError(f"{what} has zero time steps; a series needs at least one")
    if min(shape[1:]) == 0:
        raise InvalidDataError(f"{what} has an empty volume {tuple(shape[1:])} (Z, Y, X)")


def check_dtype(dtype: np.dtype) -> None:
    """Raise unless `dtype` is one of SUPPORTED_DTYPES."""
    if np.dtype(dtype).name not in SUPPORTED_DTYPES:
        raise InvalidDataError(
            f"data type {np.dtype(dtype).name} is not supported; "
            f"use one of {', '.join(SUPPORTED_DTYPES)}"
        )


def unreadable_metadata(path: Path) -> str | None:
    """The first zarr metadata file under `path` that is not valid JSON, relative to it."""
    for name in ("zarr.json", ".zgroup", ".zarray", ".zattrs"):
        for f in (path / name, path / "data" / name):
            if not f.is_file():
                continue
            try:
                json.loads(f.read_bytes())
            except (ValueError, RecursionError):
                return str(f.relative_to(path))
    return None


def checked_attrs(path: Path, arr, attrs: dict) -> tuple[SeriesStats, tuple, tuple]:
    """The statistics, spacing (dx, dy, dz), x first, and time labels of a chronocl store,
    checked against its array.

    Raises StoreCorruptError when they are missing, malformed or disagree with the array.
    """
    t = arr.shape[0]

    def number(value: object, what: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise damaged(path, f"its {what} is {value!r}, not a number")
        if not math.isfinite(value):
            raise damaged(path, f"its {what} is {value}, not a finite number")
        return float(value)

    def numbers(key: str) -> tuple[float, ...]:
        values = attrs.get(key)
        if not isinstance(values, list):
            raise damaged(path, f"its statistics lack the list {key!r}")
        if len(values) != t:
            raise damaged(
                path, f"it has {t} time steps but {len(values)} entries in its {key} statistics"
            )
        return tuple(number(v, f"{key}[{i}]") for i, v in enumerate(values))

    for key in ("vmin", "vmax"):
        if key not in attrs:
            raise damaged(path, f"its statistics lack {key!r}")
    vmin, vmax = number(attrs["vmin"], "vmin"), number(attrs["vmax"], "vmax")
    smin, smax, smean = numbers("step_min"), numbers("step_max"), numbers("step_mean")
    if vmin > vmax:
        raise damaged(path, f"its value range [{vmin}, {vmax}] is inverted")
    if vmin != min(smin) or vmax != max(smax):
        raise damaged(
            path,
            f"its value range [{vmin}, {vmax}] disagrees with its per-step statistics "
            f"[{min(smin)}, {max(smax)}]",
        )
    for i, (lo, mean, hi) in enumerate(zip(smin, smean, smax, strict=True)):
        if not lo <= hi or not lo - 1e-6 * abs(lo) <= mean <= hi + 1e-6 * abs(hi):
            raise damaged(path, f"the statistics of step {i} are inconsistent")
    chunks = tuple(arr.chunks)
    if chunks[0] != 1 or chunks[2:] != tuple(arr.shape[2:]):
        raise damaged(
            path,
            f"its chunk shape {chunks} is not one step of whole (Y, X) planes "
            f"(1, zc, {arr.shape[2]}, {arr.shape[3]}) as chronocl writes",
        )
    sp = attrs.get("spacing", {})
    try:
        # Stored by axis name ({"x", "y", "z"}), so no order is assumed on disk.
        spacing = parse_spacing((sp.get("x", 1.0), sp.get("y", 1.0), sp.get("z", 1.0)))
    except (ChronoclError, AttributeError):
        raise damaged(path, f"its voxel spacing {sp!r} is not three numbers > 0") from None
    times = attrs.get("times", [])
    if not isinstance(times, list) or len(times) not in (0, t):
        n = len(times) if isinstance(times, list) else type(times).__name__
        raise damaged(path, f"it has {t} time steps but {n} time labels")
    stats = SeriesStats(vmin=vmin, vmax=vmax, step_min=smin, step_max=smax, step_mean=smean)
    return stats, spacing, tuple(times)
