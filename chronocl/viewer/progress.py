"""How far a frame's work got, told to the client as it goes.

The render worker makes a frame answering input, and refines a coarse frame view by view;
under both the session reads the window's steps, integrates them slab by slab and gathers a
recolouring's winners in pieces, calling `chronocl.core.interrupt.checkpoint` between pieces.
`RefineProgress` turns those checkpoints into `progress` messages ({"what": "refine" or
"frame", "stage", "done", "total", "view", "views"}), one per change, so the page can say
"integrating 3/8 slabs" (a refine, in the status line, with an offer to cancel) or "reading
steps 3/10" (a frame answering input, in the busy box). `reporting` runs a frame's work
under it without making that work one that newer input gives up.

A frame answering input says nothing for its first `TUNING.frame_progress_after_s`: the page
shows its busy box only after 400 ms, and a notebook widget's messages each cost the kernel,
the Jupyter server and JupyterLab's page CPU that the frame itself needs (a 256^3 slide made
about ten reports beside its two frames). The newest report of that time is held, and sent
when it ends if the frame is still being made (`finish`, just before the frame is sent, says
it no longer is): a stage that started early and runs for seconds is still named in the busy
box.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager

from chronocl.core.interrupt import reported
from chronocl.core.tuning import TUNING


class RefineProgress:
    """Sends a `progress` message through `reply` at each new checkpoint of a refine of
    `views` views (`view`: the one refining now; None where the work does not go view by
    view), or with `what` "frame" of the frame answering request `rid`."""

    def __init__(
        self,
        reply: Callable[[dict], bool],
        views: int,
        what: str = "refine",
        rid: int | None = None,
    ) -> None:
        self.reply = reply
        self.views = views
        self.what = what
        self.rid = rid
        self.view: int | None = 0 if what == "refine" else None
        self._last: tuple | None = None
        quiet_s = TUNING.frame_progress_after_s if what == "frame" else 0.0
        self._quiet_until = time.monotonic() + quiet_s
        # The quiet time's newest report and the timer that sends it when the time ends; the
        # lock keeps reports in order between the work's thread and the timer's.
        self._lock = threading.Lock()
        self._held: tuple | None = None
        self._timer: threading.Timer | None = None
        self._finished = False

    def __call__(self, stage: str, done: int, total: int) -> None:
        key = (self.view, stage, done, total)
        with self._lock:
            newest = self._held[0] if self._held else self._last
            if self._finished or key == newest:
                return
            wait = self._quiet_until - time.monotonic()
            if wait > 0:
                self._held = (key, stage, done, total)
                if self._timer is None:
                    self._timer = threading.Timer(wait, self._send_held)
                    self._timer.daemon = True
                    self._timer.start()
                return
            self._held = None
            self._send(key, stage, done, total)

    def _send(self, key: tuple, stage: str, done: int, total: int) -> None:
        self._last = key
        msg = refine_progress(stage, done, total, self.view, self.views)
        self.reply({**msg, "what": self.what, "id": self.rid})

    def _send_held(self) -> None:
        with self._lock:
            held, self._held = self._held, None
            if held is not None and not self._finished:
                self._send(*held)

    def finish(self) -> None:
        """The frame is about to be sent (or failed): nothing held goes after it."""
        with self._lock:
            self._finished, self._held = True, None
            if self._timer is not None:
                self._timer.cancel()


def refine_progress(stage: str, done: int, total: int, view: int | None, views: int) -> dict:
    """The `progress` message of a refine (stage "cancelled": the answer to `cancel`)."""
    return {
        "type": "progress",
        "id": None,
        "what": "refine",
        "stage": stage,
        "done": done,
        "total": total,
        "view": view,
        "views": views,
    }


def reporting(progress: RefineProgress) -> AbstractContextManager[None]:
    """The work inside tells `progress` of its checkpoints (a frame answering input: the reads
    of its steps, its integration, its recolouring's gather). Unlike a refine's it is never
    given up, nor split into more pieces than it would be anyway (`interrupt.reported`)."""
    return reported(progress)
