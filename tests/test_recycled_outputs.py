"""Recycled output memory (`chronocl.core.memory.recycled_empty`): a chronovolume's arrays are
made on the memory of earlier ones that died, old contents and all, so every path that fills
them must write every element. Spare maps here hold garbage (NaN, -1), and what comes out
must equal what fresh zeroed memory gives, bit for bit, and the numpy reference."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl.core import memory
from chronocl.core.memory import recycled_empty, spares
from chronocl.core.tuning import TUNING
from chronocl.data.bricks import ResidentBricks
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration import inmemory
from chronocl.integration.inmemory import integrate_bricks, window_job

from .strategies import examples, specs, windows
from .test_opencl import assert_same

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


@pytest.fixture(autouse=True)
def small_maps(monkeypatch):
    """Every output is recycled, so the small volumes here are too."""
    monkeypatch.setattr(TUNING, "mapped_bytes", 1)
    monkeypatch.setattr(TUNING, "spare_maps", 3)
    monkeypatch.setattr(TUNING, "spare_sizes", 3)  # `poison`'s three sizes
    spares.clear()
    yield
    spares.clear()


def poison(shape) -> int:
    """Put spare maps of every size the outputs of `shape` (Z, Y, X) may take, full of 0xFF
    (NaN as float32, -1 as int32, 255 as uint8); returns how many are spare."""
    spares.clear()
    held = []  # all alive at once: one map each
    for dims, dt in (((*shape, 4), np.float32), ((*shape, 4), np.uint8), (shape, np.int32)):
        held.append(recycled_empty(dims, dt))
        held[-1].view(np.uint8).reshape(-1)[:] = 0xFF
    del held
    gc.collect()
    return len(spares.maps)


@pytest.fixture
def taken(monkeypatch) -> list[int]:
    """The sizes of the spare maps handed out."""
    sizes: list[int] = []
    take = spares.take

    def counted(size):
        got = take(size)
        if got is not None:
            sizes.append(size)
        return got

    monkeypatch.setattr(spares, "take", counted)
    return sizes


def test_a_dead_array_gives_its_memory_to_the_next_of_its_size():
    a = recycled_empty((64, 64, 4), np.float32)
    a[...] = 7
    address = a.ctypes.data
    view = a[3:5]
    del a
    gc.collect()
    assert not spares.maps  # a view keeps it alive
    del view
    gc.collect()
    b = recycled_empty((64, 64, 4), np.float32)
    assert b.ctypes.data == address and (b == 7).all() and b.flags.writeable
    c = recycled_empty((64, 64, 4), np.float32)  # none spare: a fresh map, zeroed
    assert c.ctypes.data != address and not c.any()
    assert b.ctypes.data % memory.ALIGN == 0 and c.ctypes.data % memory.ALIGN == 0


def test_spares_put_aside_are_back_as_they_were_and_the_block_sees_fresh_memory():
    """`spares.aside` (bench/integrate.py's first call at a size): the block's arrays are on
    fresh maps, and the spares it found are the others' again after it."""
    a = recycled_empty((64, 64, 4), np.float32)
    a[...] = 3
    address = a.ctypes.data
    del a
    gc.collect()
    with spares.aside():
        b = recycled_empty((64, 64, 4), np.float32)
        assert b.ctypes.data != address and not b.any()
        del b
        gc.collect()
    c = recycled_empty((64, 64, 4), np.float32)
    assert c.ctypes.data == address and (c == 3).all()
    assert not spares.maps  # the block's dead array was let go, not kept


def test_a_caller_giving_back_before_it_takes_leaves_the_other_spares(monkeypatch):
    """A session gives its last chronovolume back before it takes memory for the next. Kept
    per size, that leaves the spares of another caller of the same sizes (`chronocl.integrate`'s
    last rgba and t_index) where they were; with two maps in all, it pushed them out."""
    import mmap

    monkeypatch.setattr(TUNING, "spare_maps", 2)
    monkeypatch.setattr(TUNING, "spare_sizes", 2)
    rgba, t_index = 16 * mmap.PAGESIZE, 4 * mmap.PAGESIZE
    for size in (rgba, t_index):  # chronocl.integrate's output died
        spares.give(mmap.mmap(-1, size))
    for size in (rgba, t_index):  # a session's last one dies, then it takes memory again
        spares.give(mmap.mmap(-1, size))
    assert spares.take(rgba) is not None and spares.take(t_index) is not None
    assert spares.take(rgba) is not None and spares.take(t_index) is not None  # integrate's


def test_arrays_dying_fast_start_one_timer_not_one_each():
    before = threading.active_count()
    for _ in range(50):  # a viewer sliding at 30 frames a second
        recycled_empty((64, 64), np.float32)
    assert spares.maps and threading.active_count() <= before + 1


def test_spares_are_bounded_in_number_and_time(monkeypatch):
    held = [recycled_empty((100 + i, 64), np.float32) for i in range(3 * TUNING.spare_sizes)]
    del held
    gc.collect()
    assert len(spares.maps) == TUNING.spare_sizes  # one of each of the last sizes
    held = [recycled_empty((100, 64), np.float32) for _ in range(3 * TUNING.spare_maps)]
    del held
    gc.collect()
    assert sum(len(m) == len(spares.maps[-1]) for m in spares.maps) == TUNING.spare_maps
    monkeypatch.setattr(TUNING, "spare_seconds", 0.05)
    recycled_empty((100, 64), np.float32)  # dies at once: a spare again, for 0.05 s
    for _ in range(200):
        if not spares.maps:
            break
        time.sleep(0.05)
    assert not spares.maps


def window_of(u: np.ndarray, sel, spec):
    """(series, job, resident arrays) of the drawn window `u` at the steps of `sel`."""
    full = np.zeros((sel.n_steps, *u.shape[1:]), np.float32)
    full[list(sel.steps)] = u
    series = chronocl.TimeSeries.from_array(full)
    return series, window_job(series, sel, spec), {s: series.host[s] for s in sel.steps}


@settings(max_examples=examples(8), deadline=None)
@given(st.data())
def test_integrating_on_garbage_equals_integrating_on_zeros(taken, data):
    u, sel = data.draw(windows())
    spec = data.draw(specs(selection=sel))
    display = data.draw(st.booleans())
    slab = data.draw(st.integers(1, u.shape[1] + 1))
    series, job, arrays = window_of(u, sel, spec)
    engine = OpenCLEngine(host_ptr=data.draw(st.booleans()))

    spares.clear()
    clean = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab, display=display)
    poison(u.shape[1:])
    taken.clear()
    dirty = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab, display=display)
    assert taken  # made on garbage
    np.testing.assert_array_equal(dirty.rgba, clean.rgba)
    if clean.t_index is not None:
        np.testing.assert_array_equal(dirty.t_index, clean.t_index)
    poison(u.shape[1:])
    taken.clear()
    got = chronocl.integrate(series, sel, spec=spec, engine=engine, slab=slab)
    assert taken
    assert_same(got, chronocl.integrate(series, sel, spec=spec, engine="numpy"))


