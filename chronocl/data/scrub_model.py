"""How far ahead the window manager reads: the scrub's speed times the time a step takes to read.

A step `d` steps ahead of the window's edge is wanted `d / v` seconds from now when the user
scrubs at `v` steps a second; a read started now lands after `r`, the time a step takes to read
(measured, a running average). So every step within `v * r` of the edge must be under way
already, or the scrub catches up with the reads: `ScrubModel.ahead` asks for that many steps,
with a margin (`TUNING.scrub_margin`), at least one. A slow scrub (or a first request, speed
unknown) reads one step ahead; a fast one over a slow store reads many.

The speed is that of the window's start over the last `TUNING.scrub_history_n` requests (within
`TUNING.scrub_history_s` seconds, in one direction): few, so that it follows a scrub speeding up at
once (a first window that took long to arrive does not hold it down). A change of direction starts a
new history, and a scrub that has stopped (its last request older than `TUNING.scrub_history_s`) has
no speed.
Thread-safe: requests come from the client's thread, read times from the manager's readers.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable

from chronocl.core.tuning import TUNING, running


class ScrubModel:
    """The scrub's speed and direction from the requests, and a step's read time from the reads.

    `clock` (seconds, monotonic) times the requests; tests give a clock of their own to scrub
    at a chosen speed. Read times are measured by the readers with `time.perf_counter`.
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.read_s: float | None = None  # running average of one step's read, seconds
        self.direction = 0
        self._history: deque[tuple[float, int]] = deque(maxlen=TUNING.scrub_history_n)
        self._lock = threading.Lock()

    def record_request(self, start: int, direction: int) -> None:
        """A request whose window starts at `start`, moving in `direction` (0: unknown)."""
        now = self.clock()
        with self._lock:
            if direction and direction != self.direction:
                self._history.clear()  # a turn: the old direction's speed says nothing
                self.direction = direction
            self._history.append((now, int(start)))

    def record_read(self, seconds: float) -> None:
        """A whole step was read in `seconds`."""
        with self._lock:
            self.read_s = running(self.read_s, float(seconds), TUNING.scrub_read_weight)

    def velocity(self) -> float:
        """Steps a second the window's start moved over the recent requests (0: unknown)."""
        now = self.clock()
        with self._lock:
            recent = [(t, s) for t, s in self._history if now - t <= TUNING.scrub_history_s]
        if len(recent) < 2:
            return 0.0
        dt = recent[-1][0] - recent[0][0]
        ds = abs(recent[-1][1] - recent[0][1])
        return ds / max(dt, 1e-3)

    def ahead(self, stride: int = 1) -> int:
        """Steps (of `stride`) to have under way beyond the window's edge: at least one."""
        v, r = self.velocity(), self.read_s
        if not v or r is None:
            return 1
        return max(1, math.ceil(TUNING.scrub_margin * v * r / max(1, stride)))
