"""Sliding state on the device (issue 32): an engine that copies bricks (a GPU; here PoCL with
host pointers off, the same code path) keeps a session's incremental state in device arrays
between slides (`chronocl.integration.interactive.slider`): the fixed-point sums updated in
place, the sliding aggregate's partials combined there, leaves integrated from the steps the
session keeps on the device. After any walk of slides both ways and jumps, windows of 1-40
steps, odd shapes, every mode, several data types, the chronovolume equals the numpy
reference; a slide sends up only the entering step and reads back only the chronovolume; the
state is held from the device budget, and stays on the host where it does not fit.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl import modes
from chronocl.core.tf import TimeTF
from chronocl.engine.device_steps import SPARE_SLOTS, budget_left
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.interactive.session import Session
from chronocl.integration.interactive.slider import state_bytes

from .strategies import examples, specs
from .test_opencl import assert_same

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

DTYPES = (np.float32, np.uint8, np.uint16, np.int16)


@pytest.fixture(scope="module")
def copying():
    return OpenCLEngine(host_ptr=False)  # bricks travel to the device, as on a GPU


@pytest.fixture(scope="module")
def converting():
    """Bricks that travel converted are not kept on the device: the state is, its leaves are
    integrated from the host and sent up."""
    return OpenCLEngine(host_ptr=False, device_format="float32")


def _series(rng: np.random.Generator, n_steps: int, shape: tuple, dtype, ties: bool):
    u = rng.random((n_steps, *shape), dtype=np.float32)
    u[rng.random(u.shape) < 0.3] = 0.0
    if ties:  # exact ties: first_hit thresholds, max/min and change tie-breaking
        u = np.round(u * 4) / 4
    info = np.iinfo(dtype) if np.dtype(dtype).kind in "iu" else None
    raw = u if info is None else np.round(u * min(info.max, 1000)).astype(dtype)
    return chronocl.TimeSeries.from_array(raw.astype(dtype))


def _check(session: Session, cv, series) -> None:
    ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
    assert cv.steps == ref.steps
    assert_same(cv, ref)


@pytest.mark.parametrize("mode", modes.names())
@settings(max_examples=examples(4), deadline=None)
@given(data=st.data())
def test_slides_with_the_state_on_the_device_equal_the_reference(copying, converting, mode, data):
    shape = data.draw(st.tuples(st.integers(1, 5), st.integers(1, 5), st.integers(1, 37)))
    width = data.draw(st.integers(1, 40))
    n_steps = data.draw(st.integers(width, width + 10))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    dtype = data.draw(st.sampled_from(DTYPES))
    series = _series(rng, n_steps, shape, dtype, data.draw(st.booleans()))
    spec = data.draw(specs(mode=mode, positions="absolute"))
    engine = data.draw(st.sampled_from([copying, copying, converting]))
    with Session(series, engine=engine, spec=spec, memory="64MB") as session:
        t0 = data.draw(st.integers(0, n_steps - width))
        _check(session, session.set_window(t0, t0 + width), series)
        for _ in range(data.draw(st.integers(1, 8))):
            if data.draw(st.integers(0, 5)) == 0:  # a jump anywhere
                t0 = data.draw(st.integers(0, n_steps - width))
                cv = session.set_window(t0, t0 + width)
            else:
                before = session.selection
                cv = session.slide(data.draw(st.sampled_from([-3, -2, -1, 1, 2, 3])))
                after = session.selection
                if after != before and set(before.steps) & set(after.steps):
                    # (or integrated: too faint to finish from its sums, its state kept)
                    why = session.stats["why_not_incremental"] or ""
                    assert session.stats["path"] == "incremental" or "too faint" in why, why
                    assert session.at(0)._slider.dc is not None  # the state is on the device
            _check(session, cv, series)


class Transfers:
    """Bytes between host and device through pyopencl while it is entered: copies, and buffers
    made from host memory (a spy: every call goes on to pyopencl)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.up: list[int] = []
        self.down: list[int] = []
        self.monkeypatch = monkeypatch

    def __enter__(self) -> Transfers:
        up, down, copy = self.up, self.down, cl.enqueue_copy

        def enqueue_copy(queue, dest, src, **kw):
            to_device = isinstance(dest, cl.MemoryObjectHolder)
            from_device = isinstance(src, cl.MemoryObjectHolder)
            if to_device != from_device:
                (up if to_device else down).append(memoryview(src if to_device else dest).nbytes)
            return copy(queue, dest, src, **kw)

        class Buffer(cl.Buffer):
            def __init__(self, context, flags, size=0, hostbuf=None):
                super().__init__(context, flags, size, hostbuf)
                if hostbuf is not None and flags & cl.mem_flags.COPY_HOST_PTR:
                    up.append(memoryview(hostbuf).nbytes)

        self.monkeypatch.setattr(cl, "enqueue_copy", enqueue_copy)
        self.monkeypatch.setattr(cl, "Buffer", Buffer)
        return self

    def __exit__(self, *exc: object) -> None:
        self.monkeypatch.undo()


