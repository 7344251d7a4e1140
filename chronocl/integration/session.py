"""Interactive sessions: a series, a moving time window, and the chronovolume kept up to date.

A `Session` is what a viewer or notebook scrubs through time with. Its steps
come from a `WindowManager` (resident under the memory budget, prefetched in
the scrub direction, no step read twice while resident). How a new window is
integrated depends on the time positions (DESIGN.md section 3):

- ``absolute`` positions with forward or backward order: a step's colour does
  not depend on the window, so the window's state is updated instead of
  recomputed. Additive keeps its colour sums in fixed point and adds the
  entering and subtracts the leaving steps exactly (its opacity, a maximum,
  slides like the others); alpha, first_hit, max and min slide through a
  `SlidingAggregate` of partial chronovolumes, combined on the engine.
- ``relative`` positions, importance orders, jumps to a window that does not
  overlap the last one, and spec changes: the window is re-integrated, from
  resident data only.

The partial volumes that sliding holds are charged to the same memory budget
as the resident steps; when both do not fit, the session re-integrates.
"""

from __future__ import annotations

import dataclasses
import time
import weakref
from collections.abc import Sequence

import numpy as np

from chronocl import reference
from chronocl.core import values
from chronocl.core.budget import human, parse_memory
from chronocl.core.memory import aligned_empty
from chronocl.core.selection import Selection, parse_selection
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.data.window import WindowManager, stack_brick
from chronocl.engine import FIXED_ONE, get_engine
from chronocl.integration.inmemory import Job, integrate, make_spec, prepare
from chronocl.integration.sliding import SlidingAggregate, block_size
from chronocl.modes.spec import IntegrationSpec
from chronocl.reference import Partial


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
        **spec_args: object,
    ) -> None:
        self.series = series
        self.spec = spec if spec is not None else make_spec(**spec_args)  # type: ignore[arg-type]
        self.engine = get_engine(engine, device) if isinstance(engine, str) else engine
        self.budget = parse_memory(memory)
        # Sessions that show one window in several views can share one manager's resident steps.
        self._owns_manager = manager is None
        self.manager = manager or WindowManager(series, self.budget, prefetch=prefetch)
        self.selection: Selection | None = None
        self.stats: dict = {}
        self._arrays: dict[int, np.ndarray] = {}
        self._slider: _Slider | None = None
        self._cv: Chronovolume | None = None

    # -- public --------------------------------------------------------------------------
    def set_window(
        self, t0: int | str | Selection | Sequence[int], t1: int | None = None, stride: int = 1
    ) -> Chronovolume:
        """Jump to the window [t0, t1) with a stride (or a '0:16:2' string, list or Selection)."""
        window = t0 if t1 is None else slice(int(t0), int(t1), int(stride))
        selection = parse_selection(window, self.series.n_steps)
        return self._update(selection)

    def slide(self, k: int = 1) -> Chronovolume:
        """Move the window by k strides (negative: back in time), clamped at either end."""
        sel = self._require()
        steps = sel.steps
        stride = sel.stride
        shift = int(k) * stride
        shift = max(-steps[0], min(shift, self.series.n_steps - 1 - steps[-1]))
        return self._update(Selection(tuple(s + shift for s in steps), sel.n_steps))

    def set_spec(self, spec: IntegrationSpec | None = None, **changes: object) -> Chronovolume:
        """Change the integration: a whole spec, or fields of the current one (mode="max")."""
        new = spec if spec is not None else dataclasses.replace(self.spec, **changes)
        if new != self.spec:
            self.spec = new
            self._slider = None
            self._cv = None
        return self.current()

    def current(self) -> Chronovolume:
        """The chronovolume of the current window and spec."""
        if self._cv is None:
            return self._update(self._require())
        return self._cv

    def close(self) -> None:
        if self._owns_manager:
            self.manager.close()
        self._arrays = {}
        self._slider = None

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals -----------------------------------------------------------------------
    def _require(self) -> Selection:
        if self.selection is None:
            self.selection = parse_selection(None, self.series.n_steps)
        return self.selection

    def _update(self, selection: Selection) -> Chronovolume:
        t = time.perf_counter()
        old = self.selection
        if old is not None and selection == old and self._cv is not None:
            return self._cv
        direction = 0 if old is None else int(np.sign(selection.steps[0] - old.steps[0]))
        reason = self._incremental_blocker(selection)
        if self._owns_manager:
            self.manager.budget = self.budget - (0 if reason else self._state_bytes(selection))
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
                self._slider = _Slider(self, selection)
            else:
                self._slider = None
        self._cv = cv
        self.stats = {
            "integrate_ms": 1e3 * (time.perf_counter() - t),
            "path": path,
            "incremental": path == "incremental",
            "why_not_incremental": reason,
            "steps": list(selection.steps),
            "resident_steps": len(self.manager.resident()),
            "reads": sum(self.manager.reads.values()),
            "held_partials": 0 if self._slider is None else self._slider.held,
        }
        return cv

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
        """Budget for the partial volumes sliding holds: 2 stacks of ~2 sqrt(W), plus work."""
        voxels = int(np.prod(self.series.volume_shape))
        per = {"alpha": 16, "first_hit": 20, "max": 24, "min": 24, "additive": 4}[self.spec.mode]
        extra = 24 * voxels if self.spec.mode == "additive" else 0  # fixed-point sums
        return (4 * block_size(selection.width) + 4) * per * voxels + extra

    def _reintegrate(self, selection: Selection) -> Chronovolume:
        return integrate(
            _ResidentSeries(self.series, self._arrays),
            selection,
            spec=self.spec,
            engine=self.engine,
        )


