"""Windows integrated where their steps lie (issue 32, no copy per integration).

The window manager reads steps into slots of one block (`chronocl.data.slots`), and an
in-memory series' steps lie in its own array: an OpenCL engine on a CPU device reads both in
place through a `SlotBrick` (kernels' SLOTS build), in chunks of rows where a brick spans
more than one buffer may hold. Each of these equals the numpy reference, on odd shapes, odd
windows, strides, orders and slabs, and a session's slides both ways over slots equal it too.

Tests of in-place reads ask for host pointers (`host_ptr=True`, valid on any OpenCL device), so
they read in place on a GPU too, where the default copies bricks to the device; a session on
that default keeps its window's steps on the device instead, and sends it only the steps
entering (`chronocl.engine.device_steps`).
"""

from __future__ import annotations

import gc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl.core.budget import resident_bytes
from chronocl.core.errors import SupersededError
from chronocl.core.interrupt import interruptible
from chronocl.core.memory import prefault
from chronocl.core.selection import Selection
from chronocl.core.time_tf import TimeTF
from chronocl.data.bricks import ResidentBricks, SeriesBricks, SlotBrick, slot_brick
from chronocl.data.slots import StepSlots, _warmer
from chronocl.engine.in_place import slot_chunks
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.inmemory import integrate_bricks, window_job
from chronocl.integration.interactive.session import Session

from .strategies import examples, specs
from .test_opencl import assert_same

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


class Counting(OpenCLEngine):
    """The OpenCL engine, counting the bricks it read where their steps lie (only with host
    pointers: a CPU device's default, or `host_ptr=True`)."""

    def __init__(self, **options) -> None:
        super().__init__(**options)
        self.in_place = 0

    def accumulate(self, brick, *args, **kwargs):
        out = super().accumulate(brick, *args, **kwargs)
        self.in_place += self.last_in_place  # read where the steps lie, not stacked
        return out


@st.composite
def slotted_windows(draw):
    """A series, a window of it (any stride) and its steps held in slots of one block, in a
    random order among more slots than the window has steps."""
    shape = draw(st.tuples(st.integers(1, 6), st.integers(1, 5), st.integers(1, 40)))
    n_steps = draw(st.integers(1, 14))
    stride = draw(st.integers(1, 3))
    t0 = draw(st.integers(0, n_steps - 1))
    steps = tuple(range(t0, n_steps, stride))[: draw(st.integers(1, 14))]
    rng = np.random.default_rng(draw(st.integers(0, 2**31)))
    dtype = draw(st.sampled_from([np.float32, np.uint8, np.uint16]))
    data = rng.random((n_steps, *shape), dtype=np.float32)
    data[rng.random(data.shape) < 0.3] = 0.0  # empty lanes beside live ones
    if dtype != np.float32:
        data = np.round(data * np.iinfo(dtype).max).astype(dtype)
    series = chronocl.TimeSeries.from_array(data)
    slots = StepSlots(shape, data.dtype, len(steps) + draw(st.integers(0, 5)))
    held = [slots.take() for _ in range(slots.count)]
    order = draw(st.permutations(range(slots.count)))
    arrays = {}
    for s, i in zip(steps, order, strict=False):
        held[i][...] = data[s]
        arrays[s] = held[i]
    return series, Selection(steps, n_steps), arrays


@settings(max_examples=examples(30))
@given(st.data())
def test_steps_in_slots_integrate_in_place_as_the_reference(data):
    series, sel, arrays = data.draw(slotted_windows())
    spec = data.draw(specs(selection=sel))
    slab = data.draw(st.integers(1, series.volume_shape[0] + 1))
    # A small buffer limit makes the engine cut the in-place brick into chunks of rows.
    limit = data.draw(st.sampled_from([None, 1, 3]))
    row = series.volume_shape[1] * series.volume_shape[2] * series.dtype.itemsize
    # Room for `limit` rows of the window with a gradient's halo rows (3 rows each at least).
    most = None if limit is None else limit * row * 3 * max(20, len(sel.steps))
    engine = Counting(host_ptr=True, max_brick_bytes=most)
    job = window_job(series, sel, spec)
    got = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab)
    ref = chronocl.integrate(series, sel, spec=spec, engine="numpy")
    assert_same(got, ref)


@settings(max_examples=examples(20))
@given(st.data())
def test_an_in_memory_series_integrates_in_place_as_the_reference(data):
    series, sel, _ = data.draw(slotted_windows())
    spec = data.draw(specs(selection=sel))
    engine = Counting(host_ptr=True)
    slab = data.draw(st.integers(1, series.volume_shape[0] + 1))
    got = chronocl.integrate(series, sel, spec=spec, engine=engine, slab=slab)
    assert_same(got, chronocl.integrate(series, sel, spec=spec, engine="numpy"))
    assert engine.in_place > 0


