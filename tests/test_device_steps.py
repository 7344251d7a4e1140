"""Steps resident on the device (issue 32): an engine that copies bricks (a GPU; here PoCL with
host pointers off, the same code path) keeps a session's window in device slots
(`chronocl.engine.device_steps`). Integrations from them equal the numpy reference on odd
shapes, windows of 1-40 steps in any sequence (slides both ways, jumps), slabs and both output
formats; a TF edit uploads no step and a slide only the entering one; a window over the device
budget is sent from the host as before, and the session says why.
"""

from __future__ import annotations

import subprocess
import sys
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl.core.selection import Selection
from chronocl.core.time_tf import TimeTF
from chronocl.data import synthetic
from chronocl.engine.device_steps import DeviceBricks, DeviceSteps
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.inmemory import integrate_bricks, window_job
from chronocl.integration.interactive.session import Session

from .strategies import examples, specs
from .test_display_output import assert_display_of, rgba8_at_any_size  # noqa: F401
from .test_opencl import assert_same

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


@pytest.fixture(scope="module")
def copying():
    return OpenCLEngine(host_ptr=False)  # bricks travel to the device, as on a GPU


@settings(max_examples=examples(10), deadline=None)
@given(st.data())
def test_windows_from_device_slots_equal_the_reference(copying, data):
    shape = data.draw(st.tuples(st.integers(1, 5), st.integers(1, 4), st.integers(1, 37)))
    n_steps = data.draw(st.integers(1, 40))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    values = rng.random((n_steps, *shape), dtype=np.float32)
    values[rng.random(values.shape) < 0.3] = 0.0
    series = chronocl.TimeSeries.from_array(values)
    arrays = {s: values[s] for s in range(n_steps)}
    widest = data.draw(st.integers(1, n_steps))
    slots = DeviceSteps(copying.dc, shape, np.float32, widest + data.draw(st.integers(0, 3)))
    for _ in range(data.draw(st.integers(1, 4))):  # a sequence of windows: slides, jumps
        width = data.draw(st.integers(1, widest))
        t0 = data.draw(st.integers(0, n_steps - width))
        sel = Selection(tuple(range(t0, t0 + width)), n_steps)
        spec = data.draw(specs(selection=sel))
        job = window_job(series, sel, spec)
        slab = data.draw(st.integers(1, shape[0] + 1))
        display = data.draw(st.booleans())
        got = integrate_bricks(job, copying, DeviceBricks(arrays, slots), slab, display=display)
        ref = chronocl.integrate(series, sel, spec=spec, engine="numpy")
        if got.rgba.dtype == np.uint8:
            assert_display_of(got, ref, exact=False)
        else:
            assert_same(got, ref)
        assert set(sel.steps) <= set(slots.resident())


@contextmanager
def host_copies():
    """The bytes of every copy from a host array to a device buffer enqueued meanwhile."""
    import pyopencl as cl

    sent: list[int] = []
    copy = cl.enqueue_copy

    def counted(queue, dest, src, **kwargs):
        if isinstance(dest, cl.MemoryObjectHolder) and isinstance(src, np.ndarray):
            sent.append(src.nbytes)
        return copy(queue, dest, src, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cl, "enqueue_copy", counted)
        yield sent


def test_an_edit_uploads_no_step_and_a_slide_one(copying, tmp_path):
    rng = np.random.default_rng(4)
    path = tmp_path / "s.zarr"
    chronocl.TimeSeries.from_array(rng.random((14, 6, 5, 19), dtype=np.float32)).save(path)
    series = chronocl.open(path)
    rgb = TimeTF.preset("rgb", positions="absolute")
    with Session(series, mode="max", time_tf=rgb, engine=copying, memory="64MB") as session:
        session.set_window(2, 10)
        slots = session.at(0)._device.slots
        assert slots is not None and slots.uploads == 8
        assert session.stats["why_not_on_device"] is None
        for change in ({"order": "backward"}, {"mode": "alpha"}, {"order": "forward"}):
            with host_copies() as sent:
                cv = session.set_spec(**change)  # integrated again, from the device's slots
            ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
            assert_same(cv, ref)
            assert slots.uploads == 8
            # nothing the size of a step went up another way (the window stacked and sent)
            assert max(sent, default=0) < 6 * 5 * 19 * 4, sent
        # incremental: the sliding state integrates the entering step alone, from its slot
        session.slide(1)
        assert session.stats["path"] == "incremental" and slots.uploads == 9
        cv = session.set_spec(order="backward")  # the window again: every step on the device
        assert_same(cv, chronocl.integrate(series, session.window(), spec=session.spec))
        assert slots.uploads == 9
        session.slide(-1)
        session.set_spec(order="forward")  # the step that left is still on the device
        assert slots.uploads == 9


