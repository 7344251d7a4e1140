"""Host arrays aligned for the device: 64-byte aligned, so 16-lane vector loads need no fix-up."""

from __future__ import annotations

import mmap

import numpy as np

ALIGN = 64
MAPPED_BYTES = 16 * 2**20  # arrays this large get a memory map of their own (`aligned_empty`)
MADV_POPULATE_WRITE = 23  # Linux 5.14: fault pages in writable without touching their data


def aligned_empty(shape: tuple[int, ...], dtype: object, align: int = ALIGN) -> np.ndarray:
    """An uninitialised C-contiguous array whose data start on an `align`-byte boundary.

    From `MAPPED_BYTES` up, an anonymous memory map of its own (page-aligned): numpy asks the
    kernel for transparent huge pages on large arrays, and where memory is fragmented (a long
    session beside a full page cache) each first touch of a fresh 2 MB page may then wait for the
    kernel to compact memory: 512 MB took 1.6-10 s to fill here where 4 KB pages take 0.4 s.
    """
    dt = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
    if nbytes >= MAPPED_BYTES and align <= mmap.PAGESIZE:
        try:
            mapped = mmap.mmap(-1, nbytes)
        except OSError as exc:  # ENOMEM: out of memory, as numpy's allocation would say
            raise MemoryError(f"cannot allocate {nbytes} bytes: {exc}") from None
        return np.frombuffer(mapped, dtype=dt).reshape(shape)
    raw = np.empty(nbytes + align, dtype=np.uint8)
    offset = (-raw.ctypes.data) % align
    return raw[offset : offset + nbytes].view(dt).reshape(shape)


def is_aligned(a: np.ndarray, align: int = ALIGN) -> bool:
    return a.ctypes.data % align == 0


def prefault(a: np.ndarray) -> bool:
    """Fault in the pages under `a` (a view of an `aligned_empty` memory map, rows of it
    contiguous) without changing what they hold, so a later first write finds them mapped:
    a fresh 512 MB takes 0.2-0.3 s to fault here, and up to 2 s on a virtual machine whose
    host returns freed memory. False where the array is not mapped or the kernel cannot."""
    owner = a
    while isinstance(owner, np.ndarray):
        owner = owner.base
    if isinstance(owner, memoryview):  # np.frombuffer's view of the map
        owner = owner.obj
    if not isinstance(owner, mmap.mmap) or a.ndim < 1:
        return False
    start = np.frombuffer(owner, np.uint8).ctypes.data
    rows = a.reshape(a.shape[0], -1) if a.ndim > 1 else a.reshape(1, -1)
    try:
        for row in rows:
            lo = row.ctypes.data - start
            first = lo - lo % mmap.PAGESIZE
            owner.madvise(MADV_POPULATE_WRITE, first, lo + row.nbytes - first)
    except (OSError, ValueError, AttributeError):  # an older kernel, no madvise, out of memory
        return False
    return True