@pytest.mark.parametrize("mode", ["alpha", "max", "first_hit", "additive", "change"])
def test_a_session_over_slots_slides_both_ways_as_the_reference(mode, tmp_path):
    """A store-backed session: steps read into the manager's slots, every window integrated
    in place (never stacked), slides both ways and a TF edit equal to the numpy reference."""
    rng = np.random.default_rng(3)
    path = tmp_path / "s.zarr"
    chronocl.TimeSeries.from_array(rng.random((16, 7, 9, 37), dtype=np.float32)).save(path)
    series = chronocl.open(path)
    engine = Counting(host_ptr=True)
    with Session(series, mode=mode, engine=engine, memory="64MB") as session:
        session.set_window(3, 11)
        for k in (1, 1, 3, -1, -4, 2, -2):
            cv = session.slide(k)
            ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
            assert_same(cv, ref)
        session.set_spec(order="backward")
        ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
        assert_same(session.current(), ref)
        assert session.manager.slots.own_arrays == 0
    assert engine.in_place > 0


def test_a_held_slot_is_never_handed_out_again():
    slots = StepSlots((2, 3, 4), np.float32, 2)
    a, b = slots.take(), slots.take()
    a[...], b[...] = 1.0, 2.0
    rows = a[1:]  # a slice alone does not hold the slot: the view does
    extra = slots.take()  # every slot taken: an array of its own
    assert slots.own_arrays == 1 and not np.shares_memory(extra, a)
    del b
    gc.collect()
    c = slots.take()  # b's slot, free again
    c[...] = 3.0
    assert (a == 1.0).all() and (rows == 1.0).all()
    assert slot_brick([a, c]) is not None


def test_a_slot_held_only_by_a_reference_cycle_is_taken_again_not_a_new_array():
    """A step evicted while an object in a reference cycle (a session's state, say) still
    held its view: its slot comes back for the next step, which stays in the block."""
    slots = StepSlots((2, 3, 4), np.float32, 1)
    gc.disable()  # the cycle stays uncollected until `take` asks for it
    try:
        cycle = {"view": slots.take()}
        cycle["self"] = cycle
        del cycle
        again = slots.take()
    finally:
        gc.enable()
    assert slots.own_arrays == 0 and slot_brick([again]) is not None


@pytest.mark.skipif(resident_bytes() is None, reason="reads /proc/self/statm")
def test_the_next_free_slots_are_faulted_in_ahead_and_keep_what_they_hold():
    slots = StepSlots((64, 256, 256), np.float32, 5)  # 16 MB a slot: a memory map
    step = 64 * 256 * 256 * 4
    first = slots.take()
    first[...] = 1.0
    slots.warm(2)  # slots 1 and 2, those taken next
    _warmer().submit(lambda: None).result()
    before = resident_bytes()
    second = slots.take()  # slot 1
    slots.warm(2)  # slots 2 (warm already) and 3
    _warmer().submit(lambda: None).result()
    grown = resident_bytes() - before
    assert 0.9 * step <= grown <= 1.5 * step  # slot 3's pages, not the whole block
    assert prefault(first) and (first == 1.0).all()  # faulting in changes no data
    second[...] = 2.0
    assert (first == 1.0).all() and slots.own_arrays == 0


def test_steps_that_do_not_share_a_block_are_stacked():
    a = np.zeros((2, 3, 16), np.float32)
    b = np.ones((2, 3, 16), np.float32)
    assert slot_brick([a, b]) is None
    assert slot_brick([a]) is not None
    brick = ResidentBricks({0: a, 1: b}).read([0, 1])
    assert isinstance(brick, np.ndarray) and brick.shape == (2, 2, 3, 16)
    together = np.arange(3 * 2 * 3 * 16, dtype=np.float32).reshape(3, 2, 3, 16)
    brick = SeriesBricks(chronocl.TimeSeries.from_array(together)).read([2, 0], 1, 2)
    assert isinstance(brick, SlotBrick)
    np.testing.assert_array_equal(np.asarray(brick), together[[2, 0], 1:2].swapaxes(0, 1))