def test_a_window_over_the_device_budget_is_sent_from_the_host(copying, tmp_path, monkeypatch):
    monkeypatch.setenv("CHRONOCL_DEVICE_MEMORY", "20KB")
    rng = np.random.default_rng(2)
    series = chronocl.TimeSeries.from_array(rng.random((6, 8, 9, 33), dtype=np.float32))
    with Session(series, mode="alpha", engine=copying, memory="64MB") as session:
        cv = session.set_window(0, 5)
        assert session.at(0)._device.slots is None
        assert "device memory" in session.stats["why_not_on_device"]
        assert_same(cv, chronocl.integrate(series, session.window(), spec=session.spec))


def test_the_viewer_says_when_a_window_is_not_on_the_device(copying, monkeypatch):
    """The frame's timings carry the session's reason (`steps_on_host`), which the page's
    status line shows; None where the steps are on the device."""
    from chronocl.viewer.datasets import Dataset
    from chronocl.viewer.view_sessions import Views
    from chronocl.viewer.view_state import default_state

    series = chronocl.TimeSeries.from_array(
        np.random.default_rng(4).random((6, 8, 9, 33), dtype=np.float32)
    )
    views = Views([Dataset("d", series)], copying, None, "64MB")
    try:
        state = default_state(0, series)
        monkeypatch.setenv("CHRONOCL_DEVICE_MEMORY", "64MB")
        views.chronovolumes(state)
        assert views.host_steps_why is None
        views.release()
        monkeypatch.setenv("CHRONOCL_DEVICE_MEMORY", "20KB")
        views = Views([Dataset("d", series)], copying, None, "64MB")
        views.chronovolumes(state)
        assert "device memory" in views.host_steps_why
    finally:
        views.release()


@pytest.mark.parametrize("level", [1, "auto"])
def test_coarse_levels_and_repooling_keep_their_own_steps_on_the_device(copying, level):
    """A coarse session's slots hold its level's steps; a mode pooling levels differently
    reads the other pooling, never the steps left on the device by the first."""
    shape = (20, 18, 130)  # levels 1 (65) and 2 (33)
    data = np.stack(list(synthetic.steps("vortex", 8, shape)))
    series = chronocl.TimeSeries.from_array(data)
    with Session(series, mode="max", engine=copying, memory="256MB", level=level) as s:
        for mode in ("max", "mean", "max"):
            cv = s.set_spec(mode=mode) if s.selection is not None else s.set_window(0, 5)
            lvl = s.shown_level if level == "auto" else level
            ref = chronocl.integrate(series, s.window(), spec=s.spec, level=lvl, engine="numpy")
            assert_same(cv, ref)


def test_float64_steps_stay_on_the_host(copying):
    rng = np.random.default_rng(6)
    series = chronocl.TimeSeries.from_array(rng.random((6, 4, 5, 17)))  # float64
    with Session(series, mode="alpha", engine=copying, memory="64MB") as session:
        cv = session.set_window(0, 4)
        assert session.at(0)._device.slots is None
        assert_same(cv, chronocl.integrate(series, session.window(), spec=session.spec))


def test_slots_count_against_one_device_budget(copying, monkeypatch):
    """Two sessions on one device share its budget: the second gets what the first left."""
    rng = np.random.default_rng(8)
    series = chronocl.TimeSeries.from_array(rng.random((8, 8, 8, 64), dtype=np.float32))
    step = 8 * 8 * 64 * 4
    monkeypatch.setenv("CHRONOCL_DEVICE_MEMORY", str(9 * step))
    with Session(series, mode="alpha", engine=copying, memory="64MB") as a:
        a.set_window(0, 5)
        assert a.at(0)._device.slots is not None and a.at(0)._device.slots.count == 7  # 5 + 2 spare
        with Session(series, mode="max", engine=copying, memory="64MB") as b:
            cv = b.set_window(0, 4)  # 2 slots left on the device: sent from the host
            assert b.at(0)._device.slots is None and "free" in b.stats["why_not_on_device"]
            assert_same(cv, chronocl.integrate(series, b.window(), spec=b.spec))
        a.close()
        with Session(series, mode="max", engine=copying, memory="64MB") as c:
            c.set_window(0, 4)  # the first's slots were given back
            assert c.at(0)._device.slots is not None


def test_a_hold_dying_while_the_budget_is_locked_does_not_deadlock():
    """A garbage collection that any allocation under the budget's lock may start gives back
    the holds and slots that died in reference cycles, in the thread holding the lock (as
    `recycled_empty`'s spares do: tests/test_recycled_outputs.py)."""
    script = (
        "from chronocl.engine import device_steps as ds\n"
        "hold = ds.Hold(-1, 10)\n"
        "with ds._lock:\n"
        "    del hold\n"
        "assert ds._held[-1] == -10\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=30)
    assert done.returncode == 0, done.stderr
