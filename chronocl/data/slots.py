"""Step slots: one block of memory that holds a window manager's resident steps side by side.

The block is laid out as the kernels read bricks, (Z, S, Y, X) for S slots: the rows of the
slots interleave, so the rows of any window of resident steps lie within S * Y * X elements
of each other and a window integrates where it lies (`chronocl.data.bricks.SlotBrick`, one
device buffer per slab) instead of being stacked. A slide reads one step into one slot. The
block is reserved, not written: its pages fill only as steps are read into it.

A slot is handed out as a (Z, Y, X) view and goes back to the free list only once nothing
holds that view (a weak reference's callback): a step evicted while a session still reads it
is never overwritten. The lowest free slot is taken first, which keeps the steps close
together. With every slot taken a step gets an array of its own: correct, only not in place.

The next free slots (as many as the caller asks: the window manager asks for one window's length,
what a jump of a whole window takes, once its reads have paused) are faulted in ahead on a
background thread at a low priority (`chronocl.core.memory.prefault`), so the step read into one
does not also pay for its fresh pages (0.2-0.3 s per 512 MB here, up to 2 s on a virtual machine
whose host took freed memory back): the slots a slide, a scrub's stop or a read ahead take next
are warm. Only those, not the whole budget, so a large budget is not all resident at once.
"""

from __future__ import annotations

import gc
import heapq
import os
import queue
import threading
import time
import weakref
from collections.abc import Callable
from concurrent.futures import Future

import numpy as np

from chronocl.core import foreground
from chronocl.core.budget import resident_bytes
from chronocl.core.memory import aligned_empty, discard, prefault
from chronocl.core.tuning import TUNING


class StepSlots:
    """`count` slots for steps of `shape` (Z, Y, X) and `dtype`."""

    def __init__(self, shape: tuple[int, int, int], dtype: np.dtype, count: int) -> None:
        self.shape, self.dtype, self.count = tuple(shape), np.dtype(dtype), max(0, int(count))
        self._block: np.ndarray | None = None
        self._free = list(range(self.count))  # a heap: the lowest slot first
        # Re-entrant: a view can be collected (and its slot given back) inside `take`.
        self._lock = threading.RLock()
        self.own_arrays = 0  # steps that found no free slot
        self._warm: set[int] = set()  # slots handed out or faulted in once
        self._collected = -TUNING.collect_every_s  # when `take` last ran the garbage collector

    def take(self) -> np.ndarray:
        """A (Z, Y, X) array for one step: a free slot, else an array of its own (the next
        free slots are warmed by `warm`, when the caller says)."""
        with self._lock:
            now = time.monotonic()
            if not self._free and now - self._collected > TUNING.collect_every_s:
                # Views of evicted steps caught in reference cycles give their slots back only
                # when collected: collect before giving a step an array of its own, which
                # would make every window holding it stack (5 GB copied per 512^3 window).
                # A full collection takes 30-130 ms in a viewer: at most once in a while.
                self._collected = now
                gc.collect()
            if not self._free:
                self.own_arrays += 1
                return aligned_empty(self.shape, self.dtype)
            if self._block is None:
                nz, ny, nx = self.shape
                self._block = aligned_empty((nz, self.count, ny, nx), self.dtype)
            i = heapq.heappop(self._free)
            view = self._block[:, i]
            self._warm.add(i)
        weakref.finalize(view, self._give_back, i)
        return view

    def warm(self, count: int, ready: Callable[[], bool | None] | None = None) -> None:
        """Fault in the next `count` free slots (those taken next) that were never written or
        warmed, on the background thread; with `ready`, each once it returns true (polled:
        the caller's own work first), none left once it returns None."""
        with self._lock:
            if self._block is None:
                return
            spares = heapq.nsmallest(max(0, count), self._free)
            cold = [j for j in spares if j not in self._warm]
            self._warm.update(spares)
        if cold:
            _warmer().submit(_prefault_when, self, cold, ready)

    @property
    def free(self) -> int:
        """Slots free now."""
        with self._lock:
            return len(self._free)

    @property
    def slot_bytes(self) -> int:
        return int(np.prod(self.shape)) * self.dtype.itemsize

    @property
    def resident_bytes(self) -> int:
        """Bytes of the slots handed out or warmed (what the block may hold resident)."""
        with self._lock:
            return len(self._warm) * self.slot_bytes

    def next_is_warm(self) -> bool:
        """Whether the slot `take` hands out next was written or warmed before."""
        with self._lock:
            return bool(self._free) and self._free[0] in self._warm

    def release(self, nbytes: int, cold: bool = True) -> int:
        """Hand back the pages of free slots, the last to be taken first, until `nbytes` are
        (a process limit wants them, `chronocl.core.process_memory`); the bytes released.
        With `cold`, slots never written nor warmed go too where that is not enough: reading a
        page of the block's shared map that was never written makes it resident (a buffer
        spanning the slab of rows a window lies in spans the free slots' rows between), which
        only the resident memory's drop tells."""
        released = 0
        with self._lock:
            if self._block is None:
                return 0
            for j in sorted((j for j in self._free if j in self._warm), reverse=True):
                if released >= nbytes:
                    return released
                self._warm.discard(j)
                if discard(self._block[:, j]):
                    released += self.slot_bytes
            if not cold:
                return released
            before = resident_bytes()
            cold = sorted(j for j in self._free if j not in self._warm)
            for j0, j1 in _runs(cold):
                discard(self._block[:, j0:j1])
            after = resident_bytes()
        if before is not None and after is not None:
            released += max(0, before - after)
        return released

    def _give_back(self, i: int) -> None:
        with self._lock:
            heapq.heappush(self._free, i)

    def _warming(self, j: int) -> bool:
        """Between rows of slot `j`'s warm: wait while a frame is made; whether to go on (not
        when frames went on for long, nor once a process limit released the slot)."""
        if not foreground.yield_to_frames():
            return False
        with self._lock:
            return self._block is not None and j in self._warm

    def _prefault(self, j: int) -> None:
        """Fault slot `j` in, unless its pages were released since it was to be warmed."""
        with self._lock:
            if self._block is None or j not in self._warm:
                return
            slot = self._block[:, j]
        prefault(slot, between=lambda: self._warming(j))
        with self._lock:  # released meanwhile (a process limit): its pages go again
            if j not in self._warm and j in self._free:
                discard(slot)


