"""Opening existing zarr groups with errors that say what the path was expected to be."""

from __future__ import annotations

import os
from pathlib import Path

import zarr

from chronocl.core.errors import ChronoclError, InputNotFoundError, StoreFormatError
from chronocl.data.integrity import CheckedStore, check_byte_order
from chronocl.data.remote_store import is_url, missing_store, remote_store


def require_store(p: Path) -> None:
    """A store path that does not exist is one clear line saying how to make one."""
    if not p.exists():
        raise InputNotFoundError(
            f"store {str(p)!r} does not exist; create one with 'chronocl ingest' or "
            "'chronocl generate'"
        )


def open_group(
    path: str | os.PathLike,
    what: str,
    checked: tuple[str, ...] = (),
    storage_options: dict | None = None,
) -> zarr.Group:
    """Open the zarr group at `path` read-only; `what` names the expected thing in errors.

    Missing chunks of the `checked` arrays raise StoreCorruptError when the group's
    attribute ``chronocl.chunks`` says that every chunk was written. `path` may be an
    http(s):// or s3:// URL (`chronocl.data.remote_store`, given `storage_options`).
    """
    remote = is_url(path)
    p = str(path).rstrip("/") if remote else Path(path)
    if not remote and not p.exists():
        raise InputNotFoundError(f"{what} {str(p)!r} does not exist")
    try:
        store = remote_store(p, storage_options, checked) if remote else CheckedStore(p, checked)
        group = zarr.open_group(store=store, mode="r")
        attrs = dict(group.attrs).get("chronocl")
        store.complete = (
            bool(checked) and isinstance(attrs, dict) and attrs.get("chunks") == "complete"
        )
        if isinstance(attrs, dict):  # written by chronocl: little-endian
            for name in checked:
                if name in group:
                    check_byte_order(p, group[name], name)
        return group
    except ChronoclError:  # a remote store's network failure or refusal
        raise
    except Exception:  # zarr raises several kinds for a folder that is not a group
        if remote:
            raise missing_store(p, storage_options) from None
        raise StoreFormatError(f"{str(p)!r} is not a zarr group, so not {_article(what)}") from None


def _article(what: str) -> str:
    return ("an " if what[:1].lower() in "aeiou" else "a ") + what
