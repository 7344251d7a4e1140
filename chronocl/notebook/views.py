"""The views of a widget on the notebook's pages, each proving that it is alive.

A view (widget.js) says "shown" when it renders and "gone" when anywidget calls its cleanup.
A page reloaded, a tab closed or a renderer crashed never calls the cleanup, so each view also
sends "alive" every `HEARTBEAT_S` while it exists, whether its page is visible or not, with
whether it is hidden (`document.visibilityState`), and a best-effort "gone" on `pagehide`. A
view not heard from for `LOST_AFTER_S` (`LOST_HIDDEN_AFTER_S` where its page said it was
hidden) is counted gone; one heard from again (a page back from the back-forward cache, or a
view counted gone while its kernel was busy) is counted shown again.

The silence is measured on `CellTime`'s clock, which stands still while the kernel runs a cell:
ipykernel handles comm messages between cells, so a view's heartbeats wait in the kernel's
queue while a long cell runs, and that silence is the kernel's, not the view's.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

# How often a view says it is alive (the front end reads it from the widget's `_heartbeat_s`).
HEARTBEAT_S = 5.0
# A visible view silent this long is gone: four heartbeats missed, so a busy browser (a long
# task on its main thread) or a slow kernel reply loses no view; a reloaded page's widget is
# suspended about this long (plus SUSPEND_AFTER_S) after the reload.
LOST_AFTER_S = 20.0
# A hidden page's timers are throttled: Chrome runs them once a minute after five minutes
# hidden ("intensive wake up throttling", Chrome 88+), Firefox and Safari at least once a second.
# Three minutes outlasts a throttled minute with room to spare, so a widget in a background
# tab is not suspended and resumed each minute.
LOST_HIDDEN_AFTER_S = 180.0


class CellTime:
    """A clock (seconds, monotonic) that stands still while the kernel runs a cell: `watch`
    hooks it to IPython's pre_run_cell and post_run_cell events. Outside IPython (marimo, a
    script) it is the plain clock."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._in_cells = 0.0  # seconds spent in cells that ended
        self._started: float | None = None  # when the outermost cell running now started
        # The cells running now, outermost first (a cell may run cells:
        # `get_ipython().run_cell`, `%run notebook.ipynb`), each by the token its start gave.
        self._running: list[object] = []
        self._watched: set[int] = set()

    def start(self, cell: object = None) -> None:
        """A cell starts; `cell` names it for its `end` (IPython's ExecutionInfo)."""
        with self._lock:
            self._running.append(cell if cell is not None else object())
            if len(self._running) == 1:
                self._started = self._clock()

    def end(self, cell: object = None) -> None:
        """The cell `cell` ended (None: the innermost). An end no start announced is ignored:
        IPython ends an empty cell, or one refused before it ran, without starting it."""
        with self._lock:
            if cell is None:
                if not self._running:
                    return
                self._running.pop()
            elif any(c is cell for c in self._running):
                while self._running.pop() is not cell:
                    pass  # (a cell whose end never came ends with the one that ran it)
            else:
                return
            if not self._running and self._started is not None:
                self._in_cells += self._clock() - self._started
                self._started = None

    def __call__(self) -> float:
        with self._lock:
            now = self._clock()
            running = 0.0 if self._started is None else now - self._started
            return now - self._in_cells - running

    def watch(self) -> None:
        """Stand still during the cells of this process's IPython shell, if it has one."""
        try:
            from IPython import get_ipython
        except ImportError:
            return
        shell = get_ipython()
        if shell is None:
            return
        with self._lock:
            if id(shell) in self._watched:
                return
            self._watched.add(id(shell))
        # pre_run_cell gives the cell's ExecutionInfo and post_run_cell its result, whose
        # `info` is the same object: an empty cell (which IPython ends without starting it,
        # also inside a running cell) does not end the cell around it.
        shell.events.register("pre_run_cell", self.start)
        shell.events.register("post_run_cell", self._ran)

    def _ran(self, result: object) -> None:
        """post_run_cell: its result's `info` (None where the cell failed inside IPython itself:
        the innermost cell ends)."""
        self.end(getattr(result, "info", None))


CELL_TIME = CellTime()


@dataclass
class _View:
    heard: float  # when it was last heard from (the views' clock)
    hidden: bool  # its page said it was hidden


class Views:
    """The views of one widget shown now, by the id each gave itself (not thread-safe: the
    widget holds its lock)."""

    def __init__(self, clock: Callable[[], float] = CELL_TIME) -> None:
        self.clock = clock
        self._views: dict[str, _View] = {}

    def heard(self, view: str, hidden: bool = False) -> bool:
        """View `view` said it is shown or alive; True where it was not counted shown."""
        new = view not in self._views
        self._views[view] = _View(self.clock(), bool(hidden))
        return new

    def gone(self, view: str) -> bool:
        """View `view` said it went; True where it was counted shown."""
        return self._views.pop(view, None) is not None

    def expire(self) -> list[str]:
        """The views silent for longer than their bound, counted gone now."""
        now = self.clock()
        lost = [
            view
            for view, seen in self._views.items()
            if now - seen.heard > (LOST_HIDDEN_AFTER_S if seen.hidden else LOST_AFTER_S)
        ]
        for view in lost:
            del self._views[view]
        return lost

    def __len__(self) -> int:
        return len(self._views)
