"""What the widgets of one kernel share, as the clients of one `chronocl view` server do
(chronocl/viewer/app.py):

- one memory limit for the kernel's process (`chronocl.core.process_memory.ProcessLimit`): every
  widget's resident steps and frames within it, steps nobody shows giving way first. The first
  widget makes it (its `memory`, else half the memory free, as `chronocl view`'s default) and
  it is held while any widget is open; a later `memory` replaces its total (the newest given is
  the kernel's; the windows of widgets made before keep the budget they were made with);
- one set of resident steps per series (`chronocl.viewer.view_sessions.SharedSteps`): widgets
  showing the same store (its path or URL, with the same storage options) or the same
  `TimeSeries` read no step twice and hold none twice. The steps go when the last widget
  showing that series closes.

A suspended widget (no view has shown it for a while: chronocl/notebook/widget.py) leaves as a
closed one does, and joins again when it resumes.

Two arrays are two series, even with equal values: only the same store or the same TimeSeries
object is shared.
"""

from __future__ import annotations

import threading
from contextlib import ExitStack
from dataclasses import dataclass, field

from chronocl.core import process_memory
from chronocl.core.budget import interactive_memory, parse_memory
from chronocl.core.errors import ChronoclError
from chronocl.core.process_memory import ProcessLimit
from chronocl.data.series import TimeSeries
from chronocl.viewer.view_sessions import SharedSteps


@dataclass
class Shown:
    """A series the kernel's widgets show: its shared steps and the widgets (by id)."""

    series: TimeSeries
    steps: SharedSteps
    store: tuple | None = None  # (where, storage options) of a store `show` opened
    widgets: set[int] = field(default_factory=set)


class Kernel:
    """The shares of this process's widgets (one `KERNEL`)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._shown: dict[int, Shown] = {}  # by id(series)
        self.limit: ProcessLimit | None = None
        self.memory: str | int | None = None  # as given to show: the workers' budget
        self._limited: ExitStack | None = None

    def find_store(self, store: tuple) -> TimeSeries | None:
        """The series of a store (where, options) an open widget shows, if any, and if the
        store did not change since (rewritten, a re-run cell shows it opened afresh: the old
        series failed every frame with 'open it again')."""
        with self._lock:
            found = [shown.series for shown in self._shown.values() if shown.store == store]
        for series in found:
            try:
                series.check_unchanged()
            except ChronoclError:
                continue
            return series
        return None

    def join(
        self,
        widget: int,
        series: TimeSeries,
        store: tuple | None = None,
        memory: str | int | None = None,
        fallback: str | int | None = None,
    ) -> tuple[SharedSteps, str | int | None]:
        """Widget `widget` shows `series`: its shared steps, and the memory budget its worker
        is to keep (the kernel's, set or replaced by `memory` where given). `fallback`: the
        limit to make where the kernel has none and no `memory` is given (a suspended widget
        resumed after every other widget went: the budget it had), never replacing one."""
        total = None if memory is None else parse_memory(memory)  # a bad one: nothing changed
        with self._lock:
            if self.limit is None:  # the first widget: the default limit, as `chronocl view`'s
                if total is None and fallback is not None:
                    memory, total = fallback, parse_memory(fallback)
                if total is None:
                    total = interactive_memory()
                self.limit = ProcessLimit(total)
                self._limited = ExitStack()
                self._limited.enter_context(process_memory.limited(self.limit))
                self.memory = total if memory is None else memory
            elif total is not None:
                self.limit.total = total
                self.memory = memory
            shown = self._shown.get(id(series))
            if shown is None:
                shown = self._shown[id(series)] = Shown(series, SharedSteps(), store)
            shown.widgets.add(widget)
            return shown.steps, self.memory

    def leave(self, widget: int, series: TimeSeries) -> None:
        """Widget `widget` closed (its worker's views released): the series' steps go with the
        last widget showing it, the kernel's memory limit with the last widget."""
        with self._lock:
            shown = self._shown.get(id(series))
            if shown is not None:
                shown.widgets.discard(widget)
                if shown.widgets:
                    shown = None
                else:
                    del self._shown[id(series)]
            last = not self._shown
            limited, self._limited = (self._limited, None) if last else (None, self._limited)
            if last:
                self.limit, self.memory = None, None
        if shown is not None:
            shown.steps.close()
        if limited is not None:
            limited.close()

    def widgets(self) -> int:
        """The widgets open now."""
        with self._lock:
            return len({w for shown in self._shown.values() for w in shown.widgets})

    def held_steps(self, series: TimeSeries) -> SharedSteps | None:
        """The shared steps of `series`, while a widget shows it."""
        with self._lock:
            shown = self._shown.get(id(series))
            return None if shown is None else shown.steps


KERNEL = Kernel()