@pytest.mark.parametrize("enhance", ["none", "edge"])
def test_a_brick_wider_than_one_buffer_goes_in_chunks_of_rows(enhance):
    """Two steps in slots 0 and 7 of eight: a 6-row brick spans 8 steps' rows, more than a
    buffer of 40 rows may hold, so the engine reads it in place in chunks (halo rows too)."""
    rng = np.random.default_rng(5)
    data = rng.random((2, 6, 4, 32), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    slots = StepSlots((6, 4, 32), np.float32, 8)
    held = [slots.take() for _ in range(8)]
    held[0][...], held[7][...] = data[0], data[1]
    row = 4 * 32 * 4
    engine = Counting(host_ptr=True, max_brick_bytes=40 * row)
    sel = Selection((0, 1), 2)
    brick = ResidentBricks({0: held[0], 1: held[7]}).read([0, 1])
    halo = 1 if enhance != "none" else 0
    chunks = slot_chunks(brick, slice(0, 6), halo, engine.max_brick_bytes)
    assert chunks is not None and len(chunks) > 1
    spec = chronocl.make_spec("max", enhance=enhance)
    job = window_job(series, sel, spec)
    got = integrate_bricks(job, engine, ResidentBricks({0: held[0], 1: held[7]}))
    assert_same(got, chronocl.integrate(series, sel, spec=spec, engine="numpy"))
    assert engine.in_place > 0


@pytest.mark.parametrize("mode", ["additive", "alpha"])
def test_a_window_given_up_mid_integration_leaves_the_session_sound(mode):
    """A refine given up between two slabs (`chronocl.core.interrupt`): the session neither
    keeps a chronovolume nor sliding state for that window, and the windows after it, slid
    from the last one completed or not, equal the reference."""
    rng = np.random.default_rng(9)
    series = chronocl.TimeSeries.from_array(rng.random((40, 12, 8, 32), dtype=np.float32))
    time_tf = TimeTF.preset("rgb", positions="absolute")
    with Session(series, mode=mode, time_tf=time_tf, memory="64MB") as session:
        session.set_window(0, 10)
        seen: list[tuple[str, int]] = []

        def note(stage: str, done: int, total: int) -> None:
            seen.append((stage, done))

        with interruptible(lambda: ("integrating", 1) in seen, note):
            with pytest.raises(SupersededError):
                session.set_window(20, 30)
        assert ("integrating", 1) in seen  # given up between slabs, not before
        for window in ((1, 11), (2, 12), (20, 30), (21, 31)):
            cv = session.set_window(*window)
            ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
            assert_same(cv, ref)


def test_a_long_scrub_keeps_every_window_in_one_block():
    """40 steps, a budget of 14, a 10-step window slid 25 times: steps are read ahead only
    into free slots, so every window the session integrates lies in one block of slots."""
    rng = np.random.default_rng(4)
    data = rng.random((40, 4, 8, 32), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    step = data[0].nbytes
    time_tf = TimeTF.preset("rgb", positions="absolute")
    engine = Counting()
    with Session(series, mode="max", time_tf=time_tf, engine=engine, memory=14 * step) as s:
        s.manager.budget = 14 * step
        s.set_window(0, 10)
        for _ in range(25):
            s.slide(1)
            assert slot_brick(list(s.at(0)._arrays.values())) is not None
        assert s.manager.slots.own_arrays == 0


@pytest.mark.parametrize("host_ptr", [True, False], ids=["in-place", "copying"])
def test_a_window_integrated_anew_takes_the_slots_of_the_steps_that_left(host_ptr):
    """A budget of one step more than the window, windows jumping by 3 and integrated anew
    (relative time positions cannot slide): the session lets go of the leaving steps before
    the entering ones are read, so they take their slots and every window stays in place.
    Read in place (host pointers), each window is integrated where its steps lie; copied (a
    GPU's default), the steps stay in the device's slots and each window sends only the 3
    entering."""
    rng = np.random.default_rng(5)
    data = rng.random((30, 4, 8, 32), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    step = data[0].nbytes
    engine = Counting(host_ptr=host_ptr)
    with Session(series, mode="max", engine=engine, memory=11 * step, prefetch=0) as s:
        s.set_window(0, 10)
        for t0 in range(3, 19, 3):
            before = engine.in_place
            slots = s.at(0)._device.slots
            sent = None if slots is None else slots.uploads
            cv = s.set_window(t0, t0 + 10)
            if host_ptr:
                assert engine.in_place > before and slots is None  # read where the steps lie
            else:
                assert engine.in_place == 0 and s.stats["why_not_on_device"] is None
                assert s.at(0)._device.slots is slots and slots.uploads - sent == 3
            assert_same(cv, chronocl.integrate(series, s.window(), spec=s.spec))
        assert s.stats["why_not_incremental"] is not None
        assert s.manager.slots.own_arrays == 0
