"""The window manager: resident steps under the budget, LRU, prefetch, cancellation, changes.

Concurrency is tested with a gated store (reads block until the test opens the gate)
instead of sleeps, so every interleaving asserted here is forced, not hoped for.
"""

from __future__ import annotations

import gc
import os
import subprocess
import sys
import threading
import time
import weakref
from pathlib import Path

import dask.array as da
import numpy as np
import pytest
import zarr

from chronocl.core.budget import resident_bytes
from chronocl.core.errors import (
    InvalidParameterError,
    InvalidSelectionError,
    StoreChangedError,
    SupersededError,
)
from chronocl.core.tuning import TUNING
from chronocl.data import slots as slots_module
from chronocl.data.series import TimeSeries, open_series
from chronocl.data.slots import StepSlots, _warmer
from chronocl.data.window import WindowManager


class GatedArray:
    """A (T, Z, Y, X) array whose reads wait for `gate` and are logged by step."""

    def __init__(self, data: np.ndarray) -> None:
        self.data = data
        self.shape, self.dtype, self.ndim = data.shape, data.dtype, data.ndim
        self.gate = threading.Event()
        self.gate.set()
        self.entered = threading.Event()  # a read is waiting at the gate
        self.log: list[int] = []
        self._lock = threading.Lock()

    def __getitem__(self, key):
        step = key[0].start if isinstance(key[0], slice) else int(key[0])
        with self._lock:
            self.log.append(int(step))
        self.entered.set()
        assert self.gate.wait(30), "the test never opened the gate"
        return self.data[key]


def gated_series(t: int = 20, shape=(4, 8, 8)) -> tuple[TimeSeries, GatedArray]:
    data = np.arange(t * np.prod(shape), dtype=np.float32).reshape(t, *shape)
    gated = GatedArray(data)
    series = TimeSeries.from_array(da.from_array(gated, chunks=(1, *shape)))
    gated.log.clear()
    return series, gated


def zarr_series(tmp_path, t: int = 12, shape=(6, 10, 10)) -> TimeSeries:
    data = np.random.default_rng(0).random((t, *shape), dtype=np.float32)
    TimeSeries.from_array(data).save(tmp_path / "s.zarr")
    return open_series(tmp_path / "s.zarr")


def test_steps_come_back_exact_and_are_read_once(tmp_path) -> None:
    series = zarr_series(tmp_path)
    truth = np.asarray(series.data)
    with WindowManager(series, "10MB") as wm:
        for steps in ([0, 1, 2], [1, 2, 3], [2, 3, 4], [0, 1, 2]):
            arrays = wm.get(steps)
            for s, a in zip(steps, arrays, strict=True):
                np.testing.assert_array_equal(a, truth[s])
        assert dict(wm.reads) == {0: 1, 1: 1, 2: 1, 3: 1, 4: 1}
        brick = wm.brick([4, 2], 1, 5)
        np.testing.assert_array_equal(brick, np.moveaxis(truth[[4, 2], 1:5], 0, 1))


def test_budget_bounds_residency_and_evicts_least_recently_used(tmp_path) -> None:
    series = zarr_series(tmp_path)
    step = 6 * 10 * 10 * 4
    with WindowManager(series, 4 * step, prefetch=0) as wm:
        assert wm.capacity == 4
        wm.get([0, 1, 2])
        wm.get([3])
        wm.get([1])  # 1 becomes the most recently used
        wm.get([5, 6])  # evicts the two least recently used: 0 and 2
        assert wm.resident() == [1, 3, 5, 6]
        assert wm.resident_bytes <= wm.budget
        wm.get([0])
        assert wm.reads[0] == 2  # evicted, so read again


