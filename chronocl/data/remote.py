"""Series read where they live: `open_remote` opens an http(s):// or s3:// store as a TimeSeries.

The store is read in place through `chronocl.data.remote_store` (zarr's FsspecStore with the
same damage checks as a local store, retries and one-line errors). The series has no local
`path`; it is named by its URL (`meta["url"]`), its other variables open from the same URL,
and its coarse levels are the store's own ``levels`` group where it has one
(`chronocl.data.remote_levels`), else pooled on the fly; `add_remote_levels` builds that group
for an s3:// store.

`parse_storage_options` reads the CLI's ``--storage-option k=v`` (values parsed as JSON where
they parse: ``anon=true``, ``requester_pays=true``, ``client_kwargs={"region_name": "..."}``).
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import zarr

from chronocl.core import env
from chronocl.core.errors import InvalidParameterError, StoreFormatError
from chronocl.core.progress import track
from chronocl.data.level_writer import NOTHING_TO_ADD, PRESENT, LevelWriter, levels_summary
from chronocl.data.pyramid import LEVELS, level_shapes
from chronocl.data.remote_levels import remote_levels
from chronocl.data.remote_store import filesystem, is_url, join, parse_storage_options
from chronocl.data.remote_write import publish, split_url
from chronocl.data.store_open import open_array
from chronocl.data.timeseries import TimeSeries, from_stored
from chronocl.data.writer import VARIABLES

__all__ = [
    "add_remote_levels",
    "is_url",
    "open_remote",
    "parse_storage_options",
    "storage_options_for",
]


def open_remote(url: str, storage_options: Mapping[str, Any] | None = None) -> TimeSeries:
    """Open the chronocl store or bare (T, Z, Y, X) zarr array at `url` in place."""
    options = dict(storage_options or {})
    url = url.rstrip("/")
    stored = open_array(url, options)
    series = from_stored(stored, stored.source or url, {**stored.meta, "url": url})
    series.zarr_array = stored.array  # reads go to zarr directly, through the remote store
    names = series.variables
    own = series.meta.get("variable")
    if len(names) > 1:
        root = url if own in (None, names[0]) else url.rsplit("/", 2)[0]

        def open_variable(name: str) -> TimeSeries:
            return open_remote(
                root if name == names[0] else join(root, f"{VARIABLES}/{name}"), options
            )

        series.open_variable = open_variable
    if stored.stats is not None:
        series.level_source = remote_levels(url, options, series)
    return series


def storage_options_for(store: str, options: dict[str, Any]) -> dict[str, Any]:
    """The options that apply to `store`: none for a local path; S3's own (``anon``,
    ``endpoint_url``) dropped for HTTP, whose filesystem takes only client arguments."""
    if not is_url(store):
        if options:
            raise InvalidParameterError(
                f"--anon and --storage-option apply to http(s):// and s3:// stores, not to the "
                f"local path {store!r}"
            )
        return {}
    if store.lower().startswith(("http://", "https://")):
        return {k: v for k, v in options.items() if k != "anon"}
    return options


def add_remote_levels(
    url: str, options: Mapping[str, Any], progress: bool = False, force: bool = False
) -> dict:
    """`chronocl pyramid` for an s3:// store: the levels are built from the store's steps in a
    local staging folder, then published under ``levels`` with ``levels/zarr.json`` last
    (`chronocl.data.remote_write.publish`). Until that last key a reader finds no levels and
    pools them on the fly; keys of an interrupted earlier build (no ``levels/zarr.json``) are
    removed first, as are old levels with `force`. ``data`` and the root are only read."""
    bucket, key = split_url(url)
    series = open_remote(url, options)
    if series.stats is None or series.zarr_array is None:
        raise StoreFormatError(f"{url} is not a chronocl store; ingest it with 'chronocl ingest'")
    arr, shape = series.zarr_array, tuple(int(n) for n in series.shape)
    if not level_shapes(shape[1:]):
        return levels_summary(url, shape, 1, NOTHING_TO_ADD)
    has = filesystem(options).exists(f"{bucket}/{key}/{LEVELS}/zarr.json")
    if has and not force:
        series.level(1).read([0])  # damaged levels metadata is reported, not kept silently
        return levels_summary(url, shape, series.n_levels, PRESENT)
    chunk_bytes = int(arr.chunks[1]) * shape[2] * shape[3] * arr.dtype.itemsize
    where = env.get("CHRONOCL_TMPDIR") or None  # as `remote_write.remote_output`
    with tempfile.TemporaryDirectory(prefix="chronocl-upload-", dir=where) as staging:
        local = Path(staging) / LEVELS
        group = zarr.open_group(store=str(local), mode="w", zarr_format=3)
        writer = LevelWriter(group, shape, arr.dtype, arr.compressors, chunk_bytes)
        for t in track(range(shape[0]), shape[0], "building levels", progress):
            writer.add(t, series.read([t])[0])
        writer.finish()
        publish(local, f"{url.rstrip('/')}/{LEVELS}", options, overwrite=True)
    return levels_summary(url, shape, 1 + len(writer.shapes), "rebuilt" if has else "added")
