"""Work a client's viewer answers beside its frames, on a thread of its own.

A client's render thread (`chronocl.viewer.worker`) makes frames; what the page asks for beside
them and needs no frame (a window's histogram, a fitted range) runs here instead, so it never
delays a frame: it waits for the machine, not for the render thread, and the render thread
never waits for it. Jobs run one at a time in the order they came; a job given under a key
that is already waiting replaces the waiting one (a newer window's histogram supersedes an
older one not yet counted), and a running job can ask `waiting(key)` to give up early.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable

from chronocl.viewer.errors import error_text
from chronocl.viewer.protocol import LIMITS


class SideWork:
    """One thread running one client's side jobs (started with the first). A job answers the
    client itself, errors included; one that escapes is logged in one line."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._jobs: OrderedDict[Hashable, Callable[[], None]] = OrderedDict()
        self._closed = False
        self._thread: threading.Thread | None = None
        self._running = False

    def submit(self, key: Hashable, job: Callable[[], None]) -> bool:
        """Run `job` after those waiting, in place of a waiting job of the same key; False
        (nothing queued) when closed or `LIMITS.side_jobs` jobs wait."""
        with self._cond:
            if self._closed or (key not in self._jobs and len(self._jobs) >= LIMITS.side_jobs):
                return False
            self._jobs.pop(key, None)
            self._jobs[key] = job
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="chronocl-side", daemon=True)
                self._thread.start()
            self._cond.notify()
            return True

    def waiting(self, key: Hashable) -> bool:
        """Whether a job of `key` waits (a running one of that key is then out of date), or
        the work is closed."""
        with self._cond:
            return self._closed or key in self._jobs

    def idle(self) -> bool:
        """Nothing waits and nothing runs."""
        with self._cond:
            return not self._jobs and not self._running

    def close(self) -> None:
        """Run nothing more (a running job finishes; `waiting` then says so)."""
        with self._cond:
            self._closed = True
            self._jobs.clear()
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                self._running = False
                while not self._closed and not self._jobs:
                    self._cond.wait()
                if self._closed:
                    return
                key, job = self._jobs.popitem(last=False)
                self._running = True
            try:
                job()
            except Exception as exc:  # the thread keeps serving
                error_text(exc, f"in a client's side work ({key})")