def test_windows_sessions_still_hold_are_not_evicted_for_another(tmp_path) -> None:
    """Two clients share a manager, their windows together over its budget: the first's
    steps, which its session still holds, stay (evicting them would free nothing, and its next
    frame would read them again); the second's are read beside them."""
    series = zarr_series(tmp_path)
    truth = np.asarray(series.data)
    step = 6 * 10 * 10 * 4
    with WindowManager(series, 4 * step, prefetch=0) as wm:
        first = wm.get([0, 1, 2])  # held, as the first client's session holds its window
        second = wm.get([5, 6, 7])
        for s, a in zip([5, 6, 7], second, strict=True):
            np.testing.assert_array_equal(a, truth[s])
        again = wm.get([0, 1, 2])
        assert all(a is b for a, b in zip(again, first, strict=True))
        assert wm.reads[0] == wm.reads[1] == wm.reads[2] == 1
        del first, second, again
        gc.collect()
        wm.get([8])  # nobody holds the others now: evicted as usual, within the budget
        assert wm.resident_bytes <= wm.budget


def test_prefetch_reads_ahead_in_the_scrub_direction(tmp_path) -> None:
    series = zarr_series(tmp_path)
    with WindowManager(series, "10MB", prefetch=2) as wm:
        wm.get([4, 5, 6], direction=+1)
        wm.request([4, 5, 6, 7, 8], direction=0).result()  # waits for the prefetched steps too
        assert wm.reads[7] == 1 and wm.reads[8] == 1
        wm.get([2, 3, 4], direction=-1)
        wm.request([0, 1, 2, 3, 4]).result()
        assert all(wm.reads[s] == 1 for s in range(9))


def warms_looked() -> None:
    """Every warm queued has looked at its manager since (twice: one not ready then goes to the
    back of the queue) and done what it could."""
    for _ in range(2):
        _warmer().submit(lambda: None).result(timeout=10)


@pytest.mark.skipif(resident_bytes() is None, reason="reads /proc/self/statm")
def test_free_slots_for_a_jump_of_a_whole_window_are_faulted_in_once_reads_pause(monkeypatch):
    """A scrub's stop reads the steps the drag passed at once: the free slots they go to are
    warm already, as many as the window is long (within the budget; not the whole budget),
    faulted in once reads have paused (not beside them), and not at all once it is closed."""
    shape, window = (16, 256, 256), 3
    step = int(np.prod(shape)) * 4  # 4 MB: the 10-slot block is a memory map of its own
    series = TimeSeries.from_array(np.ones((12, *shape), np.float32))

    def grown_by(steps: int) -> bool:
        grown = resident_bytes() - before
        return (steps - 0.5) * step <= grown <= (steps + 1.5) * step

    monkeypatch.setattr(TUNING, "warm_after_s", 60.0)
    with WindowManager(series, 10 * step, prefetch=0) as wm:
        before = resident_bytes()
        wm.get(list(range(window)))
        time.sleep(3 * TUNING.warm_poll_s)
        assert grown_by(window)  # reads only: they ran a moment ago
        monkeypatch.setattr(TUNING, "warm_after_s", 0.0)
        warms_looked()
        assert grown_by(2 * window)
        got = wm.get(list(range(window, 2 * window)))  # the jump: into the warm slots
        assert all((a == 1).all() for a in got) and wm.slots.own_arrays == 0
    monkeypatch.setattr(TUNING, "warm_after_s", 60.0)
    with WindowManager(series, 10 * step, prefetch=0) as wm:
        before = resident_bytes()
        wm.get(list(range(window)))
    warms_looked()  # closed: its warm is given up, not waited on
    assert grown_by(window)


def test_a_manager_reading_on_holds_up_neither_warms_nor_memory_of_others(monkeypatch):
    """The process's one warming thread: a warm waiting for its manager's reads to pause (a
    view playing on and on) lets the others' run, and a closed manager's memory, which its warm
    held, goes at once; the thread idle holds nothing of the last warm it ran."""
    series = TimeSeries.from_array(np.ones((8, 4, 64, 64), np.float32))
    monkeypatch.setattr(TUNING, "warm_after_s", 60.0)  # reads never pause that long
    with WindowManager(series, "1MB", prefetch=0) as reading:
        reading.get([0, 1])
        for _ in range(2):
            other = WindowManager(series, "1MB", prefetch=0)
            other.get([0, 1])  # its warm is queued behind the reading one's
            block = weakref.ref(other.slots._block)
            other.close()
            del other
            warms_looked()
            gc.collect()
            assert block() is None
    warms_looked()  # the reading one's too: closed, it gave up
    held = np.ones(4)  # as the slots of the last warm run
    gone = weakref.ref(held)
    _warmer().submit(len, held)
    del held
    deadline = time.monotonic() + 10
    while gone() is not None:  # the thread idle holds nothing of it
        assert time.monotonic() < deadline
        time.sleep(0.01)