@settings(max_examples=examples(6), deadline=None)
@given(st.data())
def test_the_display_format_on_garbage_equals_it_on_zeros(taken, data):
    """The kernels' RGBA8 (a viewer's frame) on garbage: the volumes above are all below
    `DISPLAY_VOXELS`, so this lowers it to 0."""
    u, sel = data.draw(windows(wide=True))
    spec = data.draw(specs(selection=sel))
    _, job, arrays = window_of(u, sel, spec)
    engine = OpenCLEngine(host_ptr=data.draw(st.booleans()))
    slab = data.draw(st.integers(1, u.shape[1] + 1))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(inmemory, "DISPLAY_VOXELS", 0)
        spares.clear()
        clean = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab, display=True)
        poison(u.shape[1:])
        taken.clear()
        dirty = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab, display=True)
    assert taken
    if not spec.integration.finalize_is_global(spec):
        assert dirty.rgba.dtype == np.uint8
    np.testing.assert_array_equal(dirty.rgba, clean.rgba)
    if clean.t_index is not None:
        np.testing.assert_array_equal(dirty.t_index, clean.t_index)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # fork beside threads (3.12)
def test_a_forked_child_never_writes_its_parents_memory():
    """The maps are shared with a forked child (anonymous shared maps): a child must neither
    recycle what the parent still uses (an array alive in the parent that died in the child)
    nor a spare the parent hands out too."""
    shape = (64, 64, 4)
    live = recycled_empty(shape, np.float32)
    live[...] = 1
    dead = recycled_empty(shape, np.float32)
    del dead
    gc.collect()
    assert len(spares.maps) == 1
    go_r, go_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: the parent's live array dies here, then outputs are made
        try:
            os.read(go_r, 1)
            del live
            gc.collect()
            for value in (2, 3):
                recycled_empty(shape, np.float32)[...] = value
        finally:
            os._exit(0)
    taken = recycled_empty(shape, np.float32)  # the parent's spare, handed out here
    taken[...] = 5
    os.write(go_w, b"x")
    _, status = os.waitpid(pid, 0)
    os.close(go_r)
    os.close(go_w)
    assert status == 0
    assert (live == 1).all() and (taken == 5).all()


def test_arrays_alive_at_exit_give_nothing_back():
    """Nothing is made after exit begins: an array alive then (a script's result) is not made
    spare (on Python 3.12 that started the expiry's timer thread at shutdown: a traceback)."""
    script = (
        "import numpy as np\n"
        "from chronocl.core import memory\n"
        "from chronocl.core.tuning import TUNING\n"
        "memory.spares.give = lambda mapped: print('given at exit')\n"
        "kept = memory.recycled_empty((1, TUNING.mapped_bytes), np.uint8)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0 and not done.stderr, done.stderr
    assert "given" not in done.stdout


def test_an_array_dying_while_the_spares_are_locked_does_not_deadlock():
    """A collection may run inside `give` or `take` (the expiry timer's allocations) and call
    the finalizer of a recycled array that died in a reference cycle, in the thread holding the
    spares' lock: found by varying the collection threshold, it hung the thread for good. Here
    the array dies inside the lock directly."""
    script = (
        "import numpy as np\n"
        "from chronocl.core import memory\n"
        "from chronocl.core.tuning import TUNING\n"
        "a = memory.recycled_empty((TUNING.mapped_bytes,), np.uint8)\n"
        "with memory.spares.lock:\n"
        "    del a\n"
        "assert len(memory.spares.maps) == 1\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=30)
    assert done.returncode == 0, done.stderr
