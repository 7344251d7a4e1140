"""Foreground work and the background work that yields to it.

A viewer's frame (integrate, upload, draw, encode) is foreground: `working()` marks it. Work
nobody waits for, such as warming free memory for steps to come (`chronocl.data.slots`), runs
in small pieces and calls `yield_to_frames()` between them, which waits while any frame is
being made. Run beside a frame on the same two cores, a warm slowed the frame's own passes
several times over (issue 46: an occupancy pass of 48 ms took 4.6-5.7 s while each 1 MB
madvise held the GIL, and slides during the warm took 1.7-2.7 s instead of 0.9 s once it did
not).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from chronocl.core.tuning import TUNING

_lock = threading.Lock()
_frames = 0
_idle = threading.Event()
_idle.set()


@contextmanager
def working() -> Iterator[None]:
    """Mark a frame being made (nested and concurrent frames count)."""
    global _frames
    with _lock:
        _frames += 1
        _idle.clear()
    try:
        yield
    finally:
        with _lock:
            _frames -= 1
            if _frames == 0:
                _idle.set()


def busy() -> bool:
    """Whether a frame is being made now."""
    return not _idle.is_set()


def yield_to_frames(timeout: float | None = None) -> bool:
    """Wait while a frame is being made (at most `timeout` s; None: `TUNING.max_yield_s`, so
    that frames made back to back, a view playing, do not hold the work back for ever); whether
    none is now."""
    return _idle.wait(TUNING.max_yield_s if timeout is None else timeout)
