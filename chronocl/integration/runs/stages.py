"""Where an out-of-core run's time goes: wall and CPU seconds per stage, always recorded.

The local executor times each call of its stages (read and decompress a brick, integrate it,
compress and write the slab, finish the run) with `StageTimes.stage`: two clocks per call, a
few per slab, nothing to notice. Wall seconds are those the stage's calls took on whichever
thread ran them (stages overlap, so they add up to more than the run); CPU seconds are the
calling thread's (`time.thread_time`), which leaves out what zarr's and PoCL's own threads
did for the call. `last()` gives the latest run's times, for benches (bench/out_of_core.py
--breakdown) and logs.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

STAGES = ("read", "integrate", "write", "finish")  # read: and decompress; write: and compress


class StageTimes:
    """Per-stage wall and calling-thread CPU seconds, and calls, of one run; thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.wall = dict.fromkeys(STAGES, 0.0)
        self.cpu = dict.fromkeys(STAGES, 0.0)
        self.calls = dict.fromkeys(STAGES, 0)
        self.blocked = 0.0  # the integrating thread waiting for a write to free its buffer
        self.started = time.perf_counter()
        self.seconds = 0.0  # the run's wall time, once ended

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        w0, c0 = time.perf_counter(), time.thread_time()
        try:
            yield
        finally:
            w, c = time.perf_counter() - w0, time.thread_time() - c0
            with self._lock:
                self.wall[name] += w
                self.cpu[name] += c
                self.calls[name] += 1

    def end(self) -> None:
        self.seconds = time.perf_counter() - self.started

    def as_dict(self) -> dict:
        """{"seconds": the run's wall, stage: {"wall_s", "thread_cpu_s", "calls"}, ...}."""
        return {
            "seconds": self.seconds,
            "blocked_on_write_s": self.blocked,
            **{
                s: {"wall_s": self.wall[s], "thread_cpu_s": self.cpu[s], "calls": self.calls[s]}
                for s in STAGES
            },
        }


_last: list[StageTimes] = []


def begin() -> StageTimes:
    """A new run's times, which `last()` gives from now on."""
    times = StageTimes()
    _last[:] = [times]
    return times


def current() -> StageTimes:
    """The times of the run under way (or a throwaway record where none began)."""
    return _last[0] if _last else begin()


def last() -> dict | None:
    """The latest run's times (`StageTimes.as_dict`), or None before any run."""
    return _last[0].as_dict() if _last else None
