"""Sliding windows: incremental chronovolumes equal integrating the same window from scratch.

Invariant 6 of docs/semantics.md, for every registered mode and both engines: after any
random sequence of slides (either way, by one or more strides) and jumps, the Session's
chronovolume equals `integrate` of the same window (1e-5; t_index exactly), windows of 1..40
steps. Also the
double-ended sliding aggregate on its own, with a non-commutative operation.
"""

from __future__ import annotations

import gc
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from chronocl import modes
from chronocl.core.errors import InvalidSelectionError
from chronocl.core.tf import TimeTF
from chronocl.data.series import TimeSeries
from chronocl.integration.inmemory import integrate, make_spec
from chronocl.integration.interactive.costs import Costs
from chronocl.integration.interactive.moves import slid
from chronocl.integration.interactive.session import Session
from chronocl.integration.interactive.sliding import SlidingAggregate

from .strategies import examples, specs

# Drawn transfer functions and data are often transparent on purpose; the warnings saying so
# (chronocl.integration.visibility) are tested in test_visibility.py.
pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

ENGINES = ["numpy", "opencl"]
RGB = TimeTF.preset("rgb", positions="absolute")  # (relative positions never slide)


def _series(rng: np.random.Generator, t: int, shape: tuple[int, int, int], levels: bool):
    data = rng.random((t, *shape), dtype=np.float32)
    if levels:  # exact ties: first_hit thresholds and max/min tie-breaking
        data = (np.round(data * 4) / 4).astype(np.float32)
    return TimeSeries.from_array(data)


def _check(cv, series, selection, spec, engine) -> None:
    ref = integrate(series, selection, spec=spec, engine=engine)
    assert cv.steps == tuple(selection.steps)
    np.testing.assert_allclose(cv.rgba, ref.rgba, rtol=0, atol=1e-5)
    if spec.has_t_index:
        np.testing.assert_array_equal(cv.t_index, ref.t_index)
    else:
        assert cv.t_index is None


@pytest.mark.parametrize("mode", modes.names())
@pytest.mark.parametrize("engine", ENGINES)
@settings(max_examples=examples(4))
@given(data=st.data())
def test_slides_and_jumps_equal_scratch(engine: str, mode: str, data) -> None:
    """Every registered mode: any walk of slides and jumps, W in 1..40, equals integrating
    each window from scratch."""
    shape = data.draw(st.tuples(st.integers(1, 4), st.integers(1, 3), st.integers(1, 40)))
    width = data.draw(st.integers(1, 40))
    n_steps = data.draw(st.integers(width, width + 12))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    series = _series(rng, n_steps, shape, data.draw(st.booleans()))
    spec = data.draw(specs(mode=mode, positions="absolute"))
    session = Session(series, engine=engine, spec=spec, memory="64MB")
    t0 = data.draw(st.integers(0, n_steps - width))
    cv = session.set_window(t0, t0 + width)
    _check(cv, series, session.selection, session.spec, engine)
    for _ in range(data.draw(st.integers(1, 10))):
        if data.draw(st.integers(0, 4)) == 0:  # a jump anywhere
            t0 = data.draw(st.integers(0, n_steps - width))
            cv = session.set_window(t0, t0 + width)
        else:
            before = session.selection
            k = data.draw(st.sampled_from([-3, -2, -1, 1, 2, 3]))
            cv = session.slide(k)
            moved = session.selection != before
            overlap = set(before.steps) & set(session.selection.steps)
            if moved and overlap:  # (or integrated: too faint to finish from its sums)
                why = session.stats["why_not_incremental"] or ""
                assert session.stats["path"] == "incremental" or "too faint" in why, why
        _check(cv, series, session.selection, session.spec, engine)
    session.close()


