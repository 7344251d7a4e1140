"""Choices made from measured rates (`chronocl.integration.interactive.costs`): whether a window
slides or is integrated again, and whether coarse frames read full resolution's steps ahead.
The decisions are pure (fed numbers here); a viewer's session on small data slides a long
window incrementally where its rates say so (its stats say which path each frame took) and
the slid chronovolume equals integrating the window from scratch."""

from __future__ import annotations

import random

import numpy as np
import pytest

import chronocl
from chronocl.core.tf import TimeTF
from chronocl.core.tuning import TUNING
from chronocl.integration.inmemory import make_spec
from chronocl.integration.interactive import costs
from chronocl.integration.interactive.costs import (
    INVERT_PIECES,
    ONE_STEP,
    SLIDE_PIECES,
    Costs,
    Move,
)
from chronocl.integration.interactive.moves import slid
from chronocl.integration.interactive.session import LatencyModel
from chronocl.integration.interactive.slider import slide_plan, state_bytes
from chronocl.integration.interactive.sliding import SlidingAggregate, block_size
from chronocl.modes import get as get_mode

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

V = 1_000_000  # voxels


# -- slide or integrate ---------------------------------------------------------------------


def test_nothing_measured_slides_as_a_library_session_does():
    assert Costs().why_not(V, 50) is None


def _measured(d: float, s: float, f: float, inverts: bool = False) -> Costs:
    """Rates in ms per voxel-step integrated (d), per voxel of a steady slide (s) and per
    voxel-step of a fill (f), as the sessions feed them (`inverts`: of a mode sliding by sums)."""
    c = Costs()
    c.record_direct(0, ms=d * V * 10, voxels=V, steps=10)
    c.record_slide(0, ms=f * V * 30, voxels=V, fill=30, inverts=inverts)
    c.record_slide(0, ms=s * V, voxels=V, inverts=inverts)
    return c


def test_measured_rates_set_the_width_from_which_a_slide_pays():
    """A filled state slides while s < d W, whatever the voxels; a state still to be filled
    costs its whole fill besides, less the rent its window's integrated slides have paid
    (what each cost over a steady slide, in steps integrated): it is kept once that rent
    reaches the fill."""
    c = _measured(d=1e-6, s=20e-6, f=30e-6)  # at V voxels, in ms: d V = 1, a slide 20, fill 30 W
    for voxels in (V, 8 * V):
        k = voxels / V
        assert c.why_not(voxels, 21, Move(filled=True)) is None
        why = c.why_not(voxels, 19, Move(filled=True))
        assert why and "cheaper to integrate" in why and "(measured)" in why
        why = c.why_not(voxels, 50)  # a jump's first slide: the whole fill, 1500 ms
        assert why and "(measured, its state's fill included: " in why
        assert f"{1500 * k:.0f} ms, 0 ms of it paid by integrating since the jump" in why
        assert c.rent(voxels, 50) == pytest.approx(30)  # integrated: 50 steps over a slide's 20
        assert c.why_not(voxels, 50, Move(rent=1469)) is not None
        assert c.why_not(voxels, 50, Move(rent=1471)) is None  # 20 + 29 < 50
        why = c.why_not(voxels, 50, Move(rent=1469))
        assert f"{1500 * k:.0f} ms, {1469 * k:.0f} ms of it paid by integrating since" in why
        over = c.why_not(voxels, 50, Move(rent=3000, shift=5))  # 5 steps: dearer than integrating
        assert f"{1500 * k:.0f} ms, {1500 * k:.0f} ms of it paid" in over  # the fill, not more
    # the rent is kept in steps integrated: on a machine grown busier (d from 1 to 2 ns) a
    # step paid is worth as much of the fill as before
    busier = _measured(d=1e-6, s=20e-6, f=30e-6)
    busier.direct[0] = 2e-6
    assert "3000 ms, 2938 ms of it paid" in busier.why_not(V, 50, Move(rent=1469))
    direct, slide, measured = c.predict(V, 60, Move(rent=100))
    assert measured and direct == pytest.approx(60.0) and slide == pytest.approx(20 + 1800 - 100)
    # the frame that fills the state takes the whole fill, whatever the rent paid
    assert c.slide_ms(V, 60, Move(rent=100)) == pytest.approx(20 + 1800)
    # a slide of several steps costs as many times a steady one
    assert c.why_not(V, 50, Move(shift=3, filled=True)) is not None
    assert c.rent(V, 50, Move(shift=3)) == 0  # no dearer integrated than slid: pays no rent


