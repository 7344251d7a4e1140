"""Interactive sessions: a series, a moving time window, and the chronovolume kept up to date.

A `Session` is what a viewer or notebook scrubs through time with. Its steps
come from a `WindowManager` (resident under the memory budget, prefetched in
the scrub direction, no step read twice while resident). How a new window is
integrated depends on the time positions (docs/semantics.md, sliding windows):

- ``absolute`` positions with forward or backward order: a step's colour does
  not depend on the window, so the window's state is updated instead of
  recomputed. Each mode says how (`chronocl.modes`): modes that slide by
  inversion keep sums in fixed point and add the entering and subtract the
  leaving steps exactly (a part they aggregate, like additive's opacity, slides
  like the others); the rest slide through a `SlidingAggregate` of partial
  chronovolumes, combined on the engine.
- ``relative`` positions, importance orders, jumps to a window that does not
  overlap the last one, and spec changes: the window is re-integrated, from
  resident data only.

The partial volumes that sliding holds are charged to the same memory budget
as the resident steps; when both do not fit, the session re-integrates.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np

from chronocl.core.budget import human, parse_memory
from chronocl.core.errors import InvalidParameterError
from chronocl.core.selection import Selection, parse_selection
from chronocl.core.tf import FITTED
from chronocl.data.bricks import ResidentBricks, SeriesBricks
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.data.window import WindowManager
from chronocl.engine import get_engine
from chronocl.integration.inmemory import integrate_bricks, make_spec, prepare, value_range
from chronocl.integration.levels import AutoLevels, check_level
from chronocl.integration.slider import Slider
from chronocl.integration.sliding import block_size
from chronocl.modes.spec import IntegrationSpec


class Session:
    """A series, a window and an integration spec; every call returns the current Chronovolume.

        s = Session(series, memory="2GB", mode="max", time_tf="rgb")
        cv = s.set_window(0, 16)       # steps 0..15
        cv = s.slide(+1)               # steps 1..16, updated incrementally
        cv = s.set_spec(mode="alpha")  # re-integrated from resident steps

    `memory` is the budget for resident steps plus sliding state; `manager` shares
    another session's resident steps (parallel views of one window) instead.
    `slide` clamps at either end of the series (the window keeps its width);
    `set_window` raises InvalidSelectionError for steps outside the series.
    Returned chronovolumes are new arrays each time: keep them as long as needed.
    """

    def __init__(
        self,
        series: TimeSeries,
        *,
        memory: str | int | None = None,
        engine: str | object = "opencl",
        device: str | None = None,
        spec: IntegrationSpec | None = None,
        prefetch: int | None = None,
        manager: WindowManager | None = None,
        level: int | str = 0,
        target_ms: float = 150.0,
        managers: dict | None = None,
        **spec_args: object,
    ) -> None:
        self.base = series
        # The spec as asked; `self.spec` is it with its value range fixed (`_fix_range`).
        self.asked = spec if spec is not None else make_spec(**spec_args)  # type: ignore[arg-type]
        self.spec = self.asked
        self.engine = get_engine(engine, device) if isinstance(engine, str) else engine
        self.budget = parse_memory(memory)
        self.selection: Selection | None = None
        self.stats: dict = {}
        self._arrays: dict[int, np.ndarray] = {}
        self._bricks = ResidentBricks(self._arrays)
        self._slider: Slider | None = None
        self._cv: Chronovolume | None = None
        self._prefetch = prefetch
        self._managers = managers
        # level="auto": child sessions at fixed levels, chosen per frame for the target.
        self._auto: AutoLevels | None = None
        if level == "auto":
            self.level = 0
            self._auto = AutoLevels(self, target_ms)
            self.series, self.manager, self._owns_manager = series, None, False
            return
        self.level = check_level(series, level)
        self.series = series.level(self.level, self.spec.integration.pool)
        # Sessions that show one window in several views can share one manager's resident steps.
        self._owns_manager = manager is None
        self.manager = manager or WindowManager(self.series, self.budget, prefetch=prefetch)

    # -- public --------------------------------------------------------------------------
    def set_window(
        self, t0: int | str | Selection | Sequence[int], t1: int | None = None, stride: int = 1
    ) -> Chronovolume:
        """Jump to the window [t0, t1) with a stride (or a '0:16:2' string, list or Selection)."""
        window = t0 if t1 is None else slice(int(t0), int(t1), int(stride))
        return self.show(parse_selection(window, self.series.n_steps))

    def slide(self, k: int = 1) -> Chronovolume:
        """Move the window by k strides (negative: back in time), clamped at either end."""
        sel = self._require()
        steps = sel.steps
        stride = sel.stride
        shift = int(k) * stride
        shift = max(-steps[0], min(shift, self.series.n_steps - 1 - steps[-1]))
        return self.show(Selection(tuple(s + shift for s in steps), sel.n_steps))

    def set_spec(self, spec: IntegrationSpec | None = None, **changes: object) -> Chronovolume:
        """Change the integration: a whole spec, or fields of the current one (mode="max")."""
        new = spec if spec is not None else dataclasses.replace(self.asked, **changes)
        return self.show(self._require(), new)

    def show(self, selection: Selection, spec: IntegrationSpec | None = None) -> Chronovolume:
        """The chronovolume of `selection` under `spec` (default: the current one): a window
        and a spec change at once, integrated once."""
        if spec is None or spec in (self.asked, self.spec):
            spec = self.spec if self.spec is not self.asked else self._fix_range(None, selection)
        else:
            self.asked = spec
            spec = self._fix_range(spec, selection)
        if self._auto is not None:
            self.spec, self.selection = spec, selection
            return self._auto.show(selection, spec)
        if spec != self.spec:
            if self.level and spec.integration.pool != self.spec.integration.pool:
                self._repool(spec.integration.pool)
            self.spec = spec
            self._slider = None
            self._cv = None
        return self._update(selection)

    def current(self) -> Chronovolume:
        """The chronovolume of the current window and spec."""
        if self._auto is not None:
            return self._auto.current()
        if self._cv is None:
            return self._update(self._require())
        return self._cv

    def refine(self) -> Chronovolume | None:
        """level="auto": the full-resolution chronovolume of what was last shown coarse (None
        when the last one was full resolution already, or the level is fixed)."""
        return None if self._auto is None else self._auto.refine()

    def record_display(self, ms: float) -> None:
        """The display's upload + render time of the last chronovolume returned: level="auto"
        learns from it which level meets the target next time."""
        if self._auto is not None:
            self._auto.record_display(ms)

    @property
    def shown_level(self) -> int:
        """The level of the last chronovolume returned (0: full resolution)."""
        return self.level if self._auto is None else self._auto.shown

    def close(self) -> None:
        if self._auto is not None:
            self._auto.close()
        if self._owns_manager:
            self.manager.close()
        self._arrays = {}
        self._bricks.forget()
        self._slider = None

    def _repool(self, pool: str) -> None:
        """A coarse session whose new mode pools levels differently reads the other level."""
        if not self._owns_manager:
            raise InvalidParameterError(
                f"mode {self.spec.mode!r} pools coarse levels differently; give this session "
                "its own window manager, or use level='auto'"
            )
        self.manager.close()
        self.series = self.base.level(self.level, pool)
        self.manager = WindowManager(self.series, self.budget, prefetch=self._prefetch)
        self._arrays = {}
        self._bricks.forget()
        self.selection = None

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals -----------------------------------------------------------------------
    def _fix_range(self, spec: IntegrationSpec | None, selection: Selection) -> IntegrationSpec:
        """`spec` (default: as asked) with its value range fixed: a range fitted to a window
        is fitted once, to the window shown when the spec is set, and kept while the window
        slides (sliding then equals integrating each window with that range)."""
        spec = self.asked if spec is None else spec
        if spec.data_tf.range_kind != FITTED:  # the same for every window already
            return spec
        return spec.with_value_range(value_range(self.base, selection, spec))

    def _require(self) -> Selection:
        if self.selection is None:
            self.selection = parse_selection(None, self.series.n_steps)
        return self.selection

    def _update(self, selection: Selection) -> Chronovolume:
        t = time.perf_counter()
        old = self.selection
        if old is not None and selection == old and self._cv is not None:
            return self._cv
        if self._window_bytes(selection) > self.budget:
            return self._stream(selection, t)
        direction = 0 if old is None else int(np.sign(selection.steps[0] - old.steps[0]))
        reason = self._incremental_blocker(selection)
        keep = self._bricks.keep = self._keeps_brick(selection)
        if self._owns_manager:
            state = 0 if reason else self._state_bytes(selection)
            self.manager.budget = self.budget - state - keep * self._window_bytes(selection)
        arrays = dict(
            zip(selection.steps, self.manager.get(selection.steps, direction), strict=True)
        )
        leaving = {s: a for s, a in self._arrays.items() if s not in arrays}
        self._arrays = arrays
        self.selection = selection
        slider = self._slider
        path = "reintegrate"
        if reason is None and slider is not None and slider.can_move_to(selection):
            cv = slider.move_to(selection, {**leaving, **arrays})
            path = "incremental"
        else:
            cv = self._reintegrate(selection)
            if reason is None:
                # Jumps and spec changes integrate directly (one pass over the window);
                # the sliding state is rebuilt lazily on the next slide.
                self._slider = Slider(self, selection)
            else:
                self._slider = None
        self._cv = cv
        self._record(t, path, reason)
        return cv

    def _stream(self, selection: Selection, t: float) -> Chronovolume:
        """A window larger than the budget: integrated z-slab by z-slab from the store, each
        slab's brick a quarter of the budget at most (nothing resident, no sliding)."""
        job = prepare(self.series, selection, spec=self.spec)
        rows = max(1, self.budget // (4 * max(1, job.row_bytes)))
        self._arrays, self._slider, self.selection = {}, None, selection
        self._bricks.forget()
        self._cv = integrate_bricks(job, self.engine, SeriesBricks(self.series), slab=rows)
        need = human(self._window_bytes(selection))
        why = f"the window needs {need} > budget {human(self.budget)}: streamed by z-slabs"
        self._record(t, "streamed", why)
        return self._cv

    def _record(self, t: float, path: str, reason: str | None) -> None:
        self.stats = {
            "level": self.level,
            "integrate_ms": 1e3 * (time.perf_counter() - t),
            "path": path,
            "incremental": path == "incremental",
            "why_not_incremental": reason,
            "steps": list(self.selection.steps),
            "resident_steps": len(self.manager.resident()),
            "reads": sum(self.manager.reads.values()),
            "held_partials": 0 if self._slider is None else self._slider.held,
        }

    def _incremental_blocker(self, selection: Selection) -> str | None:
        """Why this window cannot slide incrementally (None: it can)."""
        spec = self.spec
        if spec.time_tf.positions != "absolute":
            return "relative time positions recolour every step on a slide"
        if not isinstance(spec.order, str):
            return "importance orders are not sliding windows"
        need = selection.width * self.manager.step_bytes + self._state_bytes(selection)
        if need > self.budget:
            return f"window and sliding state need {human(need)} > budget {human(self.budget)}"
        return None

    def _state_bytes(self, selection: Selection) -> int:
        """Budget for the state sliding holds: 2 stacks of ~2 sqrt(W) partials, work, sums."""
        voxels = int(np.prod(self.series.volume_shape))
        mode = self.spec.integration
        partials = (4 * block_size(selection.width) + 4) * mode.state_bytes * voxels
        return partials + 8 * mode.sum_channels * voxels

    def _reintegrate(self, selection: Selection) -> Chronovolume:
        job = prepare(self.series, selection, spec=self.spec)
        self._bricks.arrays = self._arrays  # its `keep` was decided in _update
        return integrate_bricks(job, self.engine, self._bricks)

    def _window_bytes(self, selection: Selection) -> int:
        return selection.width * self.manager.step_bytes

    def _keeps_brick(self, selection: Selection) -> bool:
        """Whether the window's stacked brick is kept for the next spec change: when it fits
        the budget beside the window's steps and the sliding state."""
        need = 2 * self._window_bytes(selection) + self._state_bytes(selection)
        return need <= self.budget
