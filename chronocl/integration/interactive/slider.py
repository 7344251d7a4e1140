"""The incremental state of a session's window under one spec (absolute time positions).

A `Session` moves its window through a `Slider` when the new window overlaps the old one:
modes that slide by inversion add the entering and subtract the leaving steps' fixed-point
sums; the rest slide through a `SlidingAggregate` of partial chronovolumes (docs/window.md).
The slider is built from what it needs (the series, the engine, the spec, the window and its
value range) and knows nothing of the session. Its aggregate gets two plain functions at
construction: `Leaves.for_aggregate` (a step's partial, from the resident arrays) and
`Combine` (the engine's combine in the spec's order).

On an engine that copies bricks (a GPU) the state lives on the device between slides
(docs/window.md): the sums are a device array the fixed_add kernel updates in place, the
aggregate's partials device arrays the combine kernels make, and leaves are integrated from
the steps the session keeps on the device (`DeviceWindow`); only the finished chronovolume is
read back. Its bytes (`state_bytes`) are held from the device budget, and where they do not
fit, the state stays on the host as on a CPU device (whose kernels read host memory in place).
"""

from __future__ import annotations

import numpy as np

from chronocl.core.budget import human
from chronocl.core.interrupt import checkpoint
from chronocl.core.memory import recycled_empty
from chronocl.core.selection import Selection
from chronocl.data.bricks import ResidentBricks
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.engine.base import Engine
from chronocl.engine.buffers import max_alloc
from chronocl.engine.device_arrays import to_host, zeros
from chronocl.engine.device_leaves import alpha_of, leaf, leaf_value
from chronocl.engine.device_steps import reserve
from chronocl.integration.inmemory import DISPLAY_VOXELS, chronovolume_metadata, engine_name
from chronocl.integration.interactive.costs import Costs, Move
from chronocl.integration.interactive.sliding import SlidingAggregate, block_size
from chronocl.modes.base import FaintSums, Partial, Values
from chronocl.modes.spec import IntegrationSpec


class Combine:
    """`op(earlier, later)` of a sliding aggregate: the engine's combine, in the spec's order;
    `last`, the combine of the window's two ends into its value, which with `rgba8` the
    kernels write in the display format (RGBA8, by the rule the host converts a float32 frame
    with, so the same bytes): a quarter of the bytes written, read back from a device and
    converted by the viewer (render/upload.py `convert` took 70-80 ms for a 256^3 float32 frame
    on the 2 busy cores here, 2026-11-30)."""

    def __init__(
        self, engine: Engine, spec: IntegrationSpec, leaves: Leaves, rgba8: bool = False
    ) -> None:
        self.engine, self.spec, self.leaves = engine, spec, leaves  # `leaves` counts the pieces
        self.rgba8 = rgba8

    def __call__(self, earlier: Partial, later: Partial, rgba8: bool = False) -> Partial:
        self.leaves.tick()
        if self.spec.order == "backward":
            return self.engine.combine(later, earlier, self.spec, rgba8)
        return self.engine.combine(earlier, later, self.spec, rgba8)

    def last(self, earlier: Partial, later: Partial) -> Partial:
        return self(earlier, later, self.rgba8)


