"""Where a series' coarse levels come from: the `LevelSource` that `TimeSeries.level` asks.

`STORED` reads the ``levels`` group of a chronocl store (`chronocl.data.pyramid`); `POOLED`
pools level 0 on the fly (a series in memory, an image read in place); `AdoptedLevels` takes
arrays a format already holds for some levels (an OME-Zarr image's own resolution levels, read
in place as the "mean" levels) and pools the rest. A series given no source uses STORED when it
is read from a store and POOLED otherwise (`TimeSeries.level_source`). A source returns the
parts that differ from level 0 (`LevelParts`); the series builds and keeps the level.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import dask.array as da
import numpy as np
import zarr

from chronocl.core.errors import InvalidParameterError, StoreFormatError
from chronocl.data.integrity import CheckedArray
from chronocl.data.metadata import SeriesStats
from chronocl.data.pyramid import (
    LEVELS,
    check_pool,
    keep_range,
    lazy_level,
    lazy_stats,
    level_shapes,
    open_level_array,
    read_levels,
)


class LevelZero(Protocol):
    """What a source reads of level 0 (a `TimeSeries`)."""

    data: da.Array
    spacing: tuple[float, float, float]
    source: str
    path: Path | None

    @property
    def shape(self) -> tuple[int, int, int, int]: ...
    @property
    def volume_shape(self) -> tuple[int, int, int]: ...
    @property
    def dims(self) -> tuple[int, int, int]: ...
    @property
    def n_steps(self) -> int: ...
    @property
    def dtype(self) -> np.dtype: ...
    @property
    def vmin(self) -> float: ...
    @property
    def vmax(self) -> float: ...


@dataclass(frozen=True)
class LevelParts:
    """What a coarse level has of its own: its data, statistics (level 0's vmin/vmax with its
    own per-step ones), spacing (x first, level 0's physical extent) and, where `data` wraps a
    zarr array step for step, that array (reads then go to zarr directly)."""

    data: da.Array
    stats: SeriesStats
    spacing: tuple[float, ...]
    array: zarr.Array | None = None


class LevelSource(Protocol):
    """Where the coarse levels of a series come from."""

    def count(self, series: LevelZero) -> int:
        """1 + the coarse levels `series` (level 0) has."""
        ...

    def parts(self, series: LevelZero, n: int, pool: str) -> LevelParts:
        """Level `n` (> 0) of `series` pooled by `pool`; InvalidParameterError for a level it
        lacks, naming those it has."""
        ...


def level_number(n: object, pool: str) -> int:
    """`n` as an int, for a known `pool` and a whole number n; else one clear line."""
    check_pool(pool)
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise InvalidParameterError(f"level {n!r} is not a whole number; give 0, 1, ...")
    return int(n)


def level_shape(series: LevelZero, n: int, top: int) -> tuple[int, int, int]:
    """Level n's (Z, Y, X) shape for n in 1..L of the rule; else one line naming the levels
    0..top that `series` has (`top` 0: only level 0)."""
    shapes = level_shapes(series.volume_shape)
    if not 1 <= n <= len(shapes):
        have = f"levels 0..{top}" if top else "only level 0"
        raise InvalidParameterError(f"level {n} is out of range: {_name(series)} has {have}")
    return shapes[n - 1]


def _name(series: LevelZero) -> str:
    return series.path.name if series.path is not None else series.source or "the series"


def level_spacing(series: LevelZero, shape: Sequence[int]) -> tuple[float, ...]:
    """Spacing (x first) of a level of (Z, Y, X) `shape`: level 0's scaled by its factor."""
    factor = tuple(a / b for a, b in zip(series.volume_shape, shape, strict=True))
    return tuple(s * f for s, f in zip(series.spacing, factor[::-1], strict=True))


class PooledLevels:
    """Every level of the rule (docs/levels.md), pooled lazily step by step from level 0."""

    def count(self, series: LevelZero) -> int:
        return 1 + len(level_shapes(series.volume_shape))

    def parts(self, series: LevelZero, n: int, pool: str) -> LevelParts:
        n = level_number(n, pool)
        shape = level_shape(series, n, len(level_shapes(series.volume_shape)))
        data = lazy_level(series.data, n, pool)
        return LevelParts(
            data, lazy_stats(data, series.vmin, series.vmax), level_spacing(series, shape)
        )


class StoredLevels:
    """The levels written in the ``levels`` group of the chronocl store at `series.path`."""

    def count(self, series: LevelZero) -> int:
        levels = read_levels(series.path, series.shape)
        return 1 if levels is None else 1 + len(levels)

    def parts(self, series: LevelZero, n: int, pool: str) -> LevelParts:
        n, path = level_number(n, pool), series.path
        levels = read_levels(path, series.shape)
        top = len(level_shapes(series.volume_shape)) if levels is not None else 0
        shape = level_shape(series, n, top)
        spacing = level_spacing(series, shape)
        if levels is None:
            raise StoreFormatError(
                f"{_name(series)} has no coarse levels; add them with 'chronocl pyramid {path}'"
            )
        stats = keep_range(levels[n - 1]["stats"][pool], series.vmin, series.vmax)
        arr = open_level_array(path, n, pool, (series.n_steps, *shape), series.dtype)
        data = da.from_array(
            CheckedArray(path, arr),
            chunks=arr.chunks,
            name=f"chronocl-{path}-{LEVELS}-{n}-{pool}-{id(arr)}",
        )
        return LevelParts(data, stats, spacing, arr)


POOLED = PooledLevels()
STORED = StoredLevels()


class AdoptedLevels:
    """Levels a format already holds, read in place for the "mean" pool: `arrays` maps a level
    n to its lazy (T, Z, Y, X) data, of the rule's shape for n; other levels and pools are
    pooled on the fly."""

    def __init__(self, arrays: Mapping[int, da.Array]) -> None:
        self.arrays = dict(arrays)

    def count(self, series: LevelZero) -> int:
        return POOLED.count(series)

    def parts(self, series: LevelZero, n: int, pool: str) -> LevelParts:
        data = self.arrays.get(level_number(n, pool)) if pool == "mean" else None
        if data is None:
            return POOLED.parts(series, n, pool)
        extent = [s * a for s, a in zip(series.spacing, series.dims, strict=True)]  # x first
        spacing = tuple(e / b for e, b in zip(extent, data.shape[:0:-1], strict=True))
        return LevelParts(data, lazy_stats(data, series.vmin, series.vmax), spacing)
