"""Whole chunks of a local zarr v3 array decoded straight into the caller's rows.

zarr's read path decodes each chunk into a new buffer and copies it into a new result, which
the caller then copies into its own array: three passes over the data and fresh pages for two
of them. At 512³ float32 that made a step cost about three times its decode (0.3 s against
0.1 s here). For the layouts chronocl's writer and zarr write by default (bytes, then zstd or
nothing, then optionally crc32c; no sharding; a chunk holding whole y-x planes of one step) a
chunk's file is read, its checksum checked and its frame decoded here, into the destination
where it is contiguous and else into a buffer of a small process-wide pool (TUNING.keep_buffers stay
between reads).

Anything else goes through zarr, and so does any chunk that is missing, fails its checksum or
does not decode to exactly its size: `checked_read` then reports the damage by its key, or
reads the fill value where the store may lack the chunk. Nothing here can read damage as data.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import google_crc32c
import numcodecs
import numpy as np
import zarr
from zarr.storage import LocalStore

from chronocl.core import host_threads
from chronocl.core.tuning import TUNING
from chronocl.data.integrity import checked_read

_ZSTD_MAGIC = 0xFD2FB528


class DirectChunks:
    """How to read `arr`'s chunks from disk without zarr, or None from `of` where it cannot."""

    def __init__(self, folder: Path, arr: zarr.Array, zstd: bool, crc: bool) -> None:
        self.folder, self.arr, self.zstd, self.crc = folder, arr, zstd, crc
        self.rows = int(arr.chunks[1])
        self.chunk_shape = tuple(int(n) for n in arr.chunks[1:])
        self.dtype = np.dtype(arr.dtype)
        self.nbytes = int(np.prod(self.chunk_shape)) * self.dtype.itemsize
        self._zstd = numcodecs.Zstd() if zstd else None

    @classmethod
    def of(cls, arr: zarr.Array) -> DirectChunks | None:
        """The direct reader of a local zarr v3 array laid out as above; None otherwise."""
        store, meta = arr.store, arr.metadata
        if not isinstance(store, LocalStore) or getattr(meta, "zarr_format", None) != 3:
            return None
        if len(arr.shape) != 4 or arr.chunks[0] != 1 or tuple(arr.chunks[2:]) != arr.shape[2:]:
            return None
        if getattr(arr, "shards", None) is not None or not hasattr(meta, "encode_chunk_key"):
            return None
        try:
            dtype = np.dtype(arr.dtype)
        except TypeError:
            return None
        if dtype.kind not in "biuf" or (dtype.itemsize > 1 and sys.byteorder != "little"):
            return None
        names = [type(c).__name__ for c in meta.codecs]
        if not names or names[0] != "BytesCodec":
            return None
        endian = getattr(meta.codecs[0], "endian", None)
        if dtype.itemsize > 1 and str(getattr(endian, "value", endian)) != "little":
            return None
        crc = names[-1] == "Crc32cCodec"
        middle = names[1 : len(names) - crc]
        if middle not in ([], ["ZstdCodec"]):
            return None
        return cls(Path(store.root) / arr.path, arr, bool(middle), crc)

    def read_chunk(self, step: int, zc: int, out: np.ndarray, first: int = 0) -> bool:
        """Decode chunk (step, zc) and put its rows [first, first + len(out)) in `out`;
        False where zarr must read it (missing, failing a check, or not decoding to exactly
        its size, or too large to decode aside)."""
        whole = out.dtype == self.dtype and out.shape == self.chunk_shape and first == 0
        whole = whole and out.flags.c_contiguous
        if not whole and self.nbytes > TUNING.scratch_bytes:
            return False
        try:
            data = (self.folder / self.arr.metadata.encode_chunk_key((step, zc, 0, 0))).read_bytes()
        except OSError:
            return False
        body = np.frombuffer(data, np.uint8)
        if self.crc:
            if len(body) < 4 or google_crc32c.value(body[:-4]) != int.from_bytes(
                data[-4:], "little"
            ):
                return False
            body = body[:-4]
        if whole:
            return self._decode(body, out.view(np.uint8).reshape(-1))
        with _BUFFERS.held(self.nbytes) as flat:
            if not self._decode(body, flat):
                return False
            out[...] = flat.view(self.dtype).reshape(self.chunk_shape)[first : first + len(out)]
        return True

    def _decode(self, body: np.ndarray, flat: np.ndarray) -> bool:
        if self._zstd is None:
            if len(body) != self.nbytes:
                return False
            flat[:] = body
            return True
        if _zstd_content_size(body) != self.nbytes:
            return False
        try:
            self._zstd.decode(body, out=flat)
        except Exception:  # numcodecs raises RuntimeError for a damaged frame
            return False
        return True