class Leaves:
    """The leaves of a window: each step integrated alone from the resident arrays.

    A leaf is one step, or for a mode whose leaves span several steps (change: a pair), the
    steps ending at it. Inverting modes get raw partials (sums to add and subtract).
    """

    def __init__(
        self,
        n_steps: int,
        engine: Engine,
        spec: IntegrationSpec,
        value_range: tuple,
        dc: object | None = None,
    ) -> None:
        self.n_steps, self.engine, self.spec = n_steps, engine, spec
        self.dc = dc  # the device context where the partials stay (None: on the host)
        self.device_bricks = None  # the steps on that device, where the session keeps them
        self.mode = spec.integration
        self.value_range = value_range
        self.inverts = self.mode.slides == "invert"
        # Read in place where the engine can and the steps lie in one block (the window
        # manager's slots), else stacked.
        self.bricks = ResidentBricks({}, in_place=engine.reads_in_place)
        self.before: dict[int, tuple[int, ...]] = {}  # leaf -> the earlier steps it spans
        self._full: dict[int, Partial] = {}
        self.pieces, self.total = 0, 0  # a slide's leaves and combines so far, and about all

    @property
    def arrays(self) -> dict[int, np.ndarray]:
        """step -> its resident (Z, Y, X) values, held by the bricks read from them alone: a
        copy kept elsewhere held the leaving steps after a slide, and they could not give way
        (`chronocl.data.window.WindowManager._held`)."""
        return self.bricks.arrays

    @arrays.setter
    def arrays(self, arrays: dict[int, np.ndarray]) -> None:
        self.bricks.arrays = arrays

    def tick(self) -> None:
        """Between two pieces of a slide (a leaf, a combine): given up here once newer input
        comes (`chronocl.core.interrupt`: a refine's slide, whose first fills the whole state;
        the session then integrates the window anew), and the refine's progress told."""
        checkpoint("sliding", min(self.pieces, self.total), self.total)
        self.pieces += 1

    def full(self, step: int) -> Partial:
        """The leaf ending at `step` integrated alone: its partial (inverting modes: raw)."""
        if step in self._full:
            return self._full[step]
        self.tick()
        steps = (*self.before.get(step, ()), step) if self.mode.leaf_span > 1 else (step,)
        arrays = [self.arrays[s] for s in steps]
        positions = self.spec.time_tf.positions_of(list(steps), self.n_steps)
        spec, value_range, dc = self.spec, self.value_range, self.dc
        if dc is not None:  # from the steps on the device, into device arrays
            brick = (self.device_bricks or self.bricks).read(steps)
            partial = leaf(self.engine, brick, steps, positions, spec, value_range, self.inverts)
        else:
            brick = self.bricks.read(steps)
            nz, order = arrays[0].shape[0], np.arange(len(steps))
            partial, _ = self.engine.accumulate(
                brick, slice(0, nz), steps, positions, order, spec, value_range, raw=self.inverts
            )
        if self.mode.compares_values and dc is not None:
            partial.value = leaf_value(dc, self.mode, brick, arrays, value_range)
        elif self.mode.compares_values:
            partial.value = self.mode.leaf_value(Values(np.stack(arrays), value_range))
        if self.inverts:
            self._full[step] = partial
        return partial

    def for_aggregate(self, step: int) -> Partial:
        """The leaf as the sliding aggregate holds it (inverting modes: its opacity only)."""
        full = self.full(step)
        self._full.pop(step, None)  # cached only for the push that follows a fixed_add
        if self.inverts and self.dc is not None:
            return Partial(alpha_of(self.dc, full.rgba), None)
        if self.inverts:  # only the aggregated opacity slides here
            alpha = recycled_empty(full.rgba.shape[:-1], np.float32)
            alpha[...] = full.rgba[..., 3]
            return Partial(alpha, None)
        return full

    def forget(self, step: int | None = None) -> None:
        """Drop the cached raw partial of `step` (default: of every step)."""
        if step is None:
            self._full.clear()
        else:
            self._full.pop(step, None)