def test_free_slots_are_warmed_once_every_managers_reads_have_paused(monkeypatch):
    """A coarse level's manager whose reads paused does not warm its slots beside level 0's
    reads (the refine's, on the same cores): the pause is the process's."""
    faulted = []
    monkeypatch.setattr(
        slots_module, "prefault", lambda slot, between=None: faulted.append(slot.shape)
    )
    monkeypatch.setattr(TUNING, "warm_after_s", 0.0)
    series, gated = gated_series()
    coarse = TimeSeries.from_array(np.ones((8, 2, 8, 8), np.float32))
    with WindowManager(series, "1MB", prefetch=0) as fine, WindowManager(coarse, "1MB") as wm:
        gated.gate.clear()
        reading = fine.request([0])
        assert gated.entered.wait(10)
        wm.get([0, 1])
        warms_looked()
        assert faulted == []  # level 0 still reads
        gated.gate.set()
        reading.result(timeout=10)
        warms_looked()
        assert (2, 8, 8) in faulted


UNCLOSED = """
import sys, numpy as np
from chronocl.core.tuning import TUNING
from chronocl.data import window
from chronocl.data.series import TimeSeries
TUNING.warm_after_s = 600.0
wm = window.WindowManager(TimeSeries.from_array(np.ones((8, 4, 8, 8), np.float32)), 8 * 1024)
wm.get([0, 1])
print("read", flush=True)
"""


def test_a_manager_never_closed_does_not_hold_up_the_exit():
    """The documented `Session(...)` with no `with` or close: its warm, waiting for the reads to
    pause, does not hold the program's end (it did for TUNING.warm_after_s, then faulted in
    slots)."""
    root = Path(__file__).parents[1]
    done = subprocess.run(
        [sys.executable, "-c", UNCLOSED], cwd=root, capture_output=True, text=True, timeout=20
    )
    assert done.returncode == 0 and done.stdout == "read\n", done.stderr


