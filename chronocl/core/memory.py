"""Host arrays aligned for the device: 64-byte aligned, so 16-lane vector loads need no fix-up."""

from __future__ import annotations

import mmap

import numpy as np

ALIGN = 64
MAPPED_BYTES = 16 * 2**20  # arrays this large get a memory map of their own (`aligned_empty`)


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
