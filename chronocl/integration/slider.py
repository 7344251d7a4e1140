"""The incremental state of a session's window under one spec (absolute time positions).

`chronocl.integration.session.Session` moves its window through a `Slider` when the new
window overlaps the old one: modes that slide by inversion add the entering and subtract
the leaving steps' fixed-point sums; the rest slide through a `SlidingAggregate` of
partial chronovolumes (docs/window.md).
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING

import numpy as np

from chronocl.core.memory import aligned_empty
from chronocl.core.selection import Selection
from chronocl.data.chronovolume import Chronovolume
from chronocl.integration.inmemory import Job, prepare
from chronocl.integration.sliding import SlidingAggregate
from chronocl.modes.base import Values
from chronocl.reference import Partial

if TYPE_CHECKING:
    from chronocl.integration.session import Session


class Slider:
    """The incremental state of one window under one spec (absolute positions).

    A leaf is one step integrated alone, or for a mode whose leaves span several steps
    (change: a pair), the steps ending at it; the sliding items are the steps that end a
    leaf. Modes that slide by inversion add and subtract their leaves' raw sums; the rest
    (and an inverting mode's aggregated opacity) slide through a `SlidingAggregate`.
    """

    def __init__(self, session: Session, selection: Selection) -> None:
        self.session = session
        self.spec = session.spec
        self.mode = self.spec.integration
        self.selection = selection
        self.arrays: dict[int, np.ndarray] = {}
        self.value_range = prepare(session.series, selection, spec=self.spec).value_range
        self.inverts = self.mode.slides == "invert"
        # Callbacks through a weak proxy, so the slider and its aggregate form no cycle and a
        # dropped slider frees its partial volumes at once (no garbage collection needed).
        me = weakref.proxy(self)
        self.agg: SlidingAggregate[Partial] | None = None
        if not self.inverts or self.mode.state_bytes:
            self.agg = SlidingAggregate(lambda s: me._agg_leaf(s), lambda a, b: me._op(a, b))
            self.agg.reset(self._items(selection))
        self.acc: np.ndarray | None = None  # inverting modes: fixed-point sums (Z, Y, X, C)
        self._full: dict[int, Partial] = {}
        self._before: dict[int, tuple[int, ...]] = {}  # leaf -> the earlier steps it spans

    @property
    def held(self) -> int:
        return 0 if self.agg is None else self.agg.held

    def _items(self, selection: Selection) -> tuple[int, ...]:
        return selection.steps[self.mode.leaf_span - 1 :]

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
        old_items = self._items(self.selection)
        # Leaves spanning several steps find their earlier steps in the window they are in.
        self._before = {**self._before_of(self.selection), **self._before_of(selection)}
        if self.inverts and self.acc is None:
            shape = (*self.session.series.volume_shape, self.mode.sum_channels)
            self.acc = np.zeros(shape, np.int64)
            for s in old_items:
                engine.fixed_add(self.acc, self._leaf_full(s).rgba, +1)
                self._full.pop(s, None)
        old, new = old_items, self._items(selection)
        old_set, new_set = set(old), set(new)
        entering = [s for s in new if s not in old_set]
        leaving = [s for s in old if s not in new_set]
        forward = selection.steps[0] > self.selection.steps[0]
        for s in entering if forward else entering[::-1]:
            if self.inverts:
                engine.fixed_add(self.acc, self._leaf_full(s).rgba, +1)
            if self.agg is not None:
                self.agg.push_back(s) if forward else self.agg.push_front(s)
        for s in leaving if forward else leaving[::-1]:
            if self.inverts:
                engine.fixed_add(self.acc, self._leaf_full(s).rgba, -1)
            if self.agg is not None:
                self.agg.pop_front() if forward else self.agg.pop_back()
        self._full.clear()
        self.selection = selection
        return self._chronovolume()

    def _before_of(self, selection: Selection) -> dict[int, tuple[int, ...]]:
        span, steps = self.mode.leaf_span, selection.steps
        return {steps[i]: steps[i - span + 1 : i] for i in range(span - 1, len(steps))}

    def _chronovolume(self) -> Chronovolume:
        session, spec = self.session, self.spec
        job = Job.of(session.series, self.selection, spec, self.value_range)
        shape = session.series.volume_shape
        value = None
        if self.agg is not None and self.agg.steps:
            value = self.agg.value()
        if self.inverts:
            alpha = None if value is None else value.rgba
            rgba, t_index = session.engine.finish_sums(self.acc, alpha, job.positions, spec), None
        elif value is None:  # no leaf in the window (change over one step): nothing changed
            rgba = np.zeros((*shape, 4), np.float32)
            t_index = np.full(shape, -1, np.int32) if spec.has_t_index else None
        else:
            rgba = np.asarray(value.rgba, dtype=np.float32)
            t_index = None if value.t_index is None else np.array(value.t_index, dtype=np.int32)
        name = getattr(session.engine, "name", type(session.engine).__name__)
        return Chronovolume(rgba, t_index, job.metadata(name))

    def _leaf_full(self, step: int) -> Partial:
        """The leaf ending at `step` integrated alone: its partial (inverting modes: raw)."""
        if step in self._full:
            return self._full[step]
        series = self.session.series
        steps = (*self._before.get(step, ()), step) if self.mode.leaf_span > 1 else (step,)
        arrays = [self.arrays[s] for s in steps]
        # One step is a (Z, 1, Y, X) xytz brick without a copy.
        brick = arrays[0][:, None] if len(arrays) == 1 else np.stack(arrays, axis=1)
        positions = self.spec.time_tf.positions_of(list(steps), series.n_steps)
        partial, _ = self.session.engine.accumulate(
            brick,
            slice(0, arrays[0].shape[0]),
            steps,
            positions,
            np.arange(len(steps)),
            self.spec,
            self.value_range,
            raw=self.inverts,
        )
        if self.mode.compares_values:
            partial.value = self.mode.leaf_value(Values(np.stack(arrays), self.value_range))
        if self.inverts:
            self._full[step] = partial
        return partial

    def _agg_leaf(self, step: int) -> Partial:
        full = self._leaf_full(step)
        self._full.pop(step, None)  # cached only for the push that follows a fixed_add
        if self.inverts:  # only the aggregated opacity slides here
            alpha = aligned_empty(full.rgba.shape[:-1], np.float32)
            alpha[...] = full.rgba[..., 3]
            return Partial(alpha, None)
        return full

    def _op(self, earlier: Partial, later: Partial) -> Partial:
        engine, spec = self.session.engine, self.spec
        if spec.order == "backward":
            return engine.combine(later, earlier, spec)
        return engine.combine(earlier, later, spec)