FORKED = """
import os, numpy as np
from chronocl.core.tuning import TUNING
from chronocl.data import window
from chronocl.data.series import TimeSeries
from chronocl.data.slots import _warmer
TUNING.warm_after_s = 600.0
wm = window.WindowManager(TimeSeries.from_array(np.ones((8, 4, 8, 8), np.float32)), 8 * 1024)
wm.get([0, 1])
_warmer()
pid = os.fork()
if pid == 0:
    _warmer().submit(lambda: None).result(timeout=15)
    os._exit(0)
print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), flush=True)
"""


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork")
def test_a_forked_child_warms_on_a_thread_of_its_own():
    """The warming thread does not come along into a forked child: it makes its own (the
    parent's, left behind, would take nothing from the queue: a warm in the child never ran)."""
    root = Path(__file__).parents[1]
    done = subprocess.run(
        [sys.executable, "-c", FORKED], cwd=root, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0 and done.stdout == "0\n", (done.stdout, done.stderr)


def test_superseded_requests_are_cancelled_not_queued() -> None:
    series, gated = gated_series()
    with WindowManager(series, "10MB", threads=1, prefetch=0) as wm:
        gated.gate.clear()
        first = wm.request([0, 1, 2, 3])
        assert gated.entered.wait(10)  # step 0 is being read, 1..3 wait in the queue
        second = wm.request([10, 11, 12])
        with pytest.raises(SupersededError, match="replaced by a newer one"):
            first.result(timeout=10)
        gated.gate.set()
        arrays = second.result(timeout=30)
        assert [int(a[0, 0, 0]) for a in arrays] == [s * 256 for s in (10, 11, 12)]
        assert sorted(set(gated.log)) == [0, 10, 11, 12]  # 1..3 were never read
        assert wm.reads[0] == 0  # the read under way was dropped, not kept
        assert wm.cancelled >= 4


def test_a_request_can_wait_for_steps_another_request_started() -> None:
    series, gated = gated_series()
    with WindowManager(series, "10MB", threads=2, prefetch=0) as wm:
        gated.gate.clear()
        wm.request([5, 6])
        later = wm.request([6, 7])  # 6 keeps loading, 5 is dropped
        gated.gate.set()
        assert [int(a[0, 0, 0]) for a in later.result(timeout=30)] == [6 * 256, 7 * 256]
        assert gated.log.count(6) == 1


def test_read_errors_reach_the_waiting_request() -> None:
    series, gated = gated_series()
    gated.data = None  # every read now fails inside the store
    with WindowManager(series, "10MB", prefetch=0) as wm, pytest.raises(TypeError):
        wm.get([3])


def test_a_warm_that_cannot_start_does_not_strand_the_waiting_request(monkeypatch) -> None:
    """The step is resident before the free slots are warmed: a warm that fails (no thread to
    start) leaves the request woken, not waiting on a notice that never comes."""

    def fails(slots: StepSlots, count: int, ready: object = None) -> None:
        if count:  # a step's own slot (`take`) warms none
            raise RuntimeError("can't start new thread")

    monkeypatch.setattr(StepSlots, "warm", fails)
    series = TimeSeries.from_array(np.ones((4, 2, 8, 8), np.float32))
    with WindowManager(series, "1MB", prefetch=0) as wm:
        t0 = time.monotonic()
        assert len(wm.request([0]).result(timeout=10)) == 1
        assert time.monotonic() - t0 < 5  # woken by the read, not by the timeout


def test_budget_below_one_step_names_the_minimum() -> None:
    series, _ = gated_series(shape=(100, 100, 100))  # 4 MB per step
    with pytest.raises(InvalidParameterError, match=r"cannot hold one time step.*--memory 4MB"):
        WindowManager(series, "1MB")
    with pytest.raises(InvalidParameterError, match="not a size"):
        WindowManager(series, "lots")


def test_window_wider_than_budget_and_steps_outside(tmp_path) -> None:
    series = zarr_series(tmp_path)
    with WindowManager(series, 3 * 2400) as wm:
        with pytest.raises(InvalidParameterError, match="a window of 5 steps"):
            wm.get(range(5))
        with pytest.raises(InvalidSelectionError, match="outside"):
            wm.get([11, 12])


def test_store_modified_underneath_is_detected(tmp_path) -> None:
    series = zarr_series(tmp_path)
    with WindowManager(series, "10MB") as wm:
        wm.get([0, 1])
        arr = zarr.open_group(str(tmp_path / "s.zarr"), mode="a")["data"]
        arr.resize((14, 6, 10, 10))  # two steps appended by a running simulation
        with pytest.raises(StoreChangedError, match="now has shape"):
            wm.get([1, 2])


def test_store_replaced_by_other_values_of_its_shape_is_detected(tmp_path) -> None:
    """A store replaced whole by one of the same shape (the simulation run again, ingested
    with --overwrite): its statistics changed, so the series' (that map its values to
    colours) and the steps held are stale; the next read says so, not a picture of new values
    coloured by the old range. Its levels are still what they were until then."""
    series = zarr_series(tmp_path, shape=(4, 5, 70))  # with a level 1
    with WindowManager(series, "10MB") as wm:
        wm.get([0, 1])
        level = tmp_path / "s.zarr" / "levels" / "1" / "mean" / "zarr.json"
        os.utime(level, ns=(level.stat().st_atime_ns, level.stat().st_mtime_ns + 10**9))
        series.level(1).check_unchanged()  # a level's own statistics are not the store's
        data = np.asarray(zarr.open_group(str(tmp_path / "s.zarr"), mode="r")["data"])
        TimeSeries.from_array(data * 100).save(tmp_path / "s.zarr", overwrite=True)
        with pytest.raises(StoreChangedError, match="replaced by other values of its shape"):
            wm.get([1, 2])
