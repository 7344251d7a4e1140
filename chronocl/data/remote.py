"""Series read where they live: `open_remote` opens an http(s):// or s3:// store as a TimeSeries.

The store is read in place through `chronocl.data.remote_store` (zarr's FsspecStore with the
same damage checks as a local store, retries and one-line errors). The series has no local
`path`; it is named by its URL (`meta["url"]`), its other variables open from the same URL,
and its coarse levels are the store's own ``levels`` group where it has one
(`chronocl.data.remote_levels`), else pooled on the fly.

`parse_storage_options` reads the CLI's ``--storage-option k=v`` (values parsed as JSON where
they parse: ``anon=true``, ``requester_pays=true``, ``client_kwargs={"region_name": "..."}``).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from typing import Any

from chronocl.core.errors import InvalidParameterError
from chronocl.data.remote_store import is_url, join
from chronocl.data.store_open import open_array
from chronocl.data.timeseries import TimeSeries
from chronocl.data.writer import VARIABLES

__all__ = ["is_url", "open_remote", "parse_storage_options", "storage_options_for"]


def open_remote(url: str, storage_options: Mapping[str, Any] | None = None) -> TimeSeries:
    """Open the chronocl store or bare (T, Z, Y, X) zarr array at `url` in place."""
    from chronocl.data.remote_levels import remote_levels

    options = dict(storage_options or {})
    url = url.rstrip("/")
    stored = open_array(url, options)
    source = stored.source or url
    if stored.stats is None:  # a bare array: its statistics computed in one dask pass
        series = TimeSeries.from_array(stored.data, source=source)
    else:
        series = TimeSeries(
            data=stored.data,
            stats=stored.stats,
            spacing=stored.spacing,
            times=stored.times,
            source=source,
            meta={**stored.meta, "url": url},
        )
    series._zarr = stored.array  # reads go to zarr directly, through the remote store
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


def parse_storage_options(items: Iterable[str] | None, anon: bool = False) -> dict[str, Any]:
    """``k=v`` strings as fsspec storage options; `anon` adds ``anon=True`` (a public bucket)."""
    options: dict[str, Any] = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise InvalidParameterError(
                f"--storage-option {item!r} must be KEY=VALUE, e.g. "
                "endpoint_url=http://localhost:9000"
            )
        try:
            options[key] = json.loads(value)
        except ValueError:
            options[key] = value
    if anon:
        options["anon"] = True
    return options


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