class _Slider:
    """The incremental state of one window under one spec (absolute positions)."""

    def __init__(self, session: Session, selection: Selection) -> None:
        self.session = session
        self.spec = session.spec
        self.selection = selection
        self.arrays: dict[int, np.ndarray] = {}
        self.value_range = prepare(session.series, selection, spec=self.spec).value_range
        mode = self.spec.mode
        # Leaves of additive are raw sums: finalisation happens once per window.
        self.leaf_spec = (
            dataclasses.replace(self.spec, normalize="max") if mode == "additive" else self.spec
        )
        # Callbacks through a weak proxy, so the slider and its aggregate form no cycle and a
        # dropped slider frees its partial volumes at once (no garbage collection needed).
        me = weakref.proxy(self)
        self.agg: SlidingAggregate[Partial] = SlidingAggregate(
            lambda step: me._agg_leaf(step), lambda a, b: me._op(a, b)
        )
        self.agg.reset(selection.steps)
        self.acc: np.ndarray | None = None  # additive: fixed-point colour sums (Z, Y, X, 3)
        self._full: dict[int, Partial] = {}

    @property
    def held(self) -> int:
        return self.agg.held

    def can_move_to(self, selection: Selection) -> bool:
        old, new = self.selection.steps, selection.steps
        if len(new) != len(old) or self.spec != self.session.spec:
            return False
        shift = new[0] - old[0]
        # A slide keeps the steps' spacing and overlaps the old window.
        return tuple(s + shift for s in old) == new and bool(set(old) & set(new))

    def move_to(self, selection: Selection, arrays: dict[int, np.ndarray]) -> Chronovolume:
        engine = self.session.engine
        self.arrays = arrays
        additive = self.spec.mode == "additive"
        if additive and self.acc is None:
            self.acc = np.zeros((*self.session.series.volume_shape, 3), np.int64)
            for s in self.selection.steps:
                engine.fixed_add(self.acc, self._leaf_full(s).rgba, +1)
                self._full.pop(s, None)
        old, new = self.selection.steps, selection.steps
        old_set, new_set = set(old), set(new)
        entering = [s for s in new if s not in old_set]
        leaving = [s for s in old if s not in new_set]
        forward = new[0] > old[0]
        for s in entering if forward else entering[::-1]:
            if additive:
                engine.fixed_add(self.acc, self._leaf_full(s).rgba, +1)
            if forward:
                self.agg.push_back(s)
            else:
                self.agg.push_front(s)
        for s in leaving if forward else leaving[::-1]:
            if additive:
                engine.fixed_add(self.acc, self._leaf_full(s).rgba, -1)
            if forward:
                self.agg.pop_front()
            else:
                self.agg.pop_back()
        self._full.clear()
        self.selection = selection
        return self._chronovolume()

    def _chronovolume(self) -> Chronovolume:
        session, spec = self.session, self.spec
        job = Job.of(session.series, self.selection, spec, self.value_range)
        value = self.agg.value()
        if spec.mode == "additive":
            if spec.normalize == "time":
                norm = reference.additive_norm(spec, job.positions)
            else:
                norm = np.full(3, float(self.acc.max()) / FIXED_ONE if self.acc.size else 0.0)
            rgba, t_index = session.engine.fixed_finalize(self.acc, value.rgba, norm), None
        else:
            rgba = np.asarray(value.rgba, dtype=np.float32)
            t_index = None if value.t_index is None else np.array(value.t_index, dtype=np.int32)
        name = getattr(session.engine, "name", type(session.engine).__name__)
        return Chronovolume(rgba, t_index, job.metadata(name))

    def _leaf_full(self, step: int) -> Partial:
        """One step integrated alone: its partial chronovolume (additive: raw sums)."""
        if step in self._full:
            return self._full[step]
        series = self.session.series
        array = self.arrays[step]
        brick = array[:, None]  # one step is a (Z, 1, Y, X) xytz brick without a copy
        positions = self.spec.time_tf.positions_of([step], series.n_steps)
        partial, _ = self.session.engine.accumulate(
            brick,
            slice(0, array.shape[0]),
            (step,),
            positions,
            np.zeros(1, np.int64),
            self.leaf_spec,
            self.value_range,
        )
        if self.spec.mode in ("max", "min"):
            partial.value = values.normalize(array, *self.value_range)
        if self.spec.mode == "additive":
            self._full[step] = partial
        return partial

    def _agg_leaf(self, step: int) -> Partial:
        full = self._leaf_full(step)
        self._full.pop(step, None)  # cached only for the push that follows a fixed_add
        if self.spec.mode == "additive":  # only the opacity (a maximum) slides
            alpha = aligned_empty(full.rgba.shape[:-1], np.float32)
            alpha[...] = full.rgba[..., 3]
            return Partial(alpha, None)
        return full

    def _op(self, earlier: Partial, later: Partial) -> Partial:
        engine, spec = self.session.engine, self.spec
        if spec.order == "backward":
            return engine.combine(later, earlier, spec)
        return engine.combine(earlier, later, spec)


class _ResidentSeries:
    """A TimeSeries whose bricks come from resident step arrays (re-integration reads nothing)."""

    def __init__(self, series: TimeSeries, arrays: dict[int, np.ndarray]) -> None:
        self._series = series
        self._arrays = arrays

    def __getattr__(self, name: str):
        return getattr(self._series, name)

    def read_brick(self, steps: Sequence[int], z0: int = 0, z1: int | None = None) -> np.ndarray:
        return stack_brick([self._arrays[int(s)] for s in steps], z0, z1)