def _runs(indices: list[int]) -> list[tuple[int, int]]:
    """Sorted `indices` as runs [j0, j1) of consecutive ones."""
    runs: list[tuple[int, int]] = []
    for j in indices:
        if runs and runs[-1][1] == j:
            runs[-1] = (runs[-1][0], j + 1)
        else:
            runs.append((j, j + 1))
    return runs


def _prefault_when(slots: StepSlots, which: list[int], ready) -> None:
    """Fault in slots `which` in turn, each once `ready` is true (None: none left). One not
    ready goes behind the other warms: the one thread waiting on a manager whose reads go on (a
    view playing on and on) held up every other manager's warm, and the memory of closed ones."""
    for k, j in enumerate(which):
        state = True if ready is None else ready()
        if state is None:
            return
        if not state:
            time.sleep(TUNING.warm_poll_s)
            _warmer().submit(_prefault_when, slots, which[k:], ready)
            return
        slots._prefault(j)


class _Warmer:
    """The process's one pre-faulting thread, running what is submitted in turn. A daemon, not
    a ThreadPoolExecutor's (joined at exit): a warm waiting for the reads of a manager nobody
    closed (a `Session` used without `with`) to pause held the program's end that long, then
    faulted in its slots for nothing."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        threading.Thread(target=self._run, name="chronocl-prefault", daemon=True).start()

    def submit(self, fn: Callable, *args: object) -> Future:
        future: Future = Future()
        self._queue.put((future, fn, args))
        return future

    def _run(self) -> None:
        _low()
        while True:
            future, fn, args = self._queue.get()
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(fn(*args))
                except BaseException as exc:  # the caller's to see, if it looks
                    future.set_exception(exc)
            del future, fn, args  # idle, it holds no closed manager's slots


_warmers: list[_Warmer] = []
_warmers_lock = threading.Lock()


def _forget_warmer() -> None:
    """In a forked child: no warming thread came along; it makes its own when it needs one."""
    global _warmers_lock
    _warmers.clear()
    _warmers_lock = threading.Lock()


os.register_at_fork(after_in_child=_forget_warmer)


def _warmer() -> _Warmer:
    """The process's one pre-faulting thread (made when first needed)."""
    with _warmers_lock:
        if not _warmers:
            _warmers.append(_Warmer())
        return _warmers[0]


def _low() -> None:
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), TUNING.warm_nice)
    except (AttributeError, OSError):  # not Linux, or not allowed
        pass
