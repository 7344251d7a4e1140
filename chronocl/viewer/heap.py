"""Keeps a long-running viewer's memory near what its clients use (`HeapKeeper`)."""

from __future__ import annotations

import gc
import time

from chronocl.core.budget import malloc_trim, resident_bytes
from chronocl.core.tuning import TUNING


class HeapKeeper:
    """Keeps a long-running viewer's memory near what its clients use.

    Under 20 clients scrubbing and editing, a server leaves garbage that only a full
    collection frees (dask's task graphs of reads hold reference cycles; Python runs full
    collections rarely once many objects are long-lived), and glibc keeps what each render
    thread's arena freed. `check()` (once a second, off the event loop) collects and hands
    freed memory back (malloc_trim) once the process has grown by `allowance` over the least
    it used since the last clean-up; a clean-up stops every thread for tens of ms, so a quiet
    viewer seldom needs one. While the server runs, the objects it started with (modules,
    data sets) are frozen out of the collections (`gc.freeze`), which makes each collection
    several times cheaper under that load.
    """

    def __init__(self, allowance: int | None = None) -> None:  # None: TUNING.heap_allowance
        self.allowance = TUNING.heap_allowance if allowance is None else allowance
        self.floor = resident_bytes()
        self.cleanups = 0
        self.collect_s = 0.0  # collecting (every Python thread stopped), not waiting for it
        self.trim_s = 0.0  # in malloc_trim (threads go on)

    def freeze(self) -> None:
        gc.collect()
        gc.freeze()

    def unfreeze(self) -> None:
        gc.unfreeze()

    def check(self) -> None:
        now = resident_bytes()
        if now is None or self.floor is None:
            return
        if now <= self.floor + self.allowance:
            self.floor = min(self.floor, now)
            return
        started: list[float] = []

        def timer(phase: str, info: dict) -> None:
            if phase == "start":
                started.append(time.perf_counter())
            elif started:
                self.collect_s += time.perf_counter() - started.pop()

        gc.callbacks.append(timer)
        try:
            gc.collect()
        finally:
            gc.callbacks.remove(timer)
        t1 = time.perf_counter()
        if malloc_trim is not None:
            malloc_trim(0)
        self.floor = resident_bytes()
        self.cleanups += 1
        self.trim_s += time.perf_counter() - t1
