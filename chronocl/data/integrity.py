"""Damaged stores are reported, never read as zeros.

zarr fills a chunk that is missing from a store with the array's fill value, and a chunk whose
bytes no longer decode fails with whatever its codec raises (zstd's RuntimeError, the crc32c
checksum's ValueError, a reshape error). chronocl reads through the pieces here instead:

- `CheckedStore`, a local zarr store that raises `StoreCorruptError` for a missing chunk of a
  store that was written whole (every store chronocl writes keeps its empty chunks), through
  `MissingChunks`, which the remote store (`chronocl.data.remote_store`) shares;
- `checked_read`, which runs a read and turns a codec failure into `StoreCorruptError` naming
  the chunk and the time step that failed;
- `CheckedArray`, a zarr array whose reads go through `checked_read`, for dask.
"""

from __future__ import annotations

import itertools
import os
import re
from collections.abc import Callable, Sequence

import numpy as np
from zarr.storage import LocalStore

from chronocl.core.errors import ChronoclError, StoreCorruptError

_METADATA_NAMES = {"zarr.json", ".zarray", ".zattrs", ".zgroup", ".zmetadata"}
FIX = "restore it from a copy or ingest the data again ('chronocl verify STORE' checks a store)"


def damaged(path: str | os.PathLike, what: str) -> StoreCorruptError:
    """The one-line error for a damaged store at `path`."""
    return StoreCorruptError(f"store {str(path)!r} is damaged: {what}; {FIX}")


def check_byte_order(path: str | os.PathLike, arr, name: str) -> None:
    """StoreCorruptError where array `name` of a chronocl store at `path` is marked other than
    little-endian, the order chronocl writes: its metadata was edited, and its values would read
    as others (its checksums cover the bytes, not their order)."""
    for codec in getattr(arr.metadata, "codecs", ()):
        order = getattr(codec, "endian", None)  # an Endian (zarr 3.1), a str (3.4), or None
        order = getattr(order, "value", order)
        if order not in (None, "little"):
            raise damaged(path, f"its array {name} is marked {order}-endian, not as written")


class MissingChunks:
    """What a checked store (local or remote) does with the chunks it was asked for and did
    not find: notes them, for `checked_read` to raise StoreCorruptError after the read.

    Raising inside zarr's event loop would leave its other reads of the batch pending.

    Only chunks of the arrays named in `arrays` are checked: every chunk when `complete` says
    the store was written with all its chunks; else, when `may_miss` is set, those of steps not
    in it (the steps whose statistics allow a chunk of only the fill value, which stores
    written before chunks were kept could leave out). `where` names the store in errors.
    """

    arrays: tuple[str, ...]
    complete: bool
    may_miss: frozenset[int] | None
    missing: dict[tuple[int, ...], str]
    where: str

    def _init_checks(self, where: str, arrays: tuple[str, ...]) -> None:
        self.where = where
        self.arrays = arrays
        self.complete = False
        self.may_miss = None
        self.missing = {}

    def _note(self, key: str, buf) -> None:
        """Note `key` if its chunk must exist but `buf` says it was not found."""
        if buf is None and (self.complete or self.may_miss is not None):
            coords = self._chunk_coords(key)
            allowed = (
                self.may_miss is not None and coords is not None and coords[0] in self.may_miss
            )
            if coords is not None and not allowed:
                self.missing[coords] = key

    def check(self, touched: list[Sequence[int]]) -> None:
        """Raise StoreCorruptError if a noted missing chunk lies in the chunk index ranges."""
        for coords, key in list(self.missing.items()):
            if all(c in dim for c, dim in zip(coords, touched, strict=False)):
                by_step = self.arrays in (("data",), ("",)) or all(
                    a.startswith("levels/") for a in self.arrays
                )  # series and their coarse levels are chunked one step per chunk
                where = f" ({_where(coords)})" if by_step else ""
                raise damaged(self.where, f"chunk {key}{where} is missing")

    def _chunk_coords(self, key: str) -> tuple[int, ...] | None:
        """The chunk coordinates a key names ('data/c/3/0/0/0', 'data/3.0.0.0'), else None."""
        if key.rsplit("/", 1)[-1] in _METADATA_NAMES:
            return None
        for array in self.arrays:
            prefix = f"{array}/" if array else ""
            if key.startswith(prefix):
                break
        else:
            return None
        rest = key[len(prefix) :]
        if rest[:2] in ("c/", "c."):
            rest = rest[2:]
        try:
            return tuple(int(c) for c in rest.replace(".", "/").split("/"))
        except ValueError:
            return None