class Slider:
    """The incremental state of one window under one spec (absolute positions).

    The sliding items are the steps that end a leaf. Modes that slide by inversion add and
    subtract their leaves' raw sums; the rest (and an inverting mode's aggregated opacity)
    slide through a `SlidingAggregate`.
    """

    def __init__(
        self,
        series: TimeSeries,
        engine: Engine,
        spec: IntegrationSpec,
        selection: Selection,
        value_range: tuple[float, float],
        device: object | None = None,
        display: bool = False,
    ) -> None:
        """`device`: the session's `DeviceWindow`, whose steps on the device the leaves are
        integrated from where the engine copies bricks; `display` (a viewer's session): the
        window's value comes in the display format where an integration's would
        (`integrate_bricks`) and the mode combines partials."""
        self.series, self.engine, self.spec = series, engine, spec
        self.mode = spec.integration
        self.selection = selection
        self.value_range = value_range
        self.device = device
        self.hold = None  # the device budget the state holds, from its first slide (`_place`)
        self.dc = None  # the device context the state lives on (None: the host)
        self.placed = False
        self.leaves = Leaves(series.n_steps, engine, spec, value_range)
        self.inverts = self.leaves.inverts
        self.agg: SlidingAggregate[Partial] | None = None
        voxels = int(np.prod(series.volume_shape))
        rgba8 = display and engine.writes_display and voxels > DISPLAY_VOXELS
        rgba8 = rgba8 and not self.inverts and not self.mode.finalize_is_global(spec)
        self.combine = Combine(engine, spec, self.leaves, rgba8)
        if not self.inverts or self.mode.state_bytes:
            self.agg = SlidingAggregate(self.leaves.for_aggregate, self.combine)
            self.agg.reset(self._items(selection))
        self.acc = None  # inverting modes: fixed-point sums (Z, Y, X, C), host or device
        # The last move's window was too faint to finish from its sums (`FaintSums`): the
        # session integrated it, and predicts the next move as an integration too.
        self.faint = False

    def _place(self) -> None:
        """Where the state lives, decided at the first slide (a window only edited holds no
        device memory): an engine that copies bricks keeps it on its device where the device
        budget has room for it."""
        engine, self.placed = self.engine, True
        if not engine.copies_to_device:
            return
        voxels = int(np.prod(self.series.volume_shape))
        # each of its arrays is one device buffer (a partial's RGBA, 16 bytes a voxel; the
        # sums, 8 a channel): where one is over the device's largest, the state stays here
        if voxels * max(16, 8 * self.mode.sum_channels) > max_alloc(engine.dc):
            return
        self.hold = reserve(engine.dc, state_bytes(self.mode, self.selection.width, voxels))
        if self.hold is not None:
            self.dc = self.leaves.dc = engine.dc

    @property
    def held(self) -> int:
        return 0 if self.agg is None else self.agg.held

    def _items(self, selection: Selection) -> tuple[int, ...]:
        return selection.steps[self.mode.leaf_span - 1 :]

    def can_move_to(self, selection: Selection) -> bool:
        return slides_to(self.selection, selection)

    def move_to(self, selection: Selection, arrays: dict[int, np.ndarray]) -> Chronovolume:
        """The chronovolume of `selection`, from the old window's state and `arrays` (the
        resident steps of both windows)."""
        engine, leaves = self.engine, self.leaves
        if not self.placed:
            self._place()
        leaves.arrays = arrays
        leaves.pieces, leaves.total = 0, 2 * selection.width  # a first slide fills the state
        if self.dc is not None and self.device is not None:  # None: leaves from the host
            leaves.device_bricks = self.device.bricks(arrays, selection.width)
        old_items = self._items(self.selection)
        # Leaves spanning several steps find their earlier steps in the window they are in.
        span = self.mode.leaf_span
        leaves.before = {
            steps[i]: steps[i - span + 1 : i]
            for steps in (self.selection.steps, selection.steps)
            for i in range(span - 1, len(steps))
        }
        if self.inverts and self.acc is None:
            shape = (*self.series.volume_shape, self.mode.sum_channels)
            self.acc = np.zeros(shape, np.int64) if self.dc is None else zeros(self.dc, shape, "i8")
            for s in old_items:
                engine.fixed_add(self.acc, leaves.full(s).rgba, +1)
                leaves.forget(s)
        old, new = old_items, self._items(selection)
        old_set, new_set = set(old), set(new)
        entering = [s for s in new if s not in old_set]
        leaving = [s for s in old if s not in new_set]
        forward = selection.steps[0] > self.selection.steps[0]
        if self.inverts:  # the leaving steps first: on a device they are still in their slots
            for s in leaving:
                engine.fixed_add(self.acc, leaves.full(s).rgba, -1)
                leaves.forget(s)
        # The leaving steps leave the aggregate before the entering ones enter: the partials
        # popped die first, and their memory makes the new ones (`recycled_empty`). Pushed
        # first, a 256^3 slide's combine after the state's fill mapped a fresh 256 MB partial:
        # 480-670 ms on the 2 busy cores here against 20 ms on a spare (bench/slide_window.py).
        for _ in leaving:
            if self.agg is not None:
                self.agg.pop_front() if forward else self.agg.pop_back()
        for s in entering if forward else entering[::-1]:
            if self.inverts:
                engine.fixed_add(self.acc, leaves.full(s).rgba, +1)
            if self.agg is not None:
                self.agg.push_back(s) if forward else self.agg.push_front(s)
        leaves.forget()
        self.selection = selection
        try:
            cv = self._chronovolume()
        except FaintSums:  # too faint to finish from its sums: the state, moved, holds
            self.faint = True
            raise
        finally:
            if leaves.device_bricks is not None:
                leaves.device_bricks.slots.touch(selection.steps)
            leaves.arrays, leaves.device_bricks = {}, None  # the leaving steps' slots free
        self.faint = False
        return cv

    def _chronovolume(self) -> Chronovolume:
        series, spec, selection = self.series, self.spec, self.selection
        shape = series.volume_shape
        value = None
        if self.agg is not None and self.agg.steps:
            value = self.agg.value(self.combine.last)
        if self.inverts:
            alpha = None if value is None else value.rgba
            positions = spec.time_tf.positions_of(selection.steps, series.n_steps)
            rgba, t_index = self.engine.finish_sums(self.acc, alpha, positions, spec), None
        elif value is None:  # no leaf in the window (change over one step): nothing changed
            rgba = np.zeros((*shape, 4), np.float32)
            t_index = np.full(shape, -1, np.int32) if spec.has_t_index else None
        elif self.dc is not None:  # read back: the one transfer of a slide on the device
            rgba, t_index = to_host(self.dc, value.rgba), to_host(self.dc, value.t_index)
        else:  # RGBA8 (`Combine.last`) or float32, as it is
            rgba = (
                value.rgba if value.rgba.dtype == np.uint8 else np.asarray(value.rgba, np.float32)
            )
            t_index = None if value.t_index is None else np.array(value.t_index, dtype=np.int32)
        meta = chronovolume_metadata(
            series, selection, spec, self.value_range, engine_name(self.engine)
        )
        return Chronovolume(rgba, t_index, meta)