def read_rows(path: Path | None, arr: zarr.Array, step: int, z0: int, z1: int, out: np.ndarray):
    """Read z rows [z0, z1) of `step` of `arr` into `out` (z1 - z0, Y, X): each chunk
    directly (`DirectChunks`) where it can be, else through zarr."""
    direct = DirectChunks.of(arr)
    if direct is None:
        _through_zarr(path, arr, step, z0, z1, out)
        return
    for part in _parts(direct, step, z0, z1, out):
        _read_part(path, arr, direct, part)


def read_steps(
    path: Path | None, arr: zarr.Array, steps, z0: int, z1: int, out: np.ndarray
) -> bool:
    """Fill the xytz brick `out` (z1 - z0, W, Y, X) with rows [z0, z1) of `steps`, their
    chunks decoded directly on the host threads side by side; False (nothing read) where
    `arr` is not laid out for it."""
    direct = DirectChunks.of(arr)
    if direct is None:
        return False
    parts = [p for i, s in enumerate(steps) for p in _parts(direct, int(s), z0, z1, out[:, i])]
    # On a host thread itself (a task of the pool), waiting on the pool could deadlock.
    nested = threading.current_thread().name.startswith(host_threads.THREAD_PREFIX)
    if len(parts) == 1 or host_threads.workers() == 1 or nested:
        for part in parts:
            _read_part(path, arr, direct, part)
    else:
        list(host_threads.pool().map(lambda p: _read_part(path, arr, direct, p), parts))
    return True


def _parts(direct: DirectChunks, step: int, z0: int, z1: int, out: np.ndarray) -> list[tuple]:
    """(step, chunk, first row in it, rows of `out`, first stored row) per chunk of the rows."""
    rows = direct.rows
    parts = []
    for zc in range(z0 // rows, (z1 - 1) // rows + 1):
        a, b = max(z0, zc * rows), min(z1, (zc + 1) * rows)
        parts.append((step, zc, a - zc * rows, out[a - z0 : b - z0], a))
    return parts


def _read_part(path, arr, direct: DirectChunks, part: tuple) -> None:
    step, zc, first, rows, a = part
    if not direct.read_chunk(step, zc, rows, first):
        _through_zarr(path, arr, step, a, a + len(rows), rows)


def _through_zarr(path, arr, step: int, z0: int, z1: int, out: np.ndarray) -> None:
    sel = (int(step), slice(z0, z1))
    out[...] = checked_read(path, arr, lambda: arr[sel], sel)


class _Buffers:
    """Decode buffers of one chunk's size, reused: as many exist as decodes run at once (at
    most the host threads plus the window's readers), and TUNING.keep_buffers stay between reads."""

    def __init__(self) -> None:
        self._free: list[np.ndarray] = []
        self._lock = threading.Lock()

    @contextmanager
    def held(self, nbytes: int) -> Iterator[np.ndarray]:
        with self._lock:
            at = next((i for i, b in enumerate(self._free) if b.nbytes == nbytes), None)
            buf = np.empty(nbytes, np.uint8) if at is None else self._free.pop(at)
        try:
            yield buf
        finally:
            with self._lock:
                self._free.append(buf)
                del self._free[: -TUNING.keep_buffers]


_BUFFERS = _Buffers()


def _zstd_content_size(frame: np.ndarray) -> int | None:
    """The decoded size a zstd frame's header declares (RFC 8878 3.1.1.1); None if absent."""
    if len(frame) < 6 or int.from_bytes(frame[:4].tobytes(), "little") != _ZSTD_MAGIC:
        return None
    desc = int(frame[4])
    fcs_flag, single = desc >> 6, (desc >> 5) & 1
    at = 5 + (not single) + (0, 1, 2, 4)[desc & 3]
    size = (1 if single else 0, 2, 4, 8)[fcs_flag]
    if size == 0 or len(frame) < at + size:
        return None
    value = int.from_bytes(frame[at : at + size].tobytes(), "little")
    return value + 256 if size == 2 else value