@pytest.mark.parametrize("mode", modes.names())
@pytest.mark.parametrize("engine", ENGINES)
@settings(max_examples=examples(4))
@given(data=st.data())
def test_windows_listed_step_by_step_equal_scratch(engine: str, mode: str, data) -> None:
    """Every registered mode: windows given as lists of unevenly spaced steps, each the last
    one with steps left out at one end and others added at the other (a slide), or moved on
    as a whole (steps leaving from the middle: integrated), equal integrating each from
    scratch. [0, 1, 2, 9] -> [1, 2, 3, 10] once kept 9 between the entering steps."""
    shape = data.draw(st.tuples(st.integers(1, 3), st.integers(1, 3), st.integers(1, 17)))
    n_steps = data.draw(st.integers(4, 24))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    series = _series(rng, n_steps, shape, data.draw(st.booleans()))
    spec = data.draw(specs(mode=mode, positions="absolute"))
    some = st.lists(st.integers(0, n_steps - 1), min_size=2, max_size=n_steps, unique=True)
    steps = sorted(data.draw(some))
    with Session(series, engine=engine, spec=spec, memory="64MB") as session:
        cv = session.set_window(steps)
        _check(cv, series, session.selection, session.spec, engine)
        for _ in range(data.draw(st.integers(1, 6))):
            k = data.draw(st.integers(1, len(steps) - 1))
            if data.draw(st.booleans()):  # all moved by one: no slide where unevenly spaced
                moved = [s + 1 for s in steps] if steps[-1] + 1 < n_steps else steps
            elif data.draw(st.booleans()):  # k leave at the start, k after the end enter
                after = list(range(steps[-1] + 1, n_steps))
                moved = steps[k:] + after[:k] if len(after) >= k else steps
            else:  # k leave at the end, k before the start enter
                moved = list(range(steps[0]))[-k:] + steps[:-k] if steps[0] >= k else steps
            even = len(set(np.diff(steps))) == 1
            ends = moved[: len(steps) - k] == steps[k:] or moved[k:] == steps[: len(steps) - k]
            cv = session.set_window(moved)
            path, why = session.stats["path"], session.stats["why_not_incremental"] or ""
            if moved != steps and not even and moved == [s + 1 for s in steps]:
                assert path == "reintegrate", (steps, moved)
            elif moved != steps and ends:  # (or integrated: too faint to finish from its sums)
                assert path == "incremental" or "too faint" in why, (steps, moved, why)
            steps = moved
            _check(cv, series, session.selection, session.spec, engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_window_too_faint_for_its_sums_is_integrated(engine: str) -> None:
    """additive normalised by "max" shows each colour sum over the largest: a window whose
    sums are all but zero (here a data TF of colour 1e-20, opaque) would finish from its
    fixed-point sums as black, or coarse, where its integration is bright. Such a slide is
    integrated instead, says why, and the next bright window slides again."""
    from chronocl.core.tf import DataTF

    rng = np.random.default_rng(5)
    series = _series(rng, 12, (3, 4, 9), levels=False)
    faint = DataTF(points=((0.0, 0.0, 0.0, 1e-20, 1.0), (1.0, 0.0, 0.0, 1e-20, 1.0)))
    spec = make_spec("additive", data_tf=faint, normalize="max", time_tf=RGB)

    def predicted(session: Session) -> float | None:
        """The next one-step slide's ms as a viewer's session predicts it, slides measured
        cheap (costs given for the question alone: the session's own choose nothing)."""
        at = session.stats["level"]
        level, cheap = session.at(at), Costs()
        cheap.slide = {(at, False): 1e-6, (at, True): 1e-6}  # measured cheap: it would slide
        cheap.fill, cheap.direct = dict(cheap.slide), {at: 1e-3}
        kept, level.costs, level.weighs_slides = level.costs, cheap, True
        try:
            return level.slide_ms(slid(session.selection, 1, 12), session.spec)
        finally:
            level.costs, level.weighs_slides = kept, False

    with Session(series, engine=engine, spec=spec, memory="64MB") as session:
        session.set_window(0, 5)
        cv = session.slide(1)
        assert session.stats["path"] == "reintegrate"
        assert "too faint to slide" in session.stats["why_not_incremental"]
        _check(cv, series, session.selection, session.spec, engine)
        assert cv.rgba[..., 2].max() > 0.5  # bright, as integrated
        assert session.stats["held_partials"] > 0  # the state, moved, is kept
        assert predicted(session) is None  # not a slide alone: a slide and an integration
        cv = session.slide(1)
        assert "too faint to slide" in session.stats["why_not_incremental"]
        _check(cv, series, session.selection, session.spec, engine)
        session.set_spec(make_spec("additive", normalize="max", time_tf=RGB))
        session.slide(1)
        cv = session.slide(1)
        assert session.stats["path"] == "incremental"
        _check(cv, series, session.selection, session.spec, engine)
        assert predicted(session) is not None


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("mode", modes.names())
def test_strided_windows_slide_by_strides(engine: str, mode: str) -> None:
    rng = np.random.default_rng(7)
    series = _series(rng, 60, (3, 5, 21), levels=True)
    spec = make_spec(mode, time_tf=TimeTF.preset("warm-cool", positions="absolute"), threshold=0.3)
    with Session(series, engine=engine, spec=spec) as session:
        session.set_window("4:40:3")
        for k in (1, 1, 2, -1, -3, 5):
            cv = session.slide(k)
            assert session.stats["path"] == "incremental"
            assert np.all(np.diff(cv.steps) == 3)
            _check(cv, series, session.selection, session.spec, engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_relative_positions_and_importance_order_reintegrate(engine: str) -> None:
    rng = np.random.default_rng(3)
    series = _series(rng, 20, (2, 3, 17), levels=False)
    with Session(series, engine=engine, mode="alpha", time_tf="rgb") as session:
        session.set_window(2, 9)
        cv = session.slide(1)
        assert session.stats["path"] == "reintegrate"
        assert "relative" in session.stats["why_not_incremental"]
        _check(cv, series, session.selection, session.spec, engine)
        order = (5, 3, 9, 4, 8, 6, 7)
        cv = session.set_spec(order=order)
        _check(cv, series, session.selection, session.spec, engine)


class _Rates(Costs):
    """Slide costs at fixed rates (ms per voxel-step integrated, per voxel of a slide and per
    voxel-step of a fill): the session's own timings are not learnt, so the choice does not
    depend on the machine."""

    def __init__(self, direct: float, slide: float) -> None:
        super().__init__()
        kinds = {(0, False): slide, (0, True): slide}  # through the aggregate, by sums
        self.direct, self.slide, self.fill = {0: direct}, dict(kinds), dict(kinds)
        self.fed: list[str] = []

    def record_direct(self, level, ms, voxels, steps) -> None:
        self.fed.append("direct")

    def record_slide(self, level, ms, voxels, steps=1, fill=0, inverts=False) -> None:
        assert steps > 0
        self.fed.append("fill" if fill else "slide")


@pytest.mark.parametrize("mode", ["alpha", "additive"])
def test_a_window_cheaper_to_integrate_than_to_slide_is_integrated_on_a_slide(mode) -> None:
    """`slide_costs` (the viewer's): where the measured rates predict integrating the window
    cheaper than sliding it, a slide integrates it (no sliding state to fill, no partials to
    combine), and says why; where sliding is cheaper it slides. Both equal the reference, and
    the session feeds the rates what it timed."""
    rng = np.random.default_rng(11)
    series = _series(rng, 16, (3, 5, 19), levels=False)
    absolute = TimeTF.preset("rgb", positions="absolute")
    # a 7-step window: 7 voxel-steps integrated against a slide (and its fill's share)
    for slide, path in ((100.0, "reintegrate"), (0.01, "incremental")):
        rates = _Rates(1.0, slide)
        with Session(series, mode=mode, time_tf=absolute, slide_costs=rates) as s:
            s.set_window(2, 9)
            for k in (1, 1, -2, 3):
                cv = s.slide(k)
                assert s.stats["path"] == path
                _check(cv, series, s.selection, s.spec, "opencl")
            why = s.stats["why_not_incremental"]
            assert (why is None) == (path == "incremental")
            assert path == "incremental" or "cheaper to integrate" in why
            assert s.stats["held_partials"] == 0 or path == "incremental"
        fed = {"reintegrate": {"direct"}, "incremental": {"direct", "fill", "slide"}}[path]
        assert rates.fed[0] == "direct" and set(rates.fed) == fed


def test_spec_changes_and_slides_read_each_step_once() -> None:
    rng = np.random.default_rng(5)
    series = _series(rng, 30, (4, 4, 16), levels=False)
    absolute = TimeTF.preset("rgb", positions="absolute")
    with Session(series, engine="opencl", mode="max", time_tf=absolute, memory="64MB") as s:
        s.set_window(0, 8)
        for _ in range(10):
            s.slide(1)
        s.set_spec(mode="alpha")
        for _ in range(10):
            s.slide(-1)
        assert s.stats["path"] == "incremental"
        assert max(s.manager.reads.values()) == 1  # the budget holds every step touched


def test_slide_clamps_at_both_ends() -> None:
    series = _series(np.random.default_rng(1), 10, (2, 2, 3), levels=False)
    with Session(series, engine="numpy", mode="additive") as s:
        s.set_window(6, 9)
        assert s.slide(5).steps == (7, 8, 9)
        assert s.slide(-20).steps == (0, 1, 2)
        with pytest.raises(InvalidSelectionError):
            s.set_window(5, 12)


def test_window_larger_than_budget_is_streamed_by_slabs() -> None:
    series = _series(np.random.default_rng(1), 12, (8, 32, 32), levels=False)  # 32 KB steps
    with Session(series, engine="numpy", mode="max", memory="100KB") as s:
        cv = s.set_window(0, 10)  # 320 KB: z-slabs read from the series, nothing resident
        assert s.stats["path"] == "streamed" and "budget" in s.stats["why_not_incremental"]
        _check(cv, series, s.selection, s.spec, "numpy")


def test_sliding_state_is_charged_to_the_budget() -> None:
    series = _series(np.random.default_rng(2), 40, (8, 32, 32), levels=False)
    absolute = TimeTF.preset("rgb", positions="absolute")
    # 16 steps fit (512 KB) but not the partial volumes sliding would hold: re-integrate.
    with Session(series, engine="numpy", mode="alpha", time_tf=absolute, memory="1MB") as s:
        s.set_window(0, 16)
        cv = s.slide(1)
        assert s.stats["path"] == "reintegrate"
        assert "budget" in s.stats["why_not_incremental"]
        _check(cv, series, s.selection, s.spec, "numpy")


@settings(max_examples=examples(200))
@given(st.integers(1, 40), st.lists(st.sampled_from(["f", "b", "grow", "shrink"]), max_size=80))
def test_sliding_aggregate_both_ways(width: int, ops: list[str]) -> None:
    """Concatenation is associative but not commutative: any slip in order shows."""
    agg = SlidingAggregate(lambda s: (s,), lambda a, b: a + b)
    window = list(range(100, 100 + width))
    agg.reset(window)
    most = 0
    for op in ops:
        if op == "f":
            window.append(window[-1] + 1)
            agg.push_back(window[-1])
            assert agg.pop_front() == window.pop(0)
        elif op == "b":
            window.insert(0, window[0] - 1)
            agg.push_front(window[0])
            assert agg.pop_back() == window.pop()
        elif op == "grow":
            window.append(window[-1] + 1)
            agg.push_back(window[-1])
        elif len(window) > 1:
            assert agg.pop_front() == window.pop(0)
        assert agg.steps == window
        assert agg.value() == tuple(window)
        most = max(most, agg.held)
    bound = 4 * math.isqrt(len(window) + len(ops)) + 8
    assert most <= bound


def test_sliding_aggregate_cost_does_not_grow_with_width() -> None:
    per_slide = {}
    for width in (8, 64):
        agg = SlidingAggregate(lambda s: (s,), lambda a, b: a + b)
        agg.reset(range(width))
        agg.value()
        leaves, combines = agg.leaves, agg.combines
        for s in range(width, width + 640):
            agg.push_back(s)
            agg.pop_front()
            agg.value()
        per_slide[width] = ((agg.leaves - leaves) / 640, (agg.combines - combines) / 640)
    assert per_slide[64][0] <= 4 and per_slide[64][1] <= 5
    assert per_slide[64][0] <= 1.5 * per_slide[8][0]


@settings(max_examples=examples(40))
@given(data=st.data())
def test_combine_kernels_match_the_reference(data) -> None:
    """Each mode's combine kernel against its reference combine on random partials (ties and
    misses included); modes that slide by inversion combine their aggregated opacity."""
    from chronocl.engine import NumpyEngine, get_engine
    from chronocl.modes.base import Partial

    engine = get_engine("opencl")
    shape = data.draw(st.tuples(st.integers(1, 3), st.integers(1, 3), st.integers(1, 37)))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    names = [
        m for m in modes.names() if modes.get(m).slides == "aggregate" or modes.get(m).state_bytes
    ]
    mode = data.draw(st.sampled_from(names))
    spec = make_spec(mode)
    kind = modes.get(mode)

    def partial() -> Partial:
        a = rng.random((*shape, 1), dtype=np.float32)
        rgba = np.concatenate([rng.random((*shape, 3), dtype=np.float32) * a, a], axis=-1)
        t = rng.integers(-1, 9, shape).astype(np.int32)
        v = (np.round(rng.random(shape) * 3) / 3).astype(np.float32)  # ties
        if kind.slides == "invert":
            return Partial(np.ascontiguousarray(rgba[..., 3]), None)
        return Partial(rgba, t if kind.has_t_index else None, v if kind.compares_values else None)

    front, back = partial(), partial()
    got = engine.combine(front, back, spec)
    want = NumpyEngine().combine(front, back, spec)
    np.testing.assert_allclose(got.rgba, want.rgba, rtol=0, atol=1e-6)
    if spec.has_t_index:
        np.testing.assert_array_equal(got.t_index, want.t_index)
    if kind.compares_values:
        np.testing.assert_array_equal(got.value, want.value)


@pytest.mark.parametrize("mode", [m for m in modes.names() if modes.get(m).slides == "invert"])
@settings(max_examples=examples(15))
@given(data=st.data())
def test_fixed_point_sums_cancel_exactly(mode, data) -> None:
    """Adding then subtracting the same steps returns the sums to exactly zero, and both
    engines finish the same sums alike (each inverting mode)."""
    from chronocl.engine import NumpyEngine, get_engine

    kind = modes.get(mode)
    spec = make_spec(mode, normalize=data.draw(st.sampled_from(["time", "max"])))
    shape = data.draw(st.tuples(st.integers(1, 3), st.integers(1, 3), st.integers(1, 37)))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    steps = [rng.random((*shape, 4), dtype=np.float32) for _ in range(data.draw(st.integers(1, 9)))]
    alpha = rng.random(shape, dtype=np.float32) if kind.state_bytes else None
    positions = np.linspace(0, 1, len(steps))
    c = kind.sum_channels
    results = []
    for engine in (get_engine("opencl"), NumpyEngine()):
        acc = np.zeros((*shape, c), np.int64)
        for s in steps:
            engine.fixed_add(acc, s, +1)
        sums = acc.copy()
        results.append(engine.finish_sums(acc, alpha, positions, spec))
        for s in steps[::-1]:
            engine.fixed_add(acc, s, -1)
        assert not acc.any()
        np.testing.assert_allclose(
            sums / 2.0**40, sum(s[..., :c].astype(np.float64) for s in steps), atol=1e-9
        )
    np.testing.assert_allclose(results[0], results[1], rtol=0, atol=1e-6)


@pytest.mark.parametrize("level", [0, "auto"])
@pytest.mark.parametrize("display", [False, True])
@pytest.mark.parametrize("mode", ["alpha", "max", "first_hit", "change"])
def test_a_chronovolume_kept_across_edits_is_unchanged(mode: str, display: bool, level) -> None:
    """A chronovolume handed out is the holder's: TF edits (which recolour a max, first_hit or
    change window from its winners), a mode switch, slides and a jump back to its window all
    make new arrays and never write into the one kept, on every path that hands one out
    (float32 or the display format, one level or chosen per frame). Its bytes are compared
    after a collection, so memory recycled from dead outputs (`recycled_empty`) would show."""
    rng = np.random.default_rng(23)
    # The longest axis 70 gives a coarse level (35) for "auto" to show first.
    series = TimeSeries.from_array(rng.random((14, 5, 9, 70), dtype=np.float32))
    with Session(series, mode=mode, display=display, level=level, memory="64MB") as s:
        kept = s.set_window(3, 9)
        rgba = kept.rgba.copy()
        t_index = None if kept.t_index is None else kept.t_index.copy()
        edits = [
            lambda: s.set_spec(time_tf=TimeTF.preset("rgb", positions="absolute")),
            lambda: s.set_spec(time_tf=TimeTF.preset("rgb")),
            lambda: s.set_spec(mode="alpha" if mode != "alpha" else "max"),
            lambda: s.set_spec(mode=mode),
            lambda: s.slide(1),
            lambda: s.slide(2),
            lambda: s.set_window(3, 9),
        ]
        for edit in edits:
            other = edit()
            if level == "auto":
                other = s.refine() or other
            assert other.rgba is not kept.rgba
            assert not np.shares_memory(other.rgba, kept.rgba)
            gc.collect()
        np.testing.assert_array_equal(kept.rgba, rgba)
        if t_index is not None:
            np.testing.assert_array_equal(kept.t_index, t_index)