TABLES = 24 * 1024  # the kernels' tables (LUT, time colours, steps) and a reduction's parts


@pytest.mark.parametrize("mode", modes.names())
def test_a_slide_sends_up_the_entering_step_and_reads_back_the_chronovolume(
    copying, mode, monkeypatch
):
    """Nothing the size of the volume travels but the entering step and the chronovolume: not
    the sums, not a partial, not a leaf (each at least TABLES * 1.7 here)."""
    shape, width = (16, 20, 33), 6
    step = int(np.prod(shape)) * 4
    assert step > 1.7 * TABLES
    series = _series(np.random.default_rng(3), 14, shape, np.float32, ties=False)
    rgb = TimeTF.preset("rgb", positions="absolute")
    with Session(series, mode=mode, time_tf=rgb, engine=copying, memory="64MB") as session:
        session.set_window(2, 2 + width)
        session.slide(1)  # the state starts: the window's leaves, from the device's slots
        for k, entering in ((1, step), (1, step), (-1, 0)):  # back: that step is still there
            with Transfers(monkeypatch) as moved:
                cv = session.slide(k)
            assert session.stats["path"] == "incremental"
            _check(session, cv, series)
            out = cv.rgba.nbytes + (0 if cv.t_index is None else cv.t_index.nbytes)
            assert entering <= sum(moved.up) <= entering + TABLES, moved.up
            assert out <= sum(moved.down) <= out + TABLES, moved.down


def test_the_state_is_held_from_the_device_budget(copying, monkeypatch):
    """The state's bytes (`state_bytes`) count against the device budget beside the steps'
    slots from the first slide, and are given back with the session; where they do not fit,
    the state stays on the host (and the slides still equal the reference)."""
    shape, width = (6, 7, 33), 4
    series = _series(np.random.default_rng(5), 9, shape, np.float32, ties=False)
    step = int(np.prod(shape)) * 4
    state = state_bytes(modes.get("alpha"), width, int(np.prod(shape)))
    monkeypatch.setenv("CHRONOCL_DEVICE_MEMORY", str(2**30))
    others = 2**30 - budget_left(copying.dc)  # what other sessions of the process hold
    rgb = TimeTF.preset("rgb", positions="absolute")
    for spare, on_device in ((-1, False), (0, True)):
        budget = others + (width + SPARE_SLOTS) * step + state + spare
        monkeypatch.setenv("CHRONOCL_DEVICE_MEMORY", str(budget))
        with Session(series, mode="alpha", time_tf=rgb, engine=copying, memory="64MB") as s:
            s.set_window(0, width)
            assert s.at(0)._device.slots is not None
            left = budget_left(copying.dc)  # the slots only: the state is held from a slide on
            for k in (1, 2, -1):
                _check(s, s.slide(k), series)
                assert (s.at(0)._slider.dc is not None) == on_device
                assert budget_left(copying.dc) == (0 if on_device else left)
        assert budget_left(copying.dc) == budget - others


@pytest.mark.parametrize("mode", ["max", "mean", "additive"])
def test_a_state_over_the_largest_device_buffer_slides_on_the_host(copying, mode, monkeypatch):
    """Where one array of the sliding state (an RGBA partial, the fixed-point sums) is over the
    device's largest buffer (`chronocl.engine.buffers.max_alloc`, lowered by CHRONOCL_MAX_ALLOC
    to half an RGBA volume), the state stays on the host and slides still equal the reference
    (issue 45: it went to the device and the first slide raised DeviceLimitError)."""
    from chronocl.engine import buffers

    shape = (6, 8, 32)
    series = _series(np.random.default_rng(8), 10, shape, np.float32, False)
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, str(int(np.prod(shape)) * 16 // 2))
    rgb = TimeTF.preset("rgb", positions="absolute")
    with Session(series, mode=mode, time_tf=rgb, engine=copying, memory="64MB") as session:
        session.set_window(2, 6)
        for move in (+2, -1):
            _check(session, session.slide(move), series)
