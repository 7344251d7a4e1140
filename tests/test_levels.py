"""Integrating coarse levels: `integrate(level=)`, fixed-level sessions and level="auto"
(a coarse frame first, refined to exactly the full-resolution chronovolume)."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

import chronocl
from chronocl import modes
from chronocl.core.errors import ChronoclError, InvalidParameterError
from chronocl.core.tf import TimeTF
from chronocl.core.tuning import TUNING
from chronocl.data import synthetic
from chronocl.integration.interactive.costs import Costs
from chronocl.integration.interactive.session import LatencyModel, Session
from chronocl.modes.spec import IntegrationSpec

# Drawn transfer functions and data are often transparent on purpose; the warnings saying so
# (chronocl.integration.visibility) are tested in test_visibility.py.
pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

# Odd sizes: the longest axis 130 gives levels 1 (65) and 2 (33).
SHAPE = (20, 18, 130)


@pytest.fixture(scope="module")
def series() -> chronocl.TimeSeries:
    data = np.stack(list(synthetic.steps("vortex", 8, SHAPE)))
    return chronocl.TimeSeries.from_array(data, spacing=(2.0, 1.0, 0.5), source="vortex")


def extent(cv) -> np.ndarray:
    return np.array(cv.dims) * np.array(cv.spacing)


@pytest.mark.parametrize("mode", modes.names())
def test_integrate_a_level_keeps_the_extent_and_pools_as_the_mode_asks(series, mode):
    assert series.n_levels == 3
    full = chronocl.integrate(series, "0:6", mode)
    for level in (1, 2):
        cv = chronocl.integrate(series, "0:6", mode, level=level)
        coarse = series.level(level, modes.get(mode).pool)
        assert cv.shape == coarse.volume_shape
        np.testing.assert_allclose(extent(cv), extent(full))
        assert cv.metadata["level"] == level
        # Every level is normalised by level 0's range (fitted to level 0's window).
        spec = IntegrationSpec.from_dict(full.metadata["spec"])
        same = spec.with_value_range(full.metadata["value_range"])
        assert cv.metadata["value_range"] == full.metadata["value_range"]
        direct = chronocl.integrate(coarse, "0:6", spec=same)
        np.testing.assert_array_equal(cv.rgba, direct.rgba)
    assert full.metadata["level"] == 0


@pytest.mark.parametrize("mode", modes.names())
def test_auto_draws_coarse_first_and_refines_to_exactly_level_0(series, mode):
    with Session(series, mode=mode, time_tf="rgb", level="auto", memory="1GB") as s:
        first = s.set_window(0, 5)
        assert s.shown_level == 2 and s.stats["level"] == 2 and s.stats["refining"]
        assert first.shape == series.level(2).volume_shape
        full = s.refine()
        assert s.shown_level == 0 and not s.stats["refining"]
        ref = chronocl.integrate(series, "0:5", mode, time_tf="rgb")
        np.testing.assert_array_equal(full.rgba, ref.rgba)
        if ref.t_index is not None:
            np.testing.assert_array_equal(full.t_index, ref.t_index)
        assert s.refine() is None  # already at full resolution


def test_auto_scrubs_incrementally_at_the_level_it_picked(series):
    rgb = TimeTF.preset("rgb", positions="absolute")  # colours that do not move with the window
    with Session(series, mode="max", time_tf=rgb, level="auto", target_ms=1e-3) as s:
        s.set_window(0, 4)
        cvs = [s.slide(+1) for _ in range(3)]
        assert s.stats["incremental"] and s.stats["level"] == 2
        # The range fitted to the first window holds while the window slides.
        ref = chronocl.integrate(series, "3:7", spec=s.spec, level=2)
        np.testing.assert_array_equal(cvs[-1].rgba, ref.rgba)


def test_a_coarse_frame_reads_its_full_resolution_steps_ahead(series):
    """While a coarse level shows a window, level 0's manager reads its steps in the
    background (where the coarse frames leave a core idle: here a machine of many cores):
    the refine after a scrub finds them resident and reads nothing more."""
    with Session(series, mode="max", level="auto", target_ms=1e-3, memory="1GB") as s:
        s.costs.cores = 1000
        s.set_window(0, 4)
        for _ in range(3):
            s.slide(+1)
        assert s.shown_level == 2
        full = s.pool.session(0, s.spec)
        deadline = time.monotonic() + 60  # no request here: the reads are already under way
        while not set(full.manager.resident()) >= {3, 4, 5, 6} and time.monotonic() < deadline:
            time.sleep(0.02)
        reads = dict(full.manager.reads)
        assert set(reads) >= {3, 4, 5, 6}
        s.refine()
        assert s.shown_level == 0 and dict(full.manager.reads) == reads


def test_auto_picks_finer_levels_once_they_are_predicted_to_fit(series):
    with Session(series, mode="alpha", level="auto", target_ms=1e6) as s:
        s.set_window(0, 4)
        assert s.shown_level == 2  # nothing measured yet: the coarsest
        s.set_spec(mode="additive")
        assert s.shown_level == 0  # everything fits a generous target
        assert "within the target" in s.stats["why_level"]


def test_fixed_level_session_follows_the_modes_pooling(series):
    """A coarse level's modes pool it differently: a switch reads the other pooling's steps,
    and the steps of the pooling left go with its session, so that whatever the switches the
    resident steps stay within the budget (each pooling's kept its steps, over it)."""
    coarse = series.level(1)
    step = int(np.prod(coarse.volume_shape)) * coarse.dtype.itemsize
    with Session(series, mode="alpha", level=1, memory=6 * step) as s:
        a = s.set_window(0, 4)
        m = s.set_spec(mode="max")
        assert a.shape == m.shape == series.level(1).volume_shape
        ref = chronocl.integrate(series, "0:4", "max", level=1)
        np.testing.assert_array_equal(m.rgba, ref.rgba)
        for mode in ("mean", "max", "min", "alpha"):
            s.set_spec(mode=mode)
            held = [t for ls in s.pool.sessions.values() for t in ls.manager.resident()]
            assert len(held) * step <= 6 * step and len(s.pool.sessions) == 1, held


def test_every_level_takes_the_keywords_of_the_other(series):
    """A fixed level ignores `target_ms`, and level="auto" ignores `manager` (it holds one
    level's steps; `managers` shares them per level), as they did before sessions split."""
    with Session(series, mode="max", level=0, target_ms=100) as fixed:
        assert type(fixed) is Session and fixed.shown_level == 0
        want = fixed.set_window(0, 4)
        with Session(series, mode="max", level="auto", manager=fixed.manager) as auto:
            auto.set_window(0, 4)
            got = auto.refine()
            assert auto.shown_level == 0
            assert all(s.manager is not fixed.manager for s in auto.pool.sessions.values())
        assert fixed.slide(+1).steps == (1, 2, 3, 4)  # its manager outlives the auto session
    np.testing.assert_array_equal(got.rgba, want.rgba)


def test_latency_model_picks_the_finest_level_within_target():
    model = LatencyModel([8000, 1000, 125], target_ms=100)
    assert model.pick(10)[0] == 2
    model.costs.record_direct(2, 1.0, model.voxels[2], 10)  # 1 ms per 1250 voxel-steps
    model.costs.record_display(2, 5.0, model.voxels[2])
    assert model.predict(1, 10) == pytest.approx(8.0 + 40.0)
    assert model.pick(10)[0] == 1  # level 0: 64 + 320 ms > 100
    model.costs.record_direct(1, 100.0, model.voxels[1], 10)  # slower than predicted: back off
    assert model.pick(10)[0] == 2


def test_latency_model_draws_the_finest_level_a_little_over_target_rather_than_refine():
    """Level 0 predicted within `sharp_overrun` times the target is drawn at once: a coarse
    frame would be refined to it after, so its sharp frame would come later (a 256^3 slide in
    the notebook: 294 ms coarse and refined against 174 ms at level 0 at once). Further over,
    a coarser level within the target is drawn, as before; the overrun is level 0's alone."""
    model = LatencyModel([8000, 1000, 125], target_ms=100)
    model.costs.record_direct(0, 120.0, model.voxels[0], 10)  # level 0: 120 ms, level 1: 15 ms
    level, why = model.pick(10)
    assert level == 0 and f"within {TUNING.sharp_overrun:g}x the target" in why
    model.costs.record_direct(0, 200.0, model.voxels[0], 10)  # blended: 160 ms > 1.5 x 100
    assert model.predict(0, 10) == pytest.approx(160.0)
    level, why = model.pick(10)
    assert level == 1 and "within the target" in why
    model = LatencyModel([8000, 1000, 125], target_ms=100)
    model.costs.record_direct(0, 30.0, model.voxels[0], 10)  # level 1 over the target, within 1.5x
    model.costs.record_display(1, 120.0, model.voxels[1])  # level 2: 15 ms; level 0: 30 + 960 ms
    assert model.pick(10)[0] == 2
    model = LatencyModel([8000], target_ms=100)  # one level: nothing coarser to refine from
    model.costs.record_direct(0, 120.0, model.voxels[0], 10)
    assert model.pick(10) == (0, "no level predicted within 100 ms: the coarsest")


def test_latency_model_counts_the_steps_a_level_must_read_first():
    """A level whose window is not resident pays for reading it: a scrub at a coarse level
    does not jump to a finer one whose steps it would first read."""
    model = LatencyModel([8000, 1000, 125], target_ms=100)
    model.costs.record_direct(2, 1.0, model.voxels[2], 10)
    model.costs.record_display(2, 5.0, model.voxels[2])
    model.costs.record_read(2, 0.0025, model.voxels[2])  # 2.5 ms a step of 125: 0.02 ms a voxel
    assert model.predict(1, 10, missing=0) == pytest.approx(48.0)
    assert model.predict(1, 10, missing=10) == pytest.approx(48.0 + 10 * 0.02 * 1000)
    assert model.pick(10, lambda level: 0)[0] == 1  # its steps resident: within the target
    assert model.pick(10, lambda level: 10 if level < 2 else 1)[0] == 2  # read first: not


def test_a_streamed_window_is_predicted_at_its_own_rate_and_leaves_the_slide_rates_alone():
    """A level whose window streams (no room to stay resident) is predicted at the rate
    measured streaming it, the store's reads with it; that rate is the level policy's alone:
    the rate of integrating resident steps, which the slide choice weighs, stays as measured."""
    model = LatencyModel([8000, 1000, 125], target_ms=100)
    c = model.costs
    c.record_direct(0, 10.0, 8000, 10)  # resident: 10 ms at level 0
    c.record_streamed(0, 400.0, 8000, 10)  # streamed from the store: 400 ms
    assert model.predict(0, 10) == pytest.approx(10.0)
    assert model.predict(0, 10, missing=10, streams=True) == pytest.approx(400.0)
    assert model.pick(10)[0] == 0
    assert model.pick(10, streams=lambda level: level == 0)[0] == 1  # level 0 streams: over
    assert c.direct == {0: pytest.approx(10.0 / 80_000)}
    only = LatencyModel([8000, 1000, 125], target_ms=100)  # a streamed rate, nothing resident
    only.costs.record_streamed(0, 400.0, 8000, 10)
    why = "no level predicted within 100 ms: the coarsest"  # not measuring: level 0 was
    assert only.pick(10, streams=lambda level: level == 0) == (2, why)
    assert only.pick(10) == (2, "first frame: the coarsest level, measuring this machine")


def test_a_coarse_frame_reads_full_resolution_ahead_where_it_pays_and_says_why_not(series):
    """A new window is drawn coarse first; where `Costs` says reading ahead pays (a core left
    idle, the reads at the stop over the target), full resolution's steps are read in the
    background meanwhile, and the refine finds them resident. Where full resolution streams
    its window (over its budget) nothing is read ahead, and the frame says why."""
    step = int(np.prod(SHAPE)) * 4
    for memory, why in [(64 * step, None), (3 * step, "full resolution streams its window")]:
        costs = Costs(cores=64)  # cores to spare
        costs.reads[0] = 1.0  # ms a voxel: reading the window at the stop is far over the target
        with Session(series, level="auto", slide_costs=costs, memory=memory) as s:
            s.set_window(0, 4)
            assert s.shown_level > 0 and s.stats["why_not_read_ahead"] == why
            full = s.at(0)
            assert full is not None
            if why is None:
                deadline = time.monotonic() + 30
                while full.manager.resident() != [0, 1, 2, 3] and time.monotonic() < deadline:
                    time.sleep(0.01)
                assert full.manager.resident() == [0, 1, 2, 3]
            else:
                assert full.manager.resident() == [] and full.streams(s.selection)
            s.refine()
            assert s.shown_level == 0


def test_a_window_read_ahead_takes_the_room_of_the_last_one_not_more(series):
    """A library session is not told what it shows next (`leaving`): a jump drawn coarse, its
    full-resolution steps read ahead, let go of the last window's first, so that level 0's
    steps stay within its budget and in its slots (it held both windows: 8 steps for 5)."""
    step = int(np.prod(SHAPE)) * 4
    costs = Costs(cores=64)  # cores to spare
    costs.reads[0] = 1.0  # ms a voxel: reading the window at the stop is far over the target
    with Session(series, level="auto", slide_costs=costs, memory=5 * step) as s:
        s.set_window(0, 3)
        s.refine()
        full = s.at(0)
        assert s.shown_level == 0 and full.manager.resident() == [0, 1, 2]
        s.set_window(5, 8)
        assert s.shown_level > 0 and s.stats["why_not_read_ahead"] is None
        deadline = time.monotonic() + 30
        while full.manager.resident()[-3:] != [5, 6, 7] and time.monotonic() < deadline:
            time.sleep(0.01)
        assert full.manager.resident()[-3:] == [5, 6, 7]
        assert full.manager.resident_bytes <= full.manager.budget
        assert full.manager.slots.own_arrays == 0
        cv = s.refine()
        ref = chronocl.integrate(series, "5:8", spec=s.spec)
        np.testing.assert_allclose(cv.rgba, ref.rgba, rtol=0, atol=1e-5)


@pytest.mark.parametrize(
    ("level", "text"),
    [(3, "level 3 is out of range: vortex has levels 0..2"), ("fine", "must be an integer")],
)
def test_bad_levels_say_what_is_allowed(series, level, text):
    with pytest.raises(InvalidParameterError, match=text) as err:
        Session(series, level=level)
    assert "\n" not in str(err.value) and isinstance(err.value, ChronoclError)
    with pytest.raises(ChronoclError):
        chronocl.integrate(series, "0:4", level=level)


def test_bad_target_and_a_series_without_levels():
    with pytest.raises(InvalidParameterError, match="target_ms"):
        LatencyModel([1], target_ms=0)
    small = chronocl.TimeSeries.from_array(np.zeros((3, 8, 8, 8), np.float32))
    assert small.n_levels == 1
    with pytest.raises(InvalidParameterError, match="only level 0"):
        Session(small, level=1)
    with Session(small, level="auto") as s:  # nothing coarser: full resolution at once
        s.set_window(0, 2)
        assert s.shown_level == 0 and s.refine() is None


# `Costs.why_not_read_ahead`'s reasons for a window of 4 steps
WHY_NOT_READ_AHEAD = (
    r"nothing measured yet|reading the \d steps at the stop takes \d+ ms"
    r"|the coarse frames keep [\d.]+ of \d+ cores busy"
    r"|every step of the window is resident"  # the first frame's refine read them
)


def test_viewer_sends_a_coarse_frame_then_full_resolution(tmp_path):
    """A store with levels: the first frame of a request is coarse and says so, the next one
    (after a short idle) answers the same request at full resolution, its wait for the steps
    read within its integration; the coarse frame says why it read none of them ahead."""
    from .viewer_helpers import Client, start_server

    data = np.stack(list(synthetic.steps("vortex", 6, (40, 36, 96))))
    path = tmp_path / "vortex.zarr"
    chronocl.TimeSeries.from_array(data, source="vortex").save(path)
    assert chronocl.open(path).n_levels == 2
    server = start_server([path])
    try:
        client = Client(server)
        rid = client.send({"type": "open", "dataset": 0})
        client.wait("dataset", rid)
        rid = client.send({"type": "update", "size": [96, 96], "window": {"t0": 0, "t1": 4}})
        _, first, _ = client.frame_for(rid)
        assert first["level"] == 1 and first["refining"] and first["level_shape"] == [20, 18, 48]
        _, full, _ = client.frame_for(rid)
        assert full["id"] == rid and full["level"] == 0 and not full["refining"]
        assert full["level_shape"] == [40, 36, 96]
        why, timings = first["timings"]["why_not_read_ahead"], full["timings"]
        assert why is None or re.fullmatch(WHY_NOT_READ_AHEAD, why), why
        assert 0 <= timings["read_ms"] <= timings["integrate_ms"], timings
        if why is not None and "resident" not in why:  # its 4 steps read at the stop
            assert timings["read_ms"] > 0, timings
        assert timings["why_not_read_ahead"] is None  # a full-resolution frame reads none ahead
        client.close()
    finally:
        server.stop()


def test_cli_integrates_and_renders_a_level_and_refuses_a_missing_one(tmp_path, series):
    from .test_cli import assert_one_line_error, cli

    store = tmp_path / "v.zarr"
    series.save(store)
    out = tmp_path / "coarse.zarr"
    assert cli("integrate", str(store), str(out), "--mode", "max", "--level", "2").returncode == 0
    cv = chronocl.Chronovolume.load(out)
    assert cv.metadata["level"] == 2 and cv.shape == series.level(2).volume_shape
    png = tmp_path / "coarse.png"
    r = cli("render", str(store), "-o", str(png), "--level", "1", "--size", "64x64")
    assert r.returncode == 0 and png.exists()
    bad = cli("integrate", str(store), str(tmp_path / "x.zarr"), "--level", "3")
    assert_one_line_error(bad, "level 3 is out of range")
    assert not (tmp_path / "x.zarr").exists()
    small = tmp_path / "small.zarr"
    chronocl.TimeSeries.from_array(np.zeros((3, 8, 8, 8), np.float32)).save(small)
    r = cli("render", str(small), "-o", str(tmp_path / "s.png"), "--level", "1")
    assert_one_line_error(r, "chronocl pyramid")


def test_a_window_over_the_budget_is_streamed_by_slabs(series):
    """Full resolution of a window larger than the budget: z-slabs read from the series, the
    same chronovolume, and stats that say why it was not incremental."""
    step = int(np.prod(SHAPE)) * 4
    with Session(series, mode="additive", level="auto", memory=3 * step) as s:
        s.set_window(0, 5)
        full = s.refine()
        assert s.stats["path"] == "streamed" and "budget" in s.stats["why_not_incremental"]
        np.testing.assert_array_equal(full.rgba, chronocl.integrate(series, "0:5", "additive").rgba)
        # the next window of level 0 is predicted at the rate it streamed at, its reads within
        costs, sel = s.costs, s.selection
        assert 0 in costs.streamed and 0 not in costs.direct
        assert s._streams(0, sel, s.spec) and not s._streams(1, sel, s.spec)
        want = costs.streamed[0] * s.voxels[0] * 5
        assert s.policy.predict(0, 5, missing=5, streams=True) == pytest.approx(want)


def test_modes_pooling_differently_share_level_0s_resident_steps(series):
    """Level 0 is the same series whatever a mode's pooling: a switch from alpha (mean) to max
    keeps reading from the same window manager; coarse levels pooled differently do not."""
    managers: dict = {}
    alpha = Session(series, mode="alpha", level=0, managers=managers, memory="256MB")
    peak = Session(series, mode="max", level=0, managers=managers, memory="256MB")
    coarse = [Session(series, mode=m, level=1, managers=managers) for m in ("alpha", "max")]
    try:
        alpha.set_window(0, 4)
        reads = sum(alpha.manager.reads.values())
        peak.set_window(0, 4)
        assert peak.manager is alpha.manager and sum(peak.manager.reads.values()) == reads
        assert coarse[0].manager is not coarse[1].manager
    finally:
        for s in (alpha, peak, *coarse):
            s.close()
        for m in managers.values():
            m.close()


def test_a_move_that_fails_leaves_nothing_of_the_last_window_to_refine(series, monkeypatch):
    """A move whose integration fails (out of memory, given up) leaves the session on the window
    asked for: a refine then has nothing coarse to bring to full resolution (it brought the old
    window back, which `current()` then gave for the new one), and `current()` integrates the
    new window."""
    from chronocl.integration.interactive.level_session import LevelSession

    with Session(series, mode="max", time_tf="rgb", level="auto", memory="1GB") as s:
        s.set_window(0, 5)
        assert s.shown_level > 0
        show = LevelSession.show

        def failing(self, *args, **kwargs):
            raise MemoryError("out of device memory")

        monkeypatch.setattr(LevelSession, "show", failing)
        with pytest.raises(MemoryError):
            s.set_window(3, 8)
        monkeypatch.setattr(LevelSession, "show", show)
        assert s.refine() is None
        assert s.current().steps == (3, 4, 5, 6, 7)
