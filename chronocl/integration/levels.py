"""Choosing the level of a multiscale series to draw next, for a latency target.

A session with ``level="auto"`` keeps one fixed-level session per level it has shown (and
per pooling, docs/levels.md) and asks a `LatencyModel` which level to integrate for each new
window or spec: the finest whose predicted time to a drawn frame (integrate, plus upload and
render as the display reports them) meets the target. The model starts from the coarsest
level, whose frame is always cheap, and learns from every frame's own timings. `refine`
then brings the same window and spec to full resolution when the caller is idle.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from chronocl.core.errors import InvalidParameterError
from chronocl.data.pyramid import level_shapes
from chronocl.data.window import WindowManager

if TYPE_CHECKING:
    from chronocl.core.selection import Selection
    from chronocl.data.chronovolume import Chronovolume
    from chronocl.data.series import TimeSeries
    from chronocl.integration.session import Session
    from chronocl.modes.spec import IntegrationSpec

SMOOTHING = 0.5  # weight of the newest measurement in the running estimates


def check_level(series: TimeSeries, level: object) -> int:
    """A fixed level of `series`: an integer in 0..n_levels-1, else one clear line."""
    n = series.n_levels
    if isinstance(level, bool) or not isinstance(level, int):
        raise InvalidParameterError(
            f"level {level!r} must be an integer 0..{n - 1} (0: full resolution) or 'auto'"
        )
    if not 0 <= level < n:
        name = series.source or "the series"
        have = (
            "only level 0 (add coarse levels with 'chronocl pyramid')"
            if n == 1
            else f"levels 0..{n - 1}"
        )
        raise InvalidParameterError(f"level {level} is out of range: {name} has {have}")
    return level


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

    def record_integrate(self, level: int, ms: float, steps: int) -> None:
        self._blend(self.rate, level, ms / max(1, self.voxels[level] * steps))

    def record_display(self, level: int, ms: float) -> None:
        self._blend(self.display, level, ms)

    @staticmethod
    def _blend(table: dict[int, float], level: int, value: float) -> None:
        old = table.get(level)
        table[level] = value if old is None else (1 - SMOOTHING) * old + SMOOTHING * value

    def predict(self, level: int, steps: int) -> float | None:
        """Predicted ms for `level` (None: nothing measured yet)."""
        if not self.rate:
            return None
        finest = min(self.rate)
        ms = max(self.rate[finest], self.rate.get(level, 0.0)) * self.voxels[level] * steps
        if self.display:
            near = min(self.display, key=lambda m: abs(m - level))
            ms += self.display[near] * self.voxels[level] / self.voxels[near]
        return ms

    def pick(self, steps: int) -> tuple[int, str]:
        """The level to draw next and why."""
        coarsest = len(self.voxels) - 1
        for level in range(coarsest + 1):
            ms = self.predict(level, steps)
            if ms is not None and ms <= self.target_ms:
                finer = "" if level == 0 else "; finer levels predicted over it"
                return level, f"level {level} predicted at {ms:.0f} ms, within the target{finer}"
        if self.predict(coarsest, steps) is None:
            return coarsest, "first frame: the coarsest level, measuring this machine"
        return coarsest, f"no level predicted within {self.target_ms:g} ms: the coarsest"


class AutoLevels:
    """The fixed-level sessions behind a ``level="auto"`` session (`owner`)."""

    def __init__(self, owner: Session, target_ms: float) -> None:
        self.owner = owner
        series = owner.base
        # The shapes by the rule: building the level series here would pool lazy levels.
        shapes = [series.volume_shape, *level_shapes(series.volume_shape)][: series.n_levels]
        self.model = LatencyModel([int(z) * int(y) * int(x) for z, y, x in shapes], target_ms)
        self.sessions: dict[tuple[int, str], Session] = {}
        self.shown = len(shapes) - 1
        self.why = ""
        self._last: tuple[Selection, IntegrationSpec] | None = None
        self._cv: Chronovolume | None = None

    def session(self, level: int, spec: IntegrationSpec) -> Session:
        key = (level, spec.integration.pool)
        s = self.sessions.get(key)
        if s is None:
            o = self.owner
            # Coarse levels hold 1/8 of the voxels of the next finer one or less.
            budget = o.budget if level == 0 else max(1, o.budget // 8)
            manager = None
            if o._managers is not None:  # views of one window share resident steps per level
                manager = o._managers.get(key)
                if manager is None:
                    series = o.base.level(level, spec.integration.pool)
                    manager = WindowManager(series, budget, prefetch=o._prefetch)
                    o._managers[key] = manager
            s = self.sessions[key] = type(o)(  # a fixed-level session like the owner
                o.base,
                memory=budget,
                engine=o.engine,
                spec=spec,
                level=level,
                prefetch=o._prefetch,
                manager=manager,
            )
        return s

    def show(self, selection: Selection, spec: IntegrationSpec) -> Chronovolume:
        level, self.why = self.model.pick(selection.width)
        return self._at(level, selection, spec)

    def _at(self, level: int, selection: Selection, spec: IntegrationSpec) -> Chronovolume:
        s = self.session(level, spec)
        t = time.perf_counter()
        cv = s.show(selection, spec)
        self.model.record_integrate(level, 1e3 * (time.perf_counter() - t), selection.width)
        self.shown, self._last, self._cv = level, (selection, spec), cv
        self.owner.stats = {
            **s.stats,
            "level": level,
            "levels": len(self.model.voxels),
            "why_level": self.why,
            "refining": level > 0,
        }
        return cv

    def refine(self) -> Chronovolume | None:
        if self.shown == 0 or self._last is None:
            return None
        self.why = "refined to full resolution"
        return self._at(0, *self._last)

    def current(self) -> Chronovolume:
        if self._cv is None:
            return self.show(self.owner._require(), self.owner.spec)
        return self._cv

    def record_display(self, ms: float) -> None:
        """The display's upload + render time of the last chronovolume shown."""
        self.model.record_display(self.shown, ms)

    def close(self) -> None:
        for s in self.sessions.values():
            s.close()
        self.sessions = {}