def slides_to(old: Selection, new: Selection) -> bool:
    """Whether moving from window `old` to `new` is a slide: as many steps, some in both, and
    those at the old window's end and the new one's start (forward) or the reverse, so that
    steps leave the state at one end and enter at the other. A list of unevenly spaced steps
    moved on, [0, 1, 2, 9] -> [1, 2, 3, 10], is not one: 9 would lie between entering steps."""
    a, b = old.steps, new.steps
    both = len(set(a) & set(b))
    if len(a) != len(b) or not both:
        return False
    return a[len(a) - both :] == b[:both] or a[:both] == b[len(b) - both :]


def state_bytes(mode, width: int, voxels: int) -> int:
    """Bytes of the state sliding a window of `width` steps over `voxels` voxels holds: the
    partials its stacks keep (every B-th level of each, the top two of the one pushed onto and
    the B below the top of the one popped: at most ceil(W / B) + B + 2, and never more than W;
    counted over random walks both ways in tests/test_costs.py), 4 in hand (a leaf, the level
    under it, their combine, the window's value), and the fixed-point sums."""
    b = block_size(width)
    held = min(width, -(-width // b) + b + 2) if mode.combines() else 0
    partials = (held + 4) * mode.state_bytes * voxels
    return partials + 8 * mode.sum_channels * voxels


def slide_plan(
    spec: IntegrationSpec,
    voxels: int,
    width: int,
    window: int,
    budget: int,
    costs: Costs | None = None,
    move: Move | None = None,
) -> tuple[str | None, bool, int]:
    """How a session's budget splits for a window of `width` steps over `voxels` voxels, whose
    steps take `window` bytes: why it does not slide incrementally (None: it does); whether its
    stacked brick is kept for the next spec change (when it fits beside the steps and the
    sliding state); and the bytes of the state sliding holds (`state_bytes`). With `costs`
    (a viewer's: the rates measured on this machine, `costs.Costs`), a `move` (`costs.Move`:
    its level, the steps entering, ...) whose slide is predicted to cost more than integrating
    the window again is integrated instead; where the window is read in place, sliding pays only
    for long windows (docs/window.md). Without `costs`, every window that can slide does."""
    mode = spec.integration
    state = state_bytes(mode, width, voxels)
    keep = 2 * window + state <= budget
    # a slide by sums reads the steps leaving too (it takes them out), beside the window's
    held = window + (window // width * move.shift if move and mode.slides == "invert" else 0)
    reason = None
    if spec.time_tf.positions != "absolute":
        reason = "relative time positions recolour every step on a slide"
    elif not isinstance(spec.order, str):
        reason = "importance orders are not sliding windows"
    elif held + state > budget:
        reason = f"window and sliding state need {human(held + state)} > budget {human(budget)}"
    elif costs is not None:
        move = (move or Move())._replace(inverts=slides_by_sums(spec))
        reason = costs.why_not(voxels, width, move)
    return reason, keep, state


def slides_by_sums(spec: IntegrationSpec) -> bool:
    """Whether `spec`'s mode slides by its sums alone, adding the entering steps and taking out
    the leaving ones (`costs.Move.inverts`), not through an aggregate of partials."""
    mode = spec.integration
    return mode.slides == "invert" and not mode.combines()
