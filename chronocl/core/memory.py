"""Host arrays aligned for the device: 64-byte aligned, so 16-lane vector loads need no fix-up.

`recycled_empty` is the process's one pool of reusable host buffers, for what is made again and
again at one size (a chronovolume per call of `chronocl.integrate`, per edit of a session): the
memory of one that died is handed out again, already faulted in, instead of a fresh map whose
every page faults on first write. What a frame gives back the next takes again; what nobody
takes goes back to the system (`_Spares`). `--memory` (`chronocl.core.process_memory`) counts
the process's resident memory, so every host buffer below, the pool's spares included.

Where the process keeps host or device buffers beyond one call, and why:

- pooled here: chronovolume outputs (RGBA, t_index, winners written by the kernels), a slide's
  partials and a device array's read-back (`engine.device_arrays`), the recolouring's gathered
  winners and its RGBA8 output (`render.recolour`), a GPU recolour's RGBA read back when
  something reads it (`viewer.recolouring.InTexture`), and the texture staging of the viewer's
  uploads (`render.upload.convert`): taken per frame, given back when the frame lets go;
- step slots (`data.slots.StepSlots`): one block per window manager, its free slots faulted in
  ahead by the warming thread and handed back when `--memory` asks (`ProcessLimit.fit`): their
  owner counts them (`held_bytes`); its rare `gc.collect` returns slots held in cycles;
- handed over first: a recolouring's output goes to the next window's winners of its shape
  (`BrickWinners.take_held`), whose coloured bricks say what to rewrite, so nothing is zeroed;
  to the pool when released untaken;
- on the device: a panel's GL textures, the current one and `TUNING.kept_textures` of other
  sizes (`viewer.slots.ViewSlot`; host memory on llvmpipe, counted there), the OpenCL queues'
  pinned staging and chunk buffers (`engine.transfer.Streams`, one set per device context,
  grown to the largest chunk, 4-64 MiB by default; pinned pages are resident, so counted by
  `--memory`, their device buffers fall within the share of device memory left beside
  resident steps) and resident steps on a GPU (`engine.device_steps`, their own budget);
- per thread, reader or engine, for their lifetime: the conversion's cache-sized scratch
  (`render.upload`), a dask worker's brick buffer (`data.bricks.SeriesBricks.per_thread`), a
  reader's two brick buffers (`SeriesBricks.buffered`), the TF tables
  (`engine.tables.TableCache`) and the events' label buffers (`events.run`)."""

from __future__ import annotations

import ctypes
import ctypes.util
import mmap
import os
import threading
import time
import weakref
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from chronocl.core.tuning import TUNING

ALIGN = 64
MADV_POPULATE_WRITE = 23  # Linux 5.14: fault pages in writable without touching their data
# `aligned_empty`'s maps are shared (Python's anonymous mmap): MADV_DONTNEED only unmaps their
# pages, which keep their memory (and contents) until the map goes; MADV_REMOVE frees them.
MADV_FREE_SHARED = getattr(mmap, "MADV_REMOVE", 9)


def aligned_empty(shape: tuple[int, ...], dtype: object, align: int = ALIGN) -> np.ndarray:
    """An uninitialised C-contiguous array whose data start on an `align`-byte boundary.

    From `TUNING.mapped_bytes` up, an anonymous memory map of its own (page-aligned): numpy asks the
    kernel for transparent huge pages on large arrays, and where memory is fragmented (a long
    session beside a full page cache) each first touch of a fresh 2 MB page may then wait for the
    kernel to compact memory: 512 MB took 1.6-10 s to fill here where 4 KB pages take 0.4 s.
    """
    dt = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
    if nbytes >= TUNING.mapped_bytes and align <= mmap.PAGESIZE:
        try:
            mapped = mmap.mmap(-1, nbytes)
        except OSError as exc:  # ENOMEM: out of memory, as numpy's allocation would say
            raise MemoryError(f"cannot allocate {nbytes} bytes: {exc}") from None
        return np.frombuffer(mapped, dtype=dt).reshape(shape)
    raw = np.empty(nbytes + align, dtype=np.uint8)
    offset = (-raw.ctypes.data) % align
    return raw[offset : offset + nbytes].view(dt).reshape(shape)


