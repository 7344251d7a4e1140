"""Opening a store's (T, Z, Y, X) array, for `chronocl.data.timeseries.open_store`.

A chronocl store (zarr v3 written by `chronocl.data.writer`, v2 read) holds the array as
``data`` beside the attribute ``chronocl`` (statistics, spacing, time labels and what the
writer records with them); a bare zarr array (v2 or v3) holds the array alone. Either opens
through `CheckedStore` and is wrapped for dask through `CheckedArray`
(`chronocl.data.integrity`), told which chunks may be missing, so damage is never read as zeros.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import dask.array as da
import zarr

from chronocl.core.errors import ChronoclError, StoreFormatError
from chronocl.data.integrity import CheckedArray, CheckedStore, check_byte_order, damaged
from chronocl.data.metadata import (
    FORMAT,
    SeriesStats,
    check_dtype,
    check_shape,
    checked_attrs,
    unreadable_metadata,
)
from chronocl.data.remote_store import is_url, missing_store, remote_store
from chronocl.data.stores import require_store
from chronocl.data.writer import EXTRA_KEYS


@dataclass(frozen=True)
class StoredArray:
    """A store's array (`array`, zarr) and `data`, dask over it, with what the store records.

    `stats` is None for a bare array, whose statistics are still to be computed; the other
    fields then keep their defaults.
    """

    path: Path | None
    array: zarr.Array
    data: da.Array
    source: str
    stats: SeriesStats | None = None
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    times: tuple = ()
    meta: dict = field(default_factory=dict)


def open_array(p: Path | str, storage_options: dict | None = None) -> StoredArray:
    """Open the array of the chronocl store or bare zarr array at `p`, its metadata checked.

    `p` is a local path, or an http(s):// or s3:// URL (`chronocl.data.remote_store`, whose
    `storage_options` go to fsspec); a remote store's `path` is None and `source` its URL
    where the store records no other.
    """
    remote = is_url(p)
    if remote:
        store = remote_store(str(p), storage_options)
    else:
        require_store(p)
        store = CheckedStore(p)
    try:
        node = _open_node(store, remote)
        inner = node.get("data") if isinstance(node, zarr.Group) else None  # one lookup
        has_data = inner is not None
        arr = inner if has_data else node
    except ChronoclError:  # a remote store's network failure or refusal
        raise
    except Exception as exc:  # zarr raises several kinds for a non-store folder
        if remote:
            raise missing_store(str(p), storage_options) from None
        bad = unreadable_metadata(p)
        if bad is not None:
            raise damaged(p, f"its metadata file {bad} cannot be read") from None
        raise StoreFormatError(
            f"{str(p)!r} is not a zarr store ({type(exc).__name__}); "
            "ingest your data with 'chronocl ingest'"
        ) from None
    if isinstance(arr, zarr.Group):
        raise StoreFormatError(
            f"zarr group {str(p)!r} has no array 'data'; "
            "it is not a chronocl series (is it a chronovolume?)"
        )
    if not has_data:
        store.arrays = ("",)
    attrs = dict(node.attrs).get("chronocl", {})
    check_shape(arr.shape, str(p))
    check_dtype(arr.dtype)
    lazy = da.from_array(CheckedArray(p, arr), chunks=arr.chunks, name=f"chronocl-{p}-{id(arr)}")
    where = None if remote else p
    if not (isinstance(attrs, dict) and attrs.get("format") == FORMAT):
        return StoredArray(path=where, array=arr, data=lazy, source=str(p))
    stats, spacing, times = checked_attrs(p, arr, attrs)
    check_byte_order(p, arr, "data")
    if attrs.get("chunks") == "complete":
        store.complete = True
    else:  # written before stores kept empty chunks: a step may lack all-fill chunks
        fill = float(arr.fill_value)
        store.may_miss = frozenset(
            t for t in range(arr.shape[0]) if stats.step_min[t] <= fill <= stats.step_max[t]
        )
    return StoredArray(
        path=where,
        array=arr,
        data=lazy,
        source=str(attrs.get("source", p)),
        stats=stats,
        spacing=spacing,
        times=times,
        meta={k: attrs[k] for k in EXTRA_KEYS if k in attrs},
    )


def _open_node(store, remote: bool):
    """The group or array at the store's root. Over a network a chronocl store (a zarr v3
    group) is tried first: zarr.open probes every format, a round trip or two more."""
    if remote:
        try:
            return zarr.open_group(store=store, mode="r", zarr_format=3)
        except ChronoclError:
            raise
        except Exception:  # not a v3 group: a bare array, or zarr v2
            pass
    return zarr.open(store=store, mode="r")
