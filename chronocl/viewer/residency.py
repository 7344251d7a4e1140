"""Which steps are in memory for each view's data set, for the page's timeline: resident,
being fetched, or not loaded. The level-0 managers are the server's, shared by every client
(`view_sessions.SharedSteps`): a step another tab holds shows as resident, as it is.

While a socket is open, `report_steps` asks the full-resolution (level 0) window manager of
each view's session for its `state()` every `POLL_S` seconds and, when it changed, sends

    {"type": "steps", "views": [{"resident": [steps], "loading": [steps]} or null, ...]}

(null: the view has no session yet), for the views of the last frame: the managers the render
thread published after it (`Views.shown_managers`). Level 0 is what a refine needs: a coarse
frame asks it for the window in the background (`LevelSession.read_ahead`), and a scrub at full
resolution reads ahead in it (`chronocl.data.window`). The poll runs on the event loop and takes
each manager's lock for a moment, never the render thread's: steps being fetched show while a
frame is drawn.
"""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Awaitable, Callable

POLL_S = 0.2


def residency(views) -> list[dict | None]:
    """Per view shown in the last frame of `views` (`chronocl.viewer.view_sessions.Views`):
    its level-0 manager's resident and loading steps, or None (no session). It reads what the
    render thread published after that frame (`Views.shown_managers`), never the slots and
    sessions the render thread may be replacing meanwhile."""
    out: list[dict | None] = []
    for manager in views.shown_managers:
        if manager is None:
            out.append(None)
            continue
        state = manager.state()
        out.append({"resident": state["resident"], "loading": state["loading"]})
    return out


async def report_steps(
    views, deliver: Callable[[str], Awaitable[None]], gone: threading.Event
) -> None:
    """Send a `steps` message whenever the views' residency changes, until `gone`."""
    last = None
    while not gone.is_set():
        now = residency(views)
        if now != last and any(v is not None for v in now):
            await deliver(json.dumps({"type": "steps", "views": now}))
            last = now
        await asyncio.sleep(POLL_S)
