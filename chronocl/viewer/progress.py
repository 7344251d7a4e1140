"""How far a refine to full resolution got, told to the client as it goes.

The render worker refines a coarse frame view by view; under it the session reads the
window's steps and integrates them slab by slab, calling `chronocl.core.interrupt.checkpoint`
between pieces. `RefineProgress` turns those checkpoints into `progress` messages
({"what": "refine", "stage", "done", "total", "view", "views"}), one per change, so the page
can say "integrating 3/8 slabs" and offer to cancel.
"""

from __future__ import annotations

from collections.abc import Callable


class RefineProgress:
    """Sends a `progress` message through `reply` at each new checkpoint of a refine of
    `views` views (`view`: the one refining now)."""

    def __init__(self, reply: Callable[[dict], bool], views: int) -> None:
        self.reply = reply
        self.views = views
        self.view = 0
        self._last: tuple | None = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        key = (self.view, stage, done, total)
        if key == self._last:
            return
        self._last = key
        self.reply(refine_progress(stage, done, total, self.view, self.views))


def refine_progress(stage: str, done: int, total: int, view: int, views: int) -> dict:
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