def _slide_that_keeps_a_state(c: Costs, width: int, move: Move = ONE_STEP) -> int | None:
    """Which one-step slide after a jump, integrated with its own rent paid, keeps a state, as
    a viewer's session decides (`LevelSession._move`); the next one fills it (None: none of
    the first 1000)."""
    for n in range(1, 1000):
        move = move._replace(rent=move.rent + c.rent(V, width, move))
        if c.why_not(V, width, move) is None:
            return n
    return None


def test_a_state_is_filled_after_integrating_slides_that_cost_as_much_as_its_fill():
    """Ski rental: after a jump, a window's one-step slides are integrated until what they cost
    over steady slides reaches the state's fill, about `f W / (W - s)` slides; so a user who
    slides twice never waits for a fill that pays after fifty, and one who scrubs on pays
    about twice at most what knowing the moves to come would have cost."""
    c = _measured(d=1e-6, s=20e-6, f=31e-6)  # in ms: a slide 20, the fill 31 W
    assert _slide_that_keeps_a_state(c, 50) == 51  # the fill 1550, less 30 a slide, < 50 - 20
    assert _slide_that_keeps_a_state(c, 100) == 38  # 3100 ms, 80 a slide
    assert _slide_that_keeps_a_state(c, 20) is None  # a slide no cheaper than integrating: never
    # where the steps travel for every integration, fill and slide guessed at one voxel-step:
    # the first slide keeps a state, the second fills it
    guessed = Costs()
    guessed.record_direct(0, ms=1.0, voxels=V, steps=1)
    assert _slide_that_keeps_a_state(guessed, 10, Move(travels=True)) == 1


def test_a_gpu_and_a_cpu_find_their_own_threshold():
    """The same decision code, two machines: one whose integration is cheap per voxel-step
    beside its slides (a window read in place) integrates a 28-step window and fills a state
    for a 50-step one only after 46 of its slides; one where every integration pays for the
    whole window's transfer slides a 10-step one after one."""
    cpu = _measured(d=7e-6, s=200e-6, f=140e-6)  # a filled state slides from 29 steps
    gpu = _measured(d=15e-6, s=20e-6, f=15e-6)  # the steps sent up every time: from 2
    assert cpu.why_not(V, 28, Move(filled=True)) and cpu.why_not(V, 30, Move(filled=True)) is None
    assert gpu.why_not(V, 1, Move(filled=True)) and gpu.why_not(V, 2, Move(filled=True)) is None
    assert _slide_that_keeps_a_state(cpu, 10) is None
    assert _slide_that_keeps_a_state(cpu, 50) == 46
    assert _slide_that_keeps_a_state(gpu, 10) == 1


def test_unmeasured_slides_and_fills_are_guessed_from_the_integration():
    """Before a slide is timed, it is guessed at TUNING.slide_steps voxel-steps and a fill at
    TUNING.fill_steps a step; where the steps travel for every integration, both at one voxel-step
    (the transfer, which a slide pays for its entering step alone); a mode sliding by sums
    alone at its fewer pieces. The first slide measures the fill, the next ones a slide."""
    c = Costs()
    c.record_direct(0, ms=1.0, voxels=V, steps=1)
    s, f = TUNING.slide_steps, TUNING.fill_steps
    assert c.why_not(V, int(s) + 1, Move(filled=True)) is None
    assert "not measured yet" in c.why_not(V, int(s) - 1, Move(filled=True))
    width = int(s) + 12
    per = width - s  # the rent each integrated slide pays, in steps integrated
    keeps = (s + f * width - width) / per  # the state is kept by the first slide past it
    assert keeps != int(keeps)  # not a tie, which rounding would decide
    assert _slide_that_keeps_a_state(c, width) == int(keeps) + 1
    assert "not measured yet" in c.why_not(V, width)
    assert (
        c.why_not(V, 3, Move(travels=True))
        and c.why_not(V, 3, Move(travels=True, rent=2.5)) is None
    )
    inverting = s * INVERT_PIECES / SLIDE_PIECES
    assert c.why_not(V, int(inverting) + 1, Move(inverts=True, filled=True)) is None
    # the fill measured dear: a state is started after more integrated slides than guessed
    c.record_slide(0, ms=100 * f * 1e-6 * V * 20, voxels=V, fill=20)
    assert _slide_that_keeps_a_state(c, width) is None
    assert c.why_not(V, width, Move(filled=True)) is None  # a filled one slides on