class CheckedStore(MissingChunks, LocalStore):
    """A read-only local store that notes the chunks it was asked for and did not find
    (`MissingChunks`; a remote store does the same in `chronocl.data.remote_store`)."""

    def __init__(self, root: str | os.PathLike, arrays: tuple[str, ...] = ("data",)) -> None:
        super().__init__(root, read_only=True)
        self._init_checks(str(self.root), arrays)

    async def get(self, key, prototype=None, byte_range=None):
        buf = await super().get(key, prototype, byte_range)
        self._note(key, buf)
        return buf

    def __reduce__(self):  # for dask.distributed workers
        return _rebuild, (str(self.root), self.arrays, self.complete, self.may_miss)


def _rebuild(root, arrays, complete, may_miss) -> CheckedStore:
    store = CheckedStore(root, arrays)
    store.complete, store.may_miss = complete, may_miss
    return store


def _where(coords: Sequence[int], chunks: Sequence[int] | None = None) -> str:
    """'step 3' for a series chunk (its first coordinate is the step when chunked by step)."""
    if chunks is not None and chunks[0] != 1:
        return f"chunk coordinates {tuple(coords)}"
    return f"step {coords[0]}"


def checked_read(
    path: str | os.PathLike,
    arr,
    read: Callable[[], np.ndarray],
    selection: Sequence[object],
) -> np.ndarray:
    """Run `read()` on zarr array `arr`; a codec failure becomes StoreCorruptError.

    `selection` is what the read covers, one slice, list or int per dimension; on failure the
    chunks it touches are read one by one to name the first that fails.
    """
    if path is None and isinstance(getattr(arr, "store", None), MissingChunks):
        path = arr.store.where  # a remote store, named by its URL
    try:
        values = read()
    except (ChronoclError, MemoryError):
        raise
    except Exception as exc:  # every codec raises its own kind of error
        raise _locate(path, arr, selection, exc) from None
    store = getattr(arr, "store", None)
    if isinstance(store, MissingChunks) and store.missing:
        store.check(_touched(arr, selection))
    return values


def _touched(arr, selection: Sequence[object]) -> list[Sequence[int]]:
    """The chunk indices a read of `selection` touches, one collection per dimension."""
    per_dim = [
        _chunk_indices(sel, n, c)
        for sel, n, c in zip(selection, arr.shape, arr.chunks, strict=False)
    ]
    return per_dim + [
        range(-(-n // c)) for n, c in list(zip(arr.shape, arr.chunks, strict=True))[len(per_dim) :]
    ]


def _locate(path, arr, selection: Sequence[object], exc: Exception) -> StoreCorruptError:
    for coords in itertools.product(*_touched(arr, selection)):
        region = tuple(
            slice(i * c, min((i + 1) * c, n))
            for i, c, n in zip(coords, arr.chunks, arr.shape, strict=True)
        )
        try:
            arr[region]
        except (ChronoclError, MemoryError):
            raise
        except Exception as one:
            key = (
                f"{arr.path}/{arr.metadata.encode_chunk_key(coords)}"
                if hasattr(arr.metadata, "encode_chunk_key")
                else str(coords)
            )
            return damaged(
                path,
                f"chunk {key} ({_where(coords, arr.chunks)}) cannot be decoded ({_decoding(one)})",
            )
    return damaged(path, f"a read failed ({_short(exc)})")


def _chunk_indices(sel: object, n: int, chunk: int) -> Sequence[int]:
    """The chunk indices along one dimension that a slice, list or int selects."""
    if isinstance(sel, slice):
        start, stop, step = sel.indices(n)
        return sorted({i // chunk for i in range(start, stop, step)})
    if isinstance(sel, int | np.integer):
        return [int(sel) // chunk]
    return sorted({int(i) // chunk for i in sel})  # type: ignore[union-attr]


def _decoding(exc: Exception) -> str:
    """Why a chunk could not be decoded, in words (not the codec's checksum bytes)."""
    if "checksum" in str(exc).lower():
        return "its checksum does not match its bytes: the file was damaged or cut short"
    return _short(exc)


def _short(exc: Exception) -> str:
    """An exception as one short line."""
    text = re.sub(r"""(?<!\w)b(['"])(?:\\.|(?!\1).)*\1""", "<bytes>", " ".join(str(exc).split()))
    if len(text) > 160:
        text = text[:157] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class CheckedArray:
    """A zarr array whose reads go through `checked_read` (what dask wraps)."""

    def __init__(self, path: str | os.PathLike, arr) -> None:
        self.path, self.arr = path, arr
        self.shape, self.dtype, self.ndim = arr.shape, arr.dtype, arr.ndim
        self.chunks = arr.chunks

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        return checked_read(self.path, self.arr, lambda: self.arr[key], key)