class _Spares:
    """The memory maps of `recycled_empty` arrays that died, most recent last: at most
    `TUNING.spare_maps` of a size, of the `TUNING.spare_sizes` sizes given back last, for at
    most `TUNING.spare_seconds`. What the caller held a moment ago, so keeping it adds nothing
    to the peak.
    Counted per size: a session gives its last chronovolume back before it takes memory for the
    next, and with two maps in all it pushed out the spares of every other caller (in
    bench/integrate.py's race `chronocl.integrate` then wrote on fresh pages: 2x slower)."""

    def __init__(self) -> None:
        # Reentrant: a garbage collection run inside (any allocation may start one) calls the
        # finalizers of recycled arrays that died in reference cycles, which give in this thread
        self.lock = threading.RLock()
        self.maps: list[mmap.mmap] = []
        self._expiry: threading.Timer | None = None  # one at a time, however often they die
        self._until = 0.0  # when the spares go back, TUNING.spare_seconds after the last came
        self._fires_at = 0.0  # when the pending timer looks at `_until`

    def take(self, size: int) -> mmap.mmap | None:
        with self.lock:
            for i in range(len(self.maps) - 1, -1, -1):
                if len(self.maps[i]) == size:
                    return self.maps.pop(i)
        return None

    def give(self, mapped: mmap.mmap) -> None:
        with self.lock:
            self.maps.append(mapped)
            size = len(mapped)
            same = [m for m in self.maps if len(m) == size]
            recent = list(dict.fromkeys(len(m) for m in reversed(self.maps)))[: TUNING.spare_sizes]
            drop = {id(m) for m in same[: -TUNING.spare_maps]}
            self.maps = [m for m in self.maps if len(m) in recent and id(m) not in drop]
            self._until = time.monotonic() + TUNING.spare_seconds
            if (
                self._expiry is None or self._until < self._fires_at
            ):  # (a shorter TUNING.spare_seconds)
                if self._expiry is not None:
                    self._expiry.cancel()
                self._start_expiry(TUNING.spare_seconds)

    def _start_expiry(self, seconds: float) -> None:
        self._fires_at = time.monotonic() + seconds
        self._expiry = threading.Timer(seconds, self._expire)
        self._expiry.daemon = True
        self._expiry.start()

    def _expire(self) -> None:
        """The timer's end: clear, or wait on where a map given since moved the deadline."""
        with self.lock:
            left = self._until - time.monotonic()
            if left > 0 and self.maps:
                self._start_expiry(left)
                return
            self._expiry = None
            self.maps.clear()

    def clear(self) -> None:
        with self.lock:
            self.maps.clear()

    @contextmanager
    def aside(self) -> Iterator[None]:
        """The spares put aside while the block runs (it sees only fresh maps: a first call at a
        size, as bench/integrate.py times it), then put back as they were; maps given back
        meanwhile are let go, so the other callers' spares are as the block found them."""
        with self.lock:
            kept, self.maps = self.maps, []
        try:
            yield
        finally:
            with self.lock:
                self.maps = kept

    def forget(self) -> None:
        """In a forked child: the maps (shared with the parent, as every anonymous map here is)
        are the parent's to hand out, and the lock may have been held by a thread not forked."""
        self.lock, self.maps, self._expiry, self._until = threading.RLock(), [], None, 0.0


spares = _Spares()
os.register_at_fork(after_in_child=spares.forget)


def _give_back(mapped: mmap.mmap, pid: int) -> None:
    """A recycled array died: its map is spare, unless it was made in another process before
    a fork (the parent may still use it, or hand it out)."""
    if os.getpid() == pid:
        spares.give(mapped)


class _Exported:
    """The owner of a recycled array's memory: numpy's views keep it alive, and its death
    gives the map back to `spares`."""

    def __init__(self, mapped: mmap.mmap, nbytes: int) -> None:
        self.keep = np.frombuffer(mapped, np.uint8, count=nbytes)
        self.__array_interface__ = {
            "shape": (nbytes,),
            "typestr": "|u1",
            "data": (self.keep.ctypes.data, False),
            "version": 3,
        }