def test_steady_slides_are_averaged_over_the_splits_period():
    """s is the mean of the last TUNING.slide_memory slides: a split of the stacks (tens of pieces
    at once) counts at its share, not as the new rate."""
    c = _measured(d=1e-6, s=10e-6, f=10e-6)
    for _ in range(20):
        c.record_slide(0, ms=10e-6 * V, voxels=V)
    c.record_slide(0, ms=400e-6 * V, voxels=V)  # a split
    assert c.slide[0, False] < 40  # in voxel-steps of integration
    assert c.why_not(V, 40, Move(filled=True)) is None  # one split does not drop the state
    slower = Costs()
    slower.record_direct(0, ms=1e-6 * V, voxels=V, steps=1)
    for k in range(3 * TUNING.slide_memory):  # slides getting dearer are followed
        slower.record_slide(0, ms=(1 if k < TUNING.slide_memory else 100) * V * 1e-6, voxels=V)
    assert slower.slide[0, False] > 50


def test_a_slide_timed_while_the_machine_was_busy_is_weighed_by_the_integration_then():
    """Slides and fills are kept in units of the integration rate measured around them: load
    that slowed a slide and the integrations beside it (4x here) is gone when the integrations
    are fast again, and the same window slides (in ms, the busy slide decided for good: an
    integrated window measures no slide). Nothing integrated yet: a slide is not kept."""
    c = _measured(d=4e-6, s=80e-6, f=60e-6)  # busy: s = 20 d, f = 15 d
    c.record_direct(0, ms=1e-6 * V, voxels=V, steps=1)
    c.record_direct(0, ms=1e-6 * V, voxels=V, steps=1)
    c.record_direct(0, ms=1e-6 * V, voxels=V, steps=1)
    assert c.direct[0] < 1.5e-6
    _, slide, measured = c.predict(V, 50)
    assert measured and slide == pytest.approx((20 + 15 * 50) * c.direct[0] * V)
    assert c.why_not(V, 21, Move(filled=True)) is None
    assert c.why_not(V, 19, Move(filled=True)) is not None
    fresh = Costs()
    fresh.record_slide(0, ms=1.0, voxels=V)
    assert not fresh.slide and fresh.predict(V, 50) is None


def test_rates_are_per_level_and_follow_the_machine():
    c = Costs()
    c.record_direct(2, ms=1.0, voxels=1000, steps=10)
    assert c.predict(V, 10) is None and c.why_not(V, 10) is None
    c.record_direct(0, ms=10.0, voxels=V, steps=10)
    c.record_direct(0, ms=30.0, voxels=V, steps=10)  # busier: the running rate moves
    assert c.direct[0] == pytest.approx(2e-6)


