"""Interactive sessions: a series, a moving time window, and the chronovolume kept up to date.

A `Session` is what a viewer or notebook scrubs through time with. It moves its window and
spec once for all the levels it shows: each move becomes a window and a spec with its value
range fixed (`moves`), its level policy picks the level, and that level's session
(`LevelSession`, from a `SessionPool`) brings its chronovolume up to date, sliding
incrementally where it can.

The level policies: `FixedLevel` always draws the level asked. `LatencyModel`
(``Session(series, level="auto")``) picks for each new window or spec the finest level whose
predicted time to a drawn frame (integrate, plus upload and render as the display reports
them) meets a latency target. It starts from the coarsest level, whose frame is always cheap,
and learns from every frame's own timings; `refine` then brings the same window and spec to
full resolution when the caller is idle. Both say which level a refine brings a frame to
(`finest`). The times it predicts from are the session's measured rates (`costs.Costs`): its
levels record their integrations and slides, the session its reads and the display's times.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from chronocl.core.errors import InvalidParameterError
from chronocl.core.process_memory import Streaming
from chronocl.core.selection import Selection, parse_selection
from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.pyramid import level_shapes
from chronocl.data.series import TimeSeries
from chronocl.data.window import WindowManager
from chronocl.integration.inmemory import check_level
from chronocl.integration.interactive.costs import Costs
from chronocl.integration.interactive.level_session import LevelSession, Recolour, SessionPool
from chronocl.integration.interactive.moves import Window, changed, fixed, jump, slid
from chronocl.integration.interactive.settings import manager_key, settings
from chronocl.modes.spec import IntegrationSpec


class LatencyModel:
    """Predicted milliseconds from a request to its drawn frame, per level, from the rates
    measured (`costs.Costs`, the session's).

    Integration is modelled per voxel-step (the rate measured at the finest level seen,
    which is the most efficient, so coarse-level overheads never make a fine level look
    cheap), a window streamed at the rate measured streaming it; display (upload + render) per
    voxel from the nearest level measured; reading a step per voxel at the larger of the
    finest level's rate measured and the level's own. Unmeasured: only the coarsest level is
    predicted to fit.
    """

    finest = 0  # a refine brings a coarse frame to full resolution

    def __init__(self, voxels: list[int], target_ms: float, costs: Costs | None = None) -> None:
        if not target_ms > 0:
            raise InvalidParameterError(f"target_ms is {target_ms}; give a positive number")
        self.voxels = voxels
        self.target_ms = float(target_ms)
        self.costs = Costs() if costs is None else costs

    def predict(
        self,
        level: int,
        steps: int,
        missing: int = 0,
        slide_ms: float | None = None,
        streams: bool = False,
    ) -> float | None:
        """Predicted ms for `level` (None: nothing measured yet), `missing` of the window's
        steps to be read first (a level not shown lately has none of them resident: a scrub
        at 64^3 that tried 256^3 waited 0.7 s for ten of its steps), `slide_ms` the level's
        prediction of a slide where it slides incrementally (None: it integrates); `streams`:
        the level streams its window, predicted at the rate measured streaming (its reads
        with it) once there is one."""
        c = self.costs
        if streams and level in c.streamed:
            ms, missing = c.streamed[level] * self.voxels[level] * steps, 0
        elif c.direct:
            rate = max(c.direct[min(c.direct)], c.direct.get(level, 0.0))
            ms = rate * self.voxels[level] * steps if slide_ms is None else slide_ms
        else:
            return None
        if c.display:
            ms += c.display[min(c.display, key=lambda m: abs(m - level))] * self.voxels[level]
        read = c.read_ms(level, self.voxels[level])
        if missing and read is not None:
            ms += missing * read
        return ms

    def pick(
        self,
        steps: int,
        missing: Callable[[int], int] = lambda level: 0,
        slides: Callable[[int], float | None] = lambda level: None,
        streams: Callable[[int], bool] = lambda level: False,
    ) -> tuple[int, str]:
        """The level to draw next and why; `missing(level)`: the steps it would read;
        `slides(level)`: the ms its slide is predicted at where it slides (else None);
        `streams(level)`: whether its window streams.

        The finest level is drawn where it is predicted within `TUNING.sharp_overrun` times
        the target: a coarser frame would be refined to it after, so the sharp frame would
        come later by the coarse frame's time and more."""
        coarsest = len(self.voxels) - 1
        measured = False
        for level in range(coarsest + 1):
            ms = self.predict(level, steps, missing(level), slides(level), streams(level))
            if ms is None:
                continue
            measured = True
            if ms <= self.target_ms:
                finer = "" if level == 0 else "; finer levels predicted over it"
                return level, f"level {level} predicted at {ms:.0f} ms, within the target{finer}"
            if level == 0 < coarsest and ms <= TUNING.sharp_overrun * self.target_ms:
                return 0, (
                    f"level 0 predicted at {ms:.0f} ms, within {TUNING.sharp_overrun:g}x the "
                    "target: drawn at once rather than coarse and refined"
                )
        if not measured:
            return coarsest, "first frame: the coarsest level, measuring this machine"
        return coarsest, f"no level predicted within {self.target_ms:g} ms: the coarsest"


class FixedLevel:
    """The level policy of a session at one level (0: full resolution): never refined."""

    def __init__(self, level: int) -> None:
        self.finest = level

    def pick(
        self,
        steps: int,
        missing: Callable[[int], int] = lambda level: 0,
        slides: Callable[[int], float | None] = lambda level: None,
        streams: Callable[[int], bool] = lambda level: False,
    ) -> tuple[int, str]:
        return self.finest, f"level {self.finest} asked"


class Session:
    """A series, a window and an integration spec; every move returns the current Chronovolume.

        s = Session(series, memory="2GB", mode="max", time_tf="rgb")
        cv = s.set_window(0, 16)       # steps 0..15
        cv = s.slide(+1)               # steps 1..16, updated incrementally
        cv = s.set_spec(mode="alpha")  # re-integrated from resident steps

    Keywords (`settings` reads them): `memory` is the budget for resident steps plus sliding
    state (default: half the memory free, at least 2 GB); `engine` (a name, with `device`, or
    an `Engine`); `spec`, or the fields of one (`mode`, `time_tf`, ... as `make_spec` takes
    them); `prefetch`, the steps read ahead in the scrub direction; `managers` (a dict the
    caller owns and closes) shares one window manager per (level, pooling) among sessions, and
    `manager` shares another session's resident steps at a fixed level (parallel views of one
    window) instead. With `display` (a viewer's), a window integrated from its steps comes
    back in the display format where the engine writes it: RGBA8 (`integrate_bricks`); slides
    and other engines still return float32. The viewer alone holds those: its recolouring
    writes a TF edit into the RGBA8 the window shows
    (`chronocl.render.recolour.bricks.shown_output`) and hands it back (`adopt`). With
    `slide_costs` (a viewer's `costs.Costs`, shared by its views' sessions, which record the
    times of their integrations and slides into it) a window slides only where a slide is
    predicted cheaper than integrating it again (`slider.slide_plan`); without (the default),
    the session measures into a `Costs` of its own, and every window that can slide does.

    `level` is the level of the series drawn (0: full resolution), or ``"auto"``: each window
    at the finest level predicted to meet `target_ms` (default `TUNING.target_ms`; level 0
    where predicted within `TUNING.sharp_overrun` of it; else a coarse frame first), which
    `refine` brings to full resolution when the caller is idle; `manager` then serves no level (one
    manager cannot serve every level: pass `managers`). A fixed level ignores `target_ms`.
    `stats` are those of the level drawn, with the level and why.

    `slide` clamps at either end of the series (the window keeps its width);
    `set_window` raises InvalidSelectionError for steps outside the series.
    Returned chronovolumes are new arrays each time: keep them as long as needed.
    """

    def __init__(
        self,
        series: TimeSeries,
        *,
        level: int | str = 0,
        manager: WindowManager | None = None,
        target_ms: float | None = None,
        **options: object,
    ) -> None:
        setup = settings(**options)  # type: ignore[arg-type]
        self.base = series
        self.engine = setup.engine
        # The spec as asked; `self.spec` is it with its value range fixed (`moves.fixed`).
        self.asked = self.spec = setup.asked
        self.selection: Selection | None = None
        self.stats: dict = {}
        self.costs = setup.costs  # the rates measured, shared by the levels (`costs.Costs`)
        # The levels' voxels, their shapes by the rule: building the level series here would
        # pool lazy levels.
        shapes = [series.volume_shape, *level_shapes(series.volume_shape)]
        self.voxels = [int(z) * int(y) * int(x) for z, y, x in shapes[: series.n_levels]]
        if level == "auto":
            target = TUNING.target_ms if target_ms is None else target_ms
            self.policy: FixedLevel | LatencyModel = LatencyModel(self.voxels, target, self.costs)
            self.shown = len(self.voxels) - 1
            manager = None
        else:
            self.policy = FixedLevel(check_level(series, level))  # type: ignore[arg-type]
            self.shown = self.policy.finest
        finest = self.policy.finest
        shared = None
        if manager is not None:
            shared = (manager_key(finest, self.asked.integration.pool), manager)
        self.pool = SessionPool(series, setup, finest, shared)
        self.why = ""
        self._last: tuple[Selection, IntegrationSpec] | None = None
        self._cv: Chronovolume | None = None
        self.why_not_read_ahead: str | None = None
        self._reading_ahead = False

    @property
    def shown_level(self) -> int:
        """The level of the last chronovolume returned (0: full resolution)."""
        return self.shown

    def at(self, level: int, spec: IntegrationSpec | None = None) -> LevelSession | None:
        """The session of `level` for the pooling of `spec` (default: the current spec's);
        None: not made yet."""
        pool = (spec or self.spec).integration.pool
        return self.pool.sessions.get(manager_key(level, pool))

    @property
    def manager(self) -> WindowManager:
        """The window manager of the level shown: its resident steps and their reads."""
        return self.pool.session(self.shown, self.spec).manager

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
        """The chronovolume of `selection` under `spec` (default: the current one), a window
        and a spec change at once, at the level the policy picks. The value range is fixed
        here, so every level is normalised by level 0's range."""
        self.asked, spec = fixed(self.base, self.asked, self.spec, spec, selection)
        # the last chronovolume goes first: a move that fails half way must not leave it shown,
        # nor a refine bring it back
        self.spec, self.selection, self._cv, self._last = spec, selection, None, None
        level, self.why = self.policy.pick(
            selection.width,
            lambda n: self._missing(n, selection),
            lambda n: self._slide_ms(n, selection, spec),
            lambda n: self._streams(n, selection, spec),
        )
        return self._at(level, selection, spec)

    def current(self) -> Chronovolume:
        """The chronovolume of the current window and spec."""
        if self._cv is None:
            return self.show(self.window(), self.spec)
        return self._cv

    def refine(self) -> Chronovolume | None:
        """The chronovolume of what was last shown coarse at the finest level (None when the
        last one was at the finest level already, as every one of a fixed level is)."""
        if self.shown == self.policy.finest or self._last is None:
            return None
        self.why = "refined to full resolution"
        return self._at(self.policy.finest, *self._last)

    def recolours(
        self, spec: IntegrationSpec, selection: Selection, shown: Chronovolume
    ) -> Recolour | str:
        """Where `spec` only recolours `shown`, the chronovolume this session last returned,
        of `selection` at the finest level, that level's `LevelSession.recolours`; else why
        not, in one line."""
        if self.selection != selection:
            return "another window"
        if self.shown != self.policy.finest:
            return "a coarse level is shown"
        full = self.at(self.policy.finest, spec)
        if full is None or full.selection != selection:
            return "the window is not integrated at full resolution"
        recolour = full.recolours(spec)
        if isinstance(recolour, str):
            return recolour
        if self._cv is not shown:
            return "the full-resolution window holds another frame"
        return recolour

    def adopt(self, asked: IntegrationSpec, spec: IntegrationSpec, cv: Chronovolume) -> None:
        """Show `cv`, the window at the finest level recoloured under `spec` (asked as
        `asked`), as if integrated; its level's session too (`LevelSession.adopt`)."""
        finest = self.policy.finest
        self.pool.session(finest, spec).adopt(asked, spec, cv)
        self.asked, self.spec, self._cv = asked, spec, cv
        self.shown, self._last = finest, (self.window(), spec)
        self.why = "recoloured at full resolution"
        self.stats = {**self.stats, "level": finest, "why_level": self.why, "refining": False}
        self.stats.update(integrate_ms=0.0, read_ms=0.0, path="recoloured", incremental=False)

    def record_display(self, ms: float) -> None:
        """The display's upload + render time of the last chronovolume returned: a latency
        policy learns from it which level meets the target next time."""
        self.costs.record_display(self.shown, ms, self.voxels[self.shown])

    def leaving(self, selection: Selection) -> None:
        """`selection` is shown next: each level lets go of what no longer helps
        (`LevelSession.leaving`), and so does this session of its last chronovolume."""
        if self.selection is not None and selection != self.selection:
            self._cv = None
        for s in self.pool.sessions.values():
            s.leaving(selection)

    def stream(self, why: Streaming | None) -> None:
        """The finest level streams its window from now on (`LevelSession.stream`), or not
        (None); coarser levels' windows are small and stay resident."""
        self.pool.stream(why)

    def close(self) -> None:
        self.pool.close()

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals -----------------------------------------------------------------------
    def _missing(self, level: int, selection: Selection) -> int:
        """The steps of `selection` not resident at `level` (all, where it has no session)."""
        held = self.at(level)
        if held is None:
            return selection.width
        resident = set(held.manager.resident())
        streaming = self.pool.streaming
        if level == self.policy.finest and streaming is not None:
            resident &= streaming.keep  # the steps not kept are read again
        return sum(1 for t in selection.steps if t not in resident)

    def _slide_ms(self, level: int, selection: Selection, spec: IntegrationSpec) -> float | None:
        """The ms `level` is predicted to slide to `selection` in, where it slides (a viewer's
        slide costs: `LevelSession.slide_ms`); None where it integrates or has no session."""
        held = self.at(level, spec)
        return None if held is None else held.slide_ms(selection, spec)

    def _streams(self, level: int, selection: Selection, spec: IntegrationSpec) -> bool:
        """Whether `level` would stream `selection` (a viewer's limit leaves the finest level's
        window no room, or the window is over the level's budget: `LevelSession.streams`)."""
        if level == self.policy.finest and self.pool.streaming is not None:
            return True
        held = self.at(level, spec)
        return held is not None and held.streams(selection)

    def _at(self, level: int, selection: Selection, spec: IntegrationSpec) -> Chronovolume:
        s, finest = self.pool.session(level, spec), self.policy.finest
        t, cpu = time.perf_counter(), time.process_time()
        cv = s.show(selection, spec)
        wall = time.perf_counter() - t
        self.costs.record_read(level, s.manager.scrub.read_s, self.voxels[level])
        if level != finest:
            self._read_ahead(selection, spec, wall, time.process_time() - cpu)
        self.shown, self._last, self._cv = level, (selection, spec), cv
        self.stats = {
            **s.stats,
            "level": level,
            "levels": self.base.n_levels,
            "why_level": self.why,
            "refining": level != finest,
            "why_not_read_ahead": self.why_not_read_ahead if level != finest else None,
        }
        return cv

    def _read_ahead(
        self, selection: Selection, spec: IntegrationSpec, wall_s: float, cpu_s: float
    ) -> None:
        """The refine to come finds the window's full-resolution steps read, where that pays
        (`Costs.why_not_read_ahead`: the coarse frames leave a core idle, and reading the steps
        at the stop would take longer than the target). On 2 PoCL cores the reads took the
        cores the coarse frames needed (docs/window.md): their integration keeps both busy
        there."""
        model = self.policy
        assert isinstance(model, LatencyModel)  # a fixed level is never shown coarse
        if not self._reading_ahead:  # the readers' CPU time would count as the frame's
            self.costs.record_frame(wall_s, cpu_s)
        missing = self._missing(0, selection)
        streams = self._streams(model.finest, selection, spec)
        why = "full resolution streams its window" if streams else None
        why = why or self.costs.why_not_read_ahead(missing, self.voxels[0], model.target_ms)
        if why is None:  # its session may be new: it says why not itself
            why = self.pool.session(model.finest, spec).read_ahead(selection)
        self.why_not_read_ahead, self._reading_ahead = why, why is None