def recycled_empty(shape: tuple[int, ...], dtype: object) -> np.ndarray:
    """`aligned_empty`, on the memory of an earlier array of the same size that died where there
    is one (its old contents: the caller writes every element). Below `TUNING.mapped_bytes` a plain
    `aligned_empty`. Writing a fresh 268 MB output costs 0.07 s of page faults here and
    unmapping it 0.03 s, half of integrating 10 x 256^3 float32 steps."""
    dt = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
    if nbytes < TUNING.mapped_bytes:
        return aligned_empty(shape, dt)
    size = -(-nbytes // mmap.PAGESIZE) * mmap.PAGESIZE
    mapped = spares.take(size)
    if mapped is None:
        try:
            mapped = mmap.mmap(-1, size)
        except OSError as exc:
            raise MemoryError(f"cannot allocate {nbytes} bytes: {exc}") from None
    owner = _Exported(mapped, nbytes)
    # Not at exit: nothing is made again, and 3.12 cannot start the expiry timer's thread then
    weakref.finalize(owner, _give_back, mapped, os.getpid()).atexit = False
    return np.asarray(owner).view(dt).reshape(shape)


def is_aligned(a: np.ndarray, align: int = ALIGN) -> bool:
    return a.ctypes.data % align == 0


def _libc_madvise():
    """libc's madvise through ctypes, which lets go of the GIL for the call (CPython's
    `mmap.madvise` holds it: a 1 MB MADV_POPULATE_WRITE takes about 10 ms here, and every
    other thread waited for each); None where there is none."""
    try:
        fn = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True).madvise
    except (OSError, AttributeError):
        return None
    fn.argtypes = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int)
    fn.restype = ctypes.c_int
    return fn


_MADVISE = _libc_madvise()


def _advise_rows(a: np.ndarray, advice: int, inward: bool, between=None) -> bool:
    """madvise(`advice`) over the pages under each row of `a` (a view of an `aligned_empty`
    memory map, rows of it contiguous): the whole pages inside a row where `inward`, else every
    page a row touches; `between()` is called before each row, and a false answer stops there.
    False where `a` is not mapped, the kernel refuses (an older kernel, no madvise, out of
    memory) or `between` stopped it."""
    owner = a
    while isinstance(owner, np.ndarray):
        owner = owner.base
    if isinstance(owner, memoryview):  # np.frombuffer's view of the map
        owner = owner.obj
    if not isinstance(owner, mmap.mmap) or a.ndim < 1:
        return False
    start = np.frombuffer(owner, np.uint8).ctypes.data
    rows = a.reshape(a.shape[0], -1) if a.ndim > 1 else a.reshape(1, -1)
    page = mmap.PAGESIZE
    try:
        for row in rows:
            if between is not None and not between():
                return False
            lo = row.ctypes.data - start
            hi = lo + row.nbytes
            first = -(-lo // page) * page if inward else lo - lo % page
            end = hi // page * page if inward else hi  # madvise rounds a length up
            if end <= first:
                continue
            if _MADVISE is None:
                owner.madvise(advice, first, end - first)
            elif _MADVISE(start + first, end - first, advice) != 0:
                return False
    except (OSError, ValueError, AttributeError):
        return False
    return True


def discard(a: np.ndarray) -> bool:
    """Hand the whole pages under `a` (as for `prefault`) back to the system: its contents are
    lost (they read as zeros), its memory is no longer resident until written again. False
    where the array is not mapped or the kernel cannot."""
    return _advise_rows(a, MADV_FREE_SHARED, inward=True)


def prefault(a: np.ndarray, between=None) -> bool:
    """Fault in the pages under `a` (a view of an `aligned_empty` memory map, rows of it
    contiguous) without changing what they hold, so a later first write finds them mapped:
    a fresh 512 MB takes 0.2-0.3 s to fault here, and up to 2 s on a virtual machine whose
    host returns freed memory. A row at a time, `between()` called before each (background
    warms yield to frames there: `chronocl.core.foreground`; false: stop). False where the
    array is not mapped, the kernel cannot, or `between` stopped it."""
    return _advise_rows(a, MADV_POPULATE_WRITE, inward=False, between=between)