def test_each_kind_of_slide_is_measured_apart(monkeypatch):
    """A mode sliding by its sums (mean: the entering and the leaving step, two pieces) and one
    sliding through the aggregate (max: about seven pieces a slide) keep their own slide and
    fill rates: after mean's cheap slides, max's slide is still predicted from the guess (they
    shared one rate per level, so a switch to max took mean's rate for its own)."""
    c = Costs()
    c.record_direct(0, ms=1e-6 * V * 10, voxels=V, steps=10)
    c.record_slide(0, ms=0.1e-6 * V * 10, voxels=V, fill=10, inverts=True)
    c.record_slide(0, ms=0.1e-6 * V, voxels=V, inverts=True)
    _, slide, measured = c.predict(V, 10, Move(filled=True, inverts=True))
    assert measured and slide == pytest.approx(0.1e-6 * V)
    _, slide, measured = c.predict(V, 10, Move(filled=True))
    assert not measured and slide == pytest.approx(TUNING.slide_steps * 1e-6 * V)
    # a session feeds its mode's kind: mean's slides by sums, max's through the aggregate
    data = np.random.default_rng(2).random((12, 4, 6, 21), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    monkeypatch.setattr(TUNING, "slide_steps", 0.01)  # guessed cheap: the first slides slide
    monkeypatch.setattr(TUNING, "fill_steps", 0.01)
    fed = Costs()
    absolute = TimeTF.preset("rgb", positions="absolute")
    for mode in ("mean", "max"):
        with chronocl.Session(series, mode=mode, time_tf=absolute, slide_costs=fed) as session:
            session.set_window(0, 6)
            session.slide(1)
            session.slide(1)
            assert session.stats["path"] == "incremental"
    assert set(fed.slide) == set(fed.fill) == {(0, True), (0, False)}


def test_slide_plan_asks_the_costs_only_where_a_slide_is_possible():
    spec = make_spec("alpha", time_tf=TimeTF.preset("rgb", positions="absolute"))
    c = _measured(d=1e-6, s=1e-3, f=1e-3)
    reason, _, _ = slide_plan(spec, V, 10, 10 * 4 * V, 2**40, c)
    assert reason and "cheaper to integrate" in reason
    assert slide_plan(spec, V, 10, 10 * 4 * V, 2**40)[0] is None  # no costs: it slides
    relative = make_spec("alpha", time_tf=TimeTF.preset("rgb"))
    assert "relative" in slide_plan(relative, V, 10, 10 * 4 * V, 2**40, c)[0]
    mean = make_spec("mean", time_tf=TimeTF.preset("rgb", positions="absolute"))
    cheap = _measured(d=1e-6, s=1e-9, f=1e-9, inverts=True)  # mean slides by its sums
    assert slide_plan(mean, V, 10, 10 * 4 * V, 2**40, cheap, Move(level=0))[0] is None


def test_slide_pieces_and_the_states_bound_are_what_the_aggregate_does():
    """SLIDE_PIECES is the count of a steady one-step slide's leaves and combines (splits
    amortised); `state_bytes` bounds the partials the stacks hold over random walks both ways
    (plus 4 in hand): ceil(W / B) + B + 2, the stack pushed onto keeping its top two levels
    and only the one popped the B below its top (both kept B: 22 at W = 50, over this bound's
    17)."""
    rng = random.Random(1)
    for width in (1, 2, 5, 10, 16, 50, 64):
        agg = SlidingAggregate(lambda s: s, lambda a, b: a + b)
        lo = 1000
        agg.reset(range(lo, lo + width))
        agg.value()
        worst = agg.held
        for _ in range(300):
            if rng.random() < 0.5:
                agg.push_back(lo + width)
                agg.pop_front()
                lo += 1
            else:
                agg.push_front(lo - 1)
                agg.pop_back()
                lo -= 1
            if rng.random() < 0.3:
                agg.value()
            worst = max(worst, agg.held)
        before = agg.leaves + agg.combines
        for _ in range(200):  # steady forward
            agg.push_back(lo + width)
            agg.pop_front()
            lo += 1
            agg.value()
            worst = max(worst, agg.held)
        pieces = (agg.leaves + agg.combines - before) / 200
        if width >= 10:
            assert abs(pieces - SLIDE_PIECES) <= 1.6, (width, pieces)
        alpha = get_mode("alpha")
        bound = state_bytes(alpha, width, 1) // alpha.state_bytes - 4
        assert worst <= bound, (width, worst, bound)
        b = block_size(width)
        assert bound <= min(width, -(-width // b) + b + 2)


def test_a_level_that_slides_is_predicted_at_its_slide_not_its_windows_integration():
    """A level policy predicts a level whose session slides to the window from the slide's ms
    (`Costs.slide_ms`: steady, or with its state's whole fill), not from integrating the
    window: a 50-step window whose full resolution slides in 20 ms is drawn there at once, not
    first coarse (128^3 through the viewer: 158 ms for the sharp frame, two frames, where the
    slide took 13). A slide's time teaches the policy nothing of integrating."""
    model = LatencyModel([V, V // 8], target_ms=150)
    model.costs.record_direct(0, 500.0, model.voxels[0], 50)
    model.costs.record_direct(1, 60.0, model.voxels[1], 50)
    assert model.pick(50)[0] == 1
    level, why = model.pick(50, slides=lambda level: 20.0 if level == 0 else None)
    assert level == 0 and "predicted at 20 ms" in why
    c = _measured(d=1e-6, s=20e-6, f=30e-6)  # in voxel-steps: 20 a slide, 30 a step's fill
    assert c.slide_ms(V, 50, Move(filled=True)) == pytest.approx(20.0)
    assert c.slide_ms(V, 50) == pytest.approx(20.0 + 30.0 * 50)
    # through a session: its slides are not recorded as integrations
    data = np.random.default_rng(5).random((30, 8, 16, 80), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    assert series.n_levels > 1
    absolute = TimeTF.preset("rgb", positions="absolute")
    rates = Costs()
    with chronocl.Session(
        series, level="auto", mode="alpha", time_tf=absolute, slide_costs=rates
    ) as session:
        session.set_window(0, 20)
        session.refine()
        before = dict(session.costs.direct)
        session.at(0).costs.slide = {(0, False): 1e-6}  # measured cheap: level 0 slides
        session.at(0).costs.fill = {(0, False): 1e-6}
        predicted = session._slide_ms(0, slid(session.window(), 1, 30), session.spec)
        assert predicted is not None and predicted < 1.0
        session.slide(1)
        assert session.stats["level"] == 0 and session.stats["path"] == "incremental"
        assert session.costs.direct.get(0) == before.get(0)


# -- read ahead or not ----------------------------------------------------------------------


def _read(cores: int, read_ms: float | None = 200.0) -> Costs:
    """Costs on `cores` cores where a full-resolution step of `V` voxels reads in `read_ms`."""
    c = Costs(cores=cores)
    if read_ms is not None:
        c.record_read(0, read_ms / 1e3, V)
    return c


def test_read_ahead_where_the_frames_leave_a_core_idle():
    two = _read(2)
    assert two.why_not_read_ahead(10, V, 150.0) == "nothing measured yet"
    two.record_frame(wall_s=0.1, cpu_s=0.19)  # a CPU device: both cores busy
    assert "1.9 of 2 cores" in two.why_not_read_ahead(10, V, 150.0)
    gpu = _read(2)
    gpu.record_frame(wall_s=0.1, cpu_s=0.03)  # a GPU integrates: the host mostly idle
    assert gpu.why_not_read_ahead(10, V, 150.0) is None
    many = _read(16)
    many.record_frame(wall_s=0.1, cpu_s=0.8)  # 8 of 16 busy
    assert many.why_not_read_ahead(10, V, 150.0) is None


def test_no_read_ahead_where_reading_at_the_stop_is_cheap_or_nothing_is_missing():
    r = _read(16, 10.0)
    r.record_frame(wall_s=0.1, cpu_s=0.1)
    assert "takes 100 ms" in r.why_not_read_ahead(10, V, 150.0)
    assert r.why_not_read_ahead(0, V, 150.0) == "every step of the window is resident"
    unread = _read(16, None)
    unread.record_frame(wall_s=0.1, cpu_s=0.1)
    assert unread.why_not_read_ahead(1, V, 150.0) == "nothing measured yet"


def test_read_ahead_counts_the_cores_this_process_may_use():
    assert 1 <= costs.cores_here() <= (__import__("os").cpu_count() or 1)
    assert Costs().cores == costs.cores_here()


# -- a viewer's session ---------------------------------------------------------------------


class _Fixed(Costs):
    """A viewer's slide costs at fixed rates (a machine where a long window slides: the
    rates measured on this one would decide otherwise at this small size): `direct` in ms per
    voxel-step, `slide` (and the fill) in voxel-steps of it; what the sessions time is still
    fed to it, and kept."""

    def __init__(self, direct: float, slide: float, fill: float | None = None) -> None:
        super().__init__()
        self.rates = direct, slide, slide if fill is None else fill
        self.fed: list[tuple[str, int]] = []
        self._reset()

    def _reset(self) -> None:
        self.direct = {lv: self.rates[0] for lv in range(4)}
        self.slide = {(lv, k): self.rates[1] for lv in range(4) for k in (False, True)}
        self.fill = {(lv, k): self.rates[2] for lv in range(4) for k in (False, True)}

    def record_direct(self, level, ms, voxels, steps) -> None:
        self.fed.append(("direct", level))
        self._reset()

    def record_slide(self, level, ms, voxels, steps=1, fill=0, inverts=False) -> None:
        self.fed.append(("fill" if fill else "slide", level))
        self._reset()


@pytest.mark.parametrize("mode", ["alpha", "max", "additive"])
def test_a_viewers_long_window_slides_incrementally_and_equals_the_direct_integration(mode):
    """Views (the viewer's sessions) over a small series: a 40-step window where sliding is
    cheaper slides incrementally at full resolution (the session's stats say so, and the
    frame's `incremental`), and each slid chronovolume equals integrating its window from
    scratch (1e-5 and t_index exactly, as docs/semantics.md invariant 6 promises); where
    integrating is cheaper, the same slides integrate and say why."""
    from chronocl.viewer.datasets import Dataset
    from chronocl.viewer.view_sessions import Views
    from chronocl.viewer.view_state import default_state, merge

    rng = np.random.default_rng(4)
    data = rng.random((48, 6, 7, 9), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    absolute = {"positions": "absolute"}
    n = series.n_steps
    for slide, path in ((1e-6, "incremental"), (1e3, "reintegrate")):
        views = Views([Dataset("d", series)], "opencl", None, "1GB")
        views.slide_costs = rates = _Fixed(direct=1e-3, slide=slide)
        try:
            state = default_state(0, series)
            time_tf = {**state.time_tf, **absolute}
            state = merge(state, {"views": [{"mode": mode, "order": "forward"}]}, n)
            state = merge(state, {"time_tf": time_tf, "window": {"t0": 0, "t1": 40}}, n)
            views.chronovolumes(state)
            views.full_resolution(range(1))  # the window at level 0 (the refine)
            for t0 in (1, 2, 3, 2):
                state = merge(state, {"window": {"t0": t0, "t1": t0 + 40}}, n)
                _, _, incremental = views.chronovolumes(state)
                views.full_resolution(range(1))
                slot = views.slots[0]
                full = slot.session.at(0)
                assert slot.session.shown_level == 0
                assert full.stats["path"] == path, full.stats
                assert (full.stats["why_not_incremental"] is None) == (path == "incremental")
                if slot.session.stats["level"] == 0 and path == "incremental":
                    assert incremental  # the frame's timings say so where level 0 answered
                ref = chronocl.integrate(series, f"{t0}:{t0 + 40}", spec=full.spec)
                got = slot.cv
                assert got.steps == ref.steps
                rgba = got.rgba if got.rgba.dtype == np.float32 else got.rgba / 255.0
                tol = 1e-5 if got.rgba.dtype == np.float32 else 0.5 / 255 + 1e-6
                np.testing.assert_allclose(rgba, ref.rgba, rtol=0, atol=tol)
                if ref.t_index is not None:
                    np.testing.assert_array_equal(got.t_index, ref.t_index)
            if path == "reintegrate":
                assert "cheaper to integrate" in full.stats["why_not_incremental"]
            assert {("fill", 0), ("slide", 0)} <= set(rates.fed) or path == "reintegrate"
            assert ("direct", 0) in rates.fed
        finally:
            views.release()


def _renting(seed: int):
    """A viewer's session over 60 random steps at rates where a 20-step window's fill (10
    voxel-steps a step: 200) pays after 13 integrated one-step slides (each 20 - 5 over a
    slide's 5), its series, and a step of integration in ms."""
    data = np.random.default_rng(seed).random((60, 6, 7, 9), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    absolute = TimeTF.preset("rgb", positions="absolute")
    rates = _Fixed(direct=1e-3, slide=5.0, fill=10.0)
    session = chronocl.Session(series, mode="alpha", time_tf=absolute, slide_costs=rates)
    return session, series, 1e-3 * int(np.prod(series.volume_shape))


def _give_up_once(monkeypatch, owner: object, name: str) -> None:
    """`owner.name` raises SupersededError (newer input came) on its next call, then is itself
    again."""
    from chronocl.core.errors import SupersededError

    real = getattr(owner, name)

    def given_up(*args, **kwargs):
        monkeypatch.setattr(owner, name, real)
        raise SupersededError("newer input came")

    monkeypatch.setattr(owner, name, given_up)


def test_a_session_integrates_its_slides_until_they_paid_for_the_fill_and_a_jump_starts_again():
    """A viewer's session at rates where a 20-step window's fill (10 voxel-steps a step: 200)
    pays after 13 integrated one-step slides (each 20 - 5 over a slide's 5): the first 12
    integrate and say how much of the fill they paid, their own share included; the 13th
    integrates and keeps a state, the 14th fills it and slides, and the next ones slide; a
    jump integrates and pays nothing. Every chronovolume equals integrating its window."""
    session, series, ms = _renting(6)
    paths, paid = [], []
    with session:
        session.set_window(0, 20)
        for t0 in range(1, 17):
            cv = session.set_window(t0, t0 + 20)
            paths.append(session.stats["path"])
            why = session.stats["why_not_incremental"] or ""
            paid.append(why.split("ms of it paid")[0].rsplit(", ", 1)[-1].strip() if why else None)
            ref = chronocl.integrate(series, f"{t0}:{t0 + 20}", spec=session.spec)
            np.testing.assert_allclose(cv.rgba, ref.rgba, rtol=0, atol=1e-5)
        assert paths == ["reintegrate"] * 13 + ["incremental"] * 3, paths
        assert paid[:12] == [f"{15 * ms * k:.0f}" for k in range(1, 13)], paid
        assert paid[12:] == [None] * 4  # kept a state; filled it; slid twice
        session.set_window(38, 58)  # a jump: integrated, and the rent starts again
        for t0, rent in ((39, 15 * ms), (40, 30 * ms), (0, 0)):  # the last a jump: pays none
            session.set_window(t0, t0 + 20)
            why = session.stats["why_not_incremental"]
            assert session.stats["path"] == "reintegrate"
            assert f", {rent:.0f} ms of it paid by integrating since the jump" in why, why


def test_a_jump_given_up_pays_its_window_no_rent_of_the_one_before(monkeypatch):
    """The rent is the jumped-to window's from the moment it is asked for: a jump whose
    integration is given up for newer input (a refine's) leaves none of the old window's rent,
    so the next slide pays its own share alone."""
    from chronocl.core.errors import SupersededError
    from chronocl.integration.interactive import level_session

    session, _, ms = _renting(7)
    with session:
        for t0 in range(6):
            session.set_window(t0, t0 + 20)
        assert f", {75 * ms:.0f} ms of it paid" in session.stats["why_not_incremental"]
        _give_up_once(monkeypatch, level_session, "integrate_bricks")
        with pytest.raises(SupersededError):
            session.set_window(30, 50)
        session.set_window(31, 51)
        assert session.stats["path"] == "reintegrate"
        assert f", {15 * ms:.0f} ms of it paid" in session.stats["why_not_incremental"]


def test_a_fill_given_up_or_a_jump_seen_in_passing_starts_the_rent_again(monkeypatch):
    """A fill given up for newer input bought nothing: the rent starts again, so a scrub does
    not start a fill on every frame it gives up; a jump a level only hears of (`leaving`: the
    frames between drawn at another level) starts it again too."""
    from chronocl.core.errors import SupersededError
    from chronocl.core.selection import parse_selection
    from chronocl.integration.interactive.slider import Slider

    session, series, ms = _renting(8)  # a state kept on the 13th slide
    with session:
        for t0 in range(14):
            session.set_window(t0, t0 + 20)
        assert session.stats["path"] == "reintegrate" and not session.stats["why_not_incremental"]
        _give_up_once(monkeypatch, Slider, "move_to")
        with pytest.raises(SupersededError):
            session.set_window(14, 34)  # the fill, given up
        for t0, paid in ((15, 15 * ms), (16, 30 * ms)):
            session.set_window(t0, t0 + 20)
            assert session.stats["path"] == "reintegrate"
            assert f", {paid:.0f} ms of it paid" in session.stats["why_not_incremental"]
        session.leaving(parse_selection("40:60", series.n_steps))  # drawn elsewhere
        session.set_window(17, 37)
        assert f", {15 * ms:.0f} ms of it paid" in session.stats["why_not_incremental"]


def test_a_window_shown_again_through_its_state_measures_no_slide():
    """A viewer announces a window (`leaving`) that newer input replaces before it is drawn, and
    the window shown comes back: the state shows it again, a move of no step, which once was
    kept as a one-step slide at its whole ms (sliding then predicted voxels times dearer: off
    for good). It equals integrating the window, and the rates measured stay as they were."""
    from chronocl.integration.interactive.moves import slid

    data = np.random.default_rng(4).random((20, 4, 5, 6), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    absolute = TimeTF.preset("rgb", positions="absolute")
    with chronocl.Session(series, mode="alpha", time_tf=absolute) as session:
        session.set_window(0, 8)
        session.slide(1)  # fills the state
        session.slide(1)
        assert session.stats["path"] == "incremental"
        costs = session.at(0).costs
        measured = dict(costs.slide)
        shown = session.selection
        session.leaving(slid(shown, 1, series.n_steps))
        cv = session.current()
        assert session.selection == shown and session.stats["path"] == "incremental"
        assert costs.slide == measured
        ref = chronocl.integrate(series, shown, spec=session.spec)
        np.testing.assert_allclose(cv.rgba, ref.rgba, rtol=0, atol=1e-5)


def test_a_closed_session_says_so_and_reads_nothing():
    """A session used after its `with` block raises at once, not quietly making a new window
    manager whose readers nothing closes; closing again is fine."""
    import threading

    from chronocl.core.errors import InvalidParameterError

    series = chronocl.TimeSeries.from_array(np.zeros((6, 2, 3, 4), np.float32))
    with chronocl.Session(series, mode="max") as session:
        session.set_window(0, 3)
    readers = {t for t in threading.enumerate() if "window" in t.name}
    with pytest.raises(InvalidParameterError, match="closed; make a new one"):
        session.slide(1)
    assert {t for t in threading.enumerate() if "window" in t.name} <= readers
    session.close()


@pytest.mark.parametrize("mode", ["alpha", "mean"])
def test_a_slide_holds_its_window_and_state_within_the_memory_given(mode):
    """Memory for the window and its sliding state exactly: a slide of k steps holds no more.
    An aggregate's leaving steps are only dropped from it, so they give way to the entering
    ones before these are read; a slide by sums reads both (it takes the leaving out), so it
    slides where the budget holds k steps more, and integrates where not (it held W + k)."""
    from chronocl import modes
    from chronocl.integration.interactive.slider import state_bytes

    width, shape = 10, (8, 16, 16)
    data = np.random.default_rng(2).random((30, *shape), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    absolute = TimeTF.preset("rgb", positions="absolute")
    step, voxels = data[0].nbytes, int(np.prod(shape))
    state = state_bytes(modes.get(mode), width, voxels)
    for k, more in [(1, 0), (3, 0), (3, 3)]:
        memory = (width + more) * step + state
        with chronocl.Session(series, mode=mode, time_tf=absolute, memory=memory) as session:
            session.set_window(0, width)
            cv = session.slide(k)
            path, why = session.stats["path"], session.stats["why_not_incremental"]
            if mode == "mean" and k > more:
                assert path == "reintegrate" and "window and sliding state need" in why, why
            else:
                assert path == "incremental", why
            held = len(session.manager.resident()) * step + (state if path != "reintegrate" else 0)
            assert held <= memory, (k, more, path)
            ref = chronocl.integrate(series, session.selection, spec=session.spec)
            np.testing.assert_allclose(cv.rgba, ref.rgba, rtol=0, atol=1e-5)


def test_a_slide_by_sums_holds_no_stacked_brick_of_the_window_it_leaves(monkeypatch):
    """An engine that stacks the window's steps (numpy here; a GPU) keeps the stacked brick for
    a spec change where it fits beside the window and the state; a slide leaves it stale, and
    lets go of it before reading: kept, a slide by sums held it beside the window and the
    steps leaving (2W + k steps and the sums, over the 2W + k - 1 given)."""
    from chronocl import modes
    from chronocl.integration.interactive import slider
    from chronocl.integration.interactive.slider import state_bytes

    width, k, shape = 10, 3, (8, 16, 16)
    data = np.random.default_rng(2).random((30, *shape), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    absolute = TimeTF.preset("rgb", positions="absolute")
    step, state = data[0].nbytes, state_bytes(modes.get("mean"), width, int(np.prod(shape)))
    memory = (2 * width + k - 1) * step + state  # keeps the brick; slides k steps
    held: list[int] = []
    real = slider.Slider.move_to

    def move_to(self, selection, arrays):
        kept = session.at(0)._bricks._kept
        held.append(sum(a.nbytes for a in arrays.values()) + (kept[1].nbytes if kept else 0))
        return real(self, selection, arrays)

    monkeypatch.setattr(slider.Slider, "move_to", move_to)
    with chronocl.Session(
        series, engine="numpy", mode="mean", time_tf=absolute, memory=memory
    ) as session:
        session.set_window(0, width)
        cv = session.slide(k)
        assert session.stats["path"] == "incremental" and len(held) == 1
        assert held[0] + state <= memory, (held[0] + state) / memory
        ref = chronocl.integrate(series, session.selection, spec=session.spec, engine="numpy")
        np.testing.assert_allclose(cv.rgba, ref.rgba, rtol=0, atol=1e-5)


def test_views_sliding_one_window_read_no_step_beside_those_leaving():
    """A viewer's panels share one manager: every view is told the next window (`leaving`)
    before any shows it. An aggregate's steps leaving go then, so the first view's entering
    steps do not come in beside the second's leaving ones (13 steps held for 10)."""
    from chronocl.core.selection import Selection
    from chronocl.data.window import WindowManager

    width, k, shape = 10, 3, (8, 16, 16)
    data = np.random.default_rng(2).random((30, *shape), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    step = data[0].nbytes
    manager = WindowManager(series, width * step, prefetch=0)  # room for the window exactly
    opts = {"time_tf": TimeTF.preset("rgb", positions="absolute"), "memory": "64MB"}
    views = [
        chronocl.Session(series, mode=mode, managers={(0, ""): manager}, **opts)
        for mode in ("alpha", "max")
    ]
    try:
        for view in views:
            view.set_window(0, width)
        for view in views:
            view.slide(1)  # the states filled: they slide from now on
        after = Selection(tuple(range(1 + k, 1 + k + width)), series.n_steps)
        for view in views:
            view.leaving(after)
        for view in views:
            cv = view.show(after)
            assert view.stats["path"] == "incremental"
            assert len(manager.resident()) <= width
            ref = chronocl.integrate(series, after, spec=view.spec)
            np.testing.assert_allclose(cv.rgba, ref.rgba, rtol=0, atol=1e-5)
    finally:
        for view in views:
            view.close()
        manager.close()
