"""The coarse levels of a chronocl store read over HTTP or S3: its ``levels`` group in place.

`RemoteLevels` is the remote twin of `chronocl.data.level_sources.StoredLevels`: the levels
group's metadata is fetched once and checked as a local store's (`pyramid.check_levels`), and
each level array is read through a checked remote store (a missing chunk is StoreCorruptError).
A store without levels pools them on the fly, as a series in memory does.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import dask.array as da
import zarr

from chronocl.core.errors import ChronoclError, StoreFormatError
from chronocl.data.integrity import CheckedArray, damaged
from chronocl.data.level_sources import POOLED, LevelParts, LevelZero, _shape, _spacing, _whole
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
        n = _whole(n, pool)
        shape = _shape(series, n, len(level_shapes(series.volume_shape)))
        stats = keep_range(self.levels[n - 1]["stats"][pool], series.vmin, series.vmax)
        name = f"{LEVELS}/{n}/{pool}"
        store = remote_store(self.url, self.options, (name,))
        arr = open_level_array(self.url, n, pool, (series.n_steps, *shape), series.dtype, store)
        data = da.from_array(
            CheckedArray(self.url, arr),
            chunks=arr.chunks,
            name=f"chronocl-{self.url}-{LEVELS}-{n}-{pool}-{id(arr)}",
        )
        return LevelParts(data, stats, _spacing(series, shape), arr)


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


def add_remote_levels(
    url: str, options: Mapping[str, Any], progress: bool = False, force: bool = False
) -> dict:
    """`chronocl pyramid` for an s3:// store: the levels are built from the store's steps in a
    local staging folder, then published under ``levels`` with ``levels/zarr.json`` last
    (`chronocl.data.remote_write.publish`). Until that last key a reader finds no levels and
    pools them on the fly; keys of an interrupted earlier build (no ``levels/zarr.json``) are
    removed first, as are old levels with `force`. ``data`` and the root are only read."""
    import os
    import tempfile
    from pathlib import Path

    from chronocl.core.progress import track
    from chronocl.data.level_writer import LevelWriter
    from chronocl.data.pyramid import COARSEST, describe_levels
    from chronocl.data.remote import open_remote
    from chronocl.data.remote_write import filesystem, publish, split_url

    bucket, key = split_url(url)
    series = open_remote(url, options)
    if series.stats is None or series._zarr is None:
        raise StoreFormatError(f"{url} is not a chronocl store; ingest it with 'chronocl ingest'")
    arr, shape = series._zarr, tuple(int(n) for n in series.shape)
    summary = {"store": url}
    if not level_shapes(shape[1:]):
        return {
            **summary,
            "levels": describe_levels(shape[1:], 1),
            "status": f"nothing to add: levels are made while the largest axis is > {COARSEST}",
        }
    has = filesystem(options).exists(f"{bucket}/{key}/{LEVELS}/zarr.json")
    if has and not force:
        series.level(1).read([0])  # damaged levels metadata is reported, not kept silently
        return {
            **summary,
            "levels": describe_levels(shape[1:], series.n_levels),
            "status": "levels already present (pass --force to rebuild them)",
        }
    chunk_bytes = int(arr.chunks[1]) * shape[2] * shape[3] * arr.dtype.itemsize
    where = os.environ.get("CHRONOCL_TMPDIR") or None  # as `remote_write.remote_output`
    with tempfile.TemporaryDirectory(prefix="chronocl-upload-", dir=where) as staging:
        local = Path(staging) / LEVELS
        group = zarr.open_group(store=str(local), mode="w", zarr_format=3)
        writer = LevelWriter(group, shape, arr.dtype, arr.compressors, chunk_bytes)
        for t in track(range(shape[0]), shape[0], "building levels", progress):
            writer.add(t, series.read([t])[0])
        writer.finish()
        publish(local, f"{url.rstrip('/')}/{LEVELS}", options, overwrite=True)
    return {
        **summary,
        "levels": describe_levels(shape[1:], 1 + len(writer.shapes)),
        "status": "rebuilt" if has else "added",
    }
