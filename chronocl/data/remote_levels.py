"""The coarse levels of a chronocl store read over HTTP or S3: its ``levels`` group in place.

`RemoteLevels` is the remote twin of `chronocl.data.level_sources.StoredLevels`: the levels
group's metadata is fetched once and checked as a local store's (`pyramid.check_levels`), and
each level array is read through a checked remote store (a missing chunk is StoreCorruptError).
A store without levels pools them on the fly, as a series in memory does; an s3:// store gets
them with `chronocl.data.remote.add_remote_levels`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import dask.array as da
import zarr

from chronocl.core.errors import ChronoclError
from chronocl.data.integrity import CheckedArray, damaged
from chronocl.data.level_sources import (
    POOLED,
    LevelParts,
    LevelZero,
    level_number,
    level_shape,
    level_spacing,
)
from chronocl.data.pyramid import LEVELS, check_levels, keep_range, level_shapes, open_level_array
from chronocl.data.remote_store import remote_store


class RemoteLevels:
    """The levels stored under ``levels`` at `url`, read in place."""

    stored = True  # read, not pooled: cheap to sample (`chronocl.integration.fit_range`)

    def __init__(self, url: str, options: Mapping[str, Any], levels: list[dict]) -> None:
        self.url, self.options, self.levels = url, dict(options), levels

    def count(self, series: LevelZero) -> int:
        return 1 + len(self.levels)

    def parts(self, series: LevelZero, n: int, pool: str) -> LevelParts:
        n = level_number(n, pool)
        shape = level_shape(series, n, len(level_shapes(series.volume_shape)))
        stats = keep_range(self.levels[n - 1]["stats"][pool], series.vmin, series.vmax)
        name = f"{LEVELS}/{n}/{pool}"
        store = remote_store(self.url, self.options, (name,))
        arr = open_level_array(self.url, n, pool, (series.n_steps, *shape), series.dtype, store)
        data = da.from_array(
            CheckedArray(self.url, arr),
            chunks=arr.chunks,
            name=f"chronocl-{self.url}-{LEVELS}-{n}-{pool}-{id(arr)}",
        )
        return LevelParts(data, stats, level_spacing(series, shape), arr)


def remote_levels(url: str, options: Mapping[str, Any], series: LevelZero):
    """RemoteLevels for the store at `url` where it has a levels group, else POOLED."""
    try:
        group = zarr.open_group(
            store=remote_store(url, options, ()), path=LEVELS, mode="r", zarr_format=3
        )
    except ChronoclError:  # the network's failure or a refusal
        raise
    except FileNotFoundError:  # no levels group (zarr's GroupNotFoundError is one)
        return POOLED
    except Exception:
        raise damaged(url, "its levels metadata levels/zarr.json cannot be read") from None
    doc = {"attributes": dict(group.attrs)}
    return RemoteLevels(url, options, check_levels(doc, url, series.shape))
