"""Choosing the level of a multiscale series to draw next, for a latency target.

An `AutoSession` (what ``Session(series, level="auto")`` returns) takes one fixed-level
session per level it has shown (and per pooling, docs/levels.md) from a `SessionPool` and
asks a `LatencyModel` which level to integrate for each new window or spec: the finest whose
predicted time to a drawn frame (integrate, plus upload and render as the display reports
them) meets the target. The model starts from the coarsest
level, whose frame is always cheap, and learns from every frame's own timings. `refine`
then brings the same window and spec to full resolution when the caller is idle.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

from chronocl.core.errors import InvalidParameterError
from chronocl.core.process_memory import Streaming
from chronocl.core.selection import Selection, parse_selection
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.pyramid import level_shapes
from chronocl.data.series import TimeSeries
from chronocl.data.window import WindowManager
from chronocl.integration.interactive.costs import ReadAhead
from chronocl.integration.interactive.moves import Window, changed, fixed, jump, slid
from chronocl.modes.spec import IntegrationSpec

SMOOTHING = 0.5  # weight of the newest measurement in the running estimates


class LatencyModel:
    """Predicted milliseconds from a request to its drawn frame, per level.

    Integration is modelled per voxel-step (the rate measured at the finest level seen,
    which is the most efficient, so coarse-level overheads never make a fine level look
    cheap); display (upload + render) per level, scaled by voxels from the nearest level
    measured. Unmeasured: only the coarsest level is predicted to fit.
    """

    def __init__(self, voxels: list[int], target_ms: float) -> None:
        if not target_ms > 0:
            raise InvalidParameterError(f"target_ms is {target_ms}; give a positive number")
        self.voxels = voxels
        self.target_ms = float(target_ms)
        self.rate: dict[int, float] = {}  # level -> ms per voxel-step of integration
        self.display: dict[int, float] = {}  # level -> ms of upload + render
        self.reads: dict[int, float] = {}  # level -> ms per voxel of reading one step

    def record_integrate(self, level: int, ms: float, steps: int) -> None:
        self._blend(self.rate, level, ms / max(1, self.voxels[level] * steps))

    def record_display(self, level: int, ms: float) -> None:
        self._blend(self.display, level, ms)

    def record_read(self, level: int, seconds: float | None) -> None:
        """A step's read time at `level` (the window manager's running average)."""
        if seconds:
            self._blend(self.reads, level, 1e3 * seconds / self.voxels[level])

    @staticmethod
    def _blend(table: dict[int, float], level: int, value: float) -> None:
        old = table.get(level)
        table[level] = value if old is None else (1 - SMOOTHING) * old + SMOOTHING * value

    def predict(self, level: int, steps: int, missing: int = 0) -> float | None:
        """Predicted ms for `level` (None: nothing measured yet), `missing` of the window's
        steps to be read first (a level not shown lately has none of them resident: a scrub
        at 64^3 that tried 256^3 waited 0.7 s for ten of its steps)."""
        if not self.rate:
            return None
        finest = min(self.rate)
        ms = max(self.rate[finest], self.rate.get(level, 0.0)) * self.voxels[level] * steps
        if self.display:
            near = min(self.display, key=lambda m: abs(m - level))
            ms += self.display[near] * self.voxels[level] / self.voxels[near]
        if missing and self.reads:
            read = max(self.reads[min(self.reads)], self.reads.get(level, 0.0))
            ms += missing * read * self.voxels[level]
        return ms

    def pick(self, steps: int, missing: Callable[[int], int] = lambda level: 0) -> tuple[int, str]:
        """The level to draw next and why; `missing(level)`: the steps it would read."""
        coarsest = len(self.voxels) - 1
        for level in range(coarsest + 1):
            ms = self.predict(level, steps, missing(level))
            if ms is not None and ms <= self.target_ms:
                finer = "" if level == 0 else "; finer levels predicted over it"
                return level, f"level {level} predicted at {ms:.0f} ms, within the target{finer}"
        if self.predict(coarsest, steps) is None:
            return coarsest, "first frame: the coarsest level, measuring this machine"
        return coarsest, f"no level predicted within {self.target_ms:g} ms: the coarsest"


class Pool(Protocol):
    """What an `AutoSession` needs of its pool (`chronocl.integration.interactive.session.
    SessionPool`): the series and a fixed-level session per level and pooling."""

    series: TimeSeries
    sessions: dict  # (level, pooling) -> the fixed-level sessions made so far

    def session(self, level: int, spec: IntegrationSpec) -> FixedLevel: ...

    def read_ahead(self, selection: Selection, spec: IntegrationSpec) -> None: ...

    def close(self) -> None: ...


class FixedLevel(Protocol):
    """What an `AutoSession` uses of a fixed-level `Session`."""

    stats: dict
    manager: WindowManager  # its resident steps and their read time
    streaming: Streaming | None

    def show(self, selection: Selection, spec: IntegrationSpec | None = None) -> Chronovolume: ...

    def leaving(self, selection: Selection) -> None: ...

    def stream(self, why: Streaming | None) -> None: ...


class AutoSession:
    """A session that draws each window at the finest level predicted to meet `target_ms`
    (a coarse frame first) and refines it to full resolution when asked (`refine`).

    Built by ``Session(series, level="auto", ...)``; it moves like a `Session` (set_window,
    slide, set_spec, show, current; the moves in `chronocl.integration.interactive.moves`)
    and passes each window to the fixed-level session of the level chosen, from `pool`.
    `stats` are that session's, with the level chosen and why.
    """

    def __init__(self, pool: Pool, spec: IntegrationSpec, target_ms: float) -> None:
        self.pool = pool
        self.base = series = pool.series
        self.asked = self.spec = spec
        self.selection: Selection | None = None
        self.stats: dict = {}
        # The shapes by the rule: building the level series here would pool lazy levels.
        shapes = [series.volume_shape, *level_shapes(series.volume_shape)][: series.n_levels]
        self.model = LatencyModel([int(z) * int(y) * int(x) for z, y, x in shapes], target_ms)
        self.shown = len(shapes) - 1
        self.why = ""
        self._last: tuple[Selection, IntegrationSpec] | None = None
        self._cv: Chronovolume | None = None
        self._streaming: Streaming | None = None  # full resolution's (`stream`)
        self.ahead = ReadAhead()  # whether coarse frames read full resolution's steps ahead
        self.why_not_read_ahead: str | None = None
        self._reading_ahead = False

    @property
    def shown_level(self) -> int:
        """The level of the last chronovolume returned (0: full resolution)."""
        return self.shown

    def set_window(self, t0: Window, t1: int | None = None, stride: int = 1) -> Chronovolume:
        """Jump to the window [t0, t1) with a stride (or a '0:16:2' string, list or Selection)."""
        return self.show(jump(t0, t1, stride, self.base.n_steps))

    def slide(self, k: int = 1) -> Chronovolume:
        """Move the window by k strides (negative: back in time), clamped at either end."""
        return self.show(slid(self.window(), k, self.base.n_steps))

    def set_spec(self, spec: IntegrationSpec | None = None, **changes: object) -> Chronovolume:
        """Change the integration: a whole spec, or fields of the current one (mode="max")."""
        return self.show(self.window(), changed(self.asked, spec, changes))

    def window(self) -> Selection:
        """The window shown (before any: every step)."""
        if self.selection is None:
            self.selection = parse_selection(None, self.base.n_steps)
        return self.selection

    def show(self, selection: Selection, spec: IntegrationSpec | None = None) -> Chronovolume:
        """The chronovolume of `selection` under `spec` (default: the current one), at the
        level the latency model picks. The value range is fixed here, as `Session.show`
        fixes it, so every level is normalised by level 0's range."""
        self.asked, spec = fixed(self.base, self.asked, self.spec, spec, selection)
        self.spec, self.selection = spec, selection
        level, self.why = self.model.pick(selection.width, lambda n: self._missing(n, selection))
        return self._at(level, selection, spec)

    def _missing(self, level: int, selection: Selection) -> int:
        """The steps of `selection` not resident at `level` (all, where it has no session)."""
        held = self.pool.sessions.get((level, self.spec.integration.pool))
        if held is None:
            return selection.width
        resident = set(held.manager.resident())
        if level == 0 and self._streaming is not None:  # the steps not kept are read again
            resident &= self._streaming.keep
        return sum(1 for t in selection.steps if t not in resident)

    def _at(self, level: int, selection: Selection, spec: IntegrationSpec) -> Chronovolume:
        s = self.pool.session(level, spec)
        if level == 0 and s.streaming != self._streaming:  # a session made since `stream`
            s.stream(self._streaming)
        t, cpu = time.perf_counter(), time.process_time()
        cv = s.show(selection, spec)
        wall = time.perf_counter() - t
        self.model.record_integrate(level, 1e3 * wall, selection.width)
        self.model.record_read(level, s.manager.scrub.read_s)
        if level > 0:
            self._read_ahead(selection, spec, wall, time.process_time() - cpu)
        self.shown, self._last, self._cv = level, (selection, spec), cv
        self.stats = {
            **s.stats,
            "level": level,
            "levels": len(self.model.voxels),
            "why_level": self.why,
            "refining": level > 0,
            "why_not_read_ahead": self.why_not_read_ahead if level > 0 else None,
        }
        return cv

    def _read_ahead(
        self, selection: Selection, spec: IntegrationSpec, wall_s: float, cpu_s: float
    ) -> None:
        """The refine to come finds the window's full-resolution steps read, where that pays
        (`costs.ReadAhead`: the coarse frames leave a core idle, and reading the steps at the
        stop would take longer than the target). On 2 PoCL cores the reads took the cores the
        coarse frames needed (docs/window.md): their integration keeps both busy there."""
        if not self._reading_ahead:  # the readers' CPU time would count as the frame's
            self.ahead.record_frame(wall_s, cpu_s)
        finest = min(self.model.reads, default=None)  # ms per voxel of a step's read
        read = None if finest is None else self.model.reads[finest] * self.model.voxels[0]
        missing = self._missing(0, selection)
        why = "full resolution streams its window" if self._streaming is not None else None
        why = why or self.ahead.why_not(missing, read, self.model.target_ms)
        self.why_not_read_ahead, self._reading_ahead = why, why is None
        if why is None:
            self.pool.read_ahead(selection, spec)

    def leaving(self, selection: Selection) -> None:
        """`selection` is shown next: each level lets go of what no longer helps
        (`Session.leaving`), and so does this session of its last chronovolume."""
        if self.selection is not None and selection != self.selection:
            self._cv = None
        for s in self.pool.sessions.values():
            s.leaving(selection)

    def stream(self, why: Streaming | None) -> None:
        """Full resolution streams its window from now on (`Session.stream`), or not (None);
        the coarse levels' windows are small and stay resident."""
        self._streaming = why
        for (level, _), s in self.pool.sessions.items():
            if level == 0:
                s.stream(why)

    def refine(self) -> Chronovolume | None:
        """The full-resolution chronovolume of what was last shown coarse (None when the last
        one was full resolution already)."""
        if self.shown == 0 or self._last is None:
            return None
        self.why = "refined to full resolution"
        return self._at(0, *self._last)

    def adopt(self, asked: IntegrationSpec, spec: IntegrationSpec, cv: Chronovolume) -> None:
        """Show `cv`, the window at full resolution recoloured under `spec` (asked as `asked`),
        as if integrated (`Session.adopt`, which its level-0 session is told too)."""
        self.asked, self.spec, self._cv = asked, spec, cv
        self.shown, self._last = 0, (self.window(), spec)
        self.why = "recoloured at full resolution"
        self.stats = {**self.stats, "level": 0, "why_level": self.why, "refining": False}
        self.stats.update(integrate_ms=0.0, path="recoloured", incremental=False)

    def current(self) -> Chronovolume:
        """The chronovolume of the current window and spec."""
        if self._cv is None:
            return self.show(self.window(), self.spec)
        return self._cv

    def record_display(self, ms: float) -> None:
        """The display's upload + render time of the last chronovolume returned: the model
        learns from it which level meets the target next time."""
        self.model.record_display(self.shown, ms)

    def close(self) -> None:
        self.pool.close()

    def __enter__(self) -> AutoSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
