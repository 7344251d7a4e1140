"""The window manager: the time steps of interest resident in memory, under a byte budget.

A `WindowManager` serves whole time steps of one `TimeSeries` as (Z, Y, X) views of
slots in one block of memory (`chronocl.data.slots`), laid out as the kernels read bricks,
so a window integrates where it lies (`chronocl.data.bricks.ResidentBricks`, `SlotBrick`).
A request names the steps of the current window:

- steps already resident are not read again; missing ones are read on
  background threads, chunk row by chunk row, through zarr (or dask);
- steps that are neither requested nor prefetched stay cached (least recently
  used first out) only while the budget allows;
- after a request, the next steps in the scrub direction are prefetched, as far
  as the budget allows without evicting the window: by default as many as the
  scrub's speed times a step's read time covers (`chronocl.data.scrub_model`);
- a newer request supersedes older ones of the same owner: loads nobody wants any
  more are cancelled before they start, or stop at the next chunk row, and waiting
  on a superseded request raises `SupersededError` instead of queueing behind it.

A manager shared by several sessions (a viewer's panels and clients: `Session`'s `managers`)
keeps each one's window apart: a request names its owner (the session), supersedes only that
owner's earlier requests, and cancels only loads no owner wants (its window or read ahead);
each owner's scrub has its own speed (`ScrubModel`). Requests without an owner share one.
"""

from __future__ import annotations

import os
import sys
import threading
import time
import weakref
from collections import Counter, OrderedDict
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from chronocl.core import process_memory
from chronocl.core.budget import human, parse_memory
from chronocl.core.errors import InvalidParameterError, InvalidSelectionError, SupersededError
from chronocl.core.interrupt import checkpoint, heard
from chronocl.core.tuning import TUNING
from chronocl.data.bricks import ResidentBricks
from chronocl.data.scrub_model import ScrubModel
from chronocl.data.series import TimeSeries
from chronocl.data.slots import StepSlots


@dataclass
class _Load:
    """One step being read: its destination, future and whether it is still wanted."""

    step: int
    array: np.ndarray | None  # None once cancelled: its slot goes back before the read runs
    future: Future | None = None
    abort: threading.Event = field(default_factory=threading.Event)


@dataclass
class _Owner:
    """One owner's window: its steps, those read ahead of it, its newest request and its
    scrub."""

    scrub: ScrubModel
    wanted: frozenset[int] = frozenset()
    ahead: tuple[int, ...] = ()
    generation: int = 0  # of its newest request
    served: int = -1  # the generation whose window `result` last handed out


class Request:
    """The steps of one window, loading; `result()` waits for them."""

    def __init__(
        self, manager: WindowManager, owner: _Owner, generation: int, steps: tuple[int, ...]
    ) -> None:
        self.manager = manager
        self.owner = owner
        self.generation = generation
        self.steps = steps

    @property
    def superseded(self) -> bool:
        return self.owner.generation != self.generation

    def result(self, timeout: float | None = None) -> list[np.ndarray]:
        """The steps' arrays in request order; SupersededError if a newer request came first."""
        return self.manager._wait(self, timeout)


_managers: weakref.WeakSet[WindowManager] = weakref.WeakSet()  # whose reads `_quiet` looks at
_managers_lock = threading.Lock()


class WindowManager:
    """Resident time steps of `series` under `memory` bytes, with prefetch and cancellation.

    `prefetch` is how many steps beyond the window to read ahead in the scrub
    direction (default None: time-aware, as many as the scrub's speed times a step's read
    time covers, at least one, as far as the free slots allow; 0: none);
    `threads` is the number of background readers.
    """

    def __init__(
        self,
        series: TimeSeries,
        memory: str | int | None = None,
        *,
        prefetch: int | None = None,
        threads: int = 2,
    ) -> None:
        self.series = series
        self.budget = parse_memory(memory)
        self.step_bytes = int(np.prod(series.volume_shape)) * series.dtype.itemsize
        if self.budget < self.step_bytes:
            raise InvalidParameterError(
                f"memory budget {human(self.budget)} cannot hold one time step of "
                f"{series.volume_shape} {series.dtype} ({human(self.step_bytes)}); "
                f"use --memory {_round_up_mb(self.step_bytes)}MB or more"
            )
        self.prefetch = prefetch
        # Requests without an owner; the scrub's speed and a step's read time (prefetch=None)
        self._anyone = _Owner(ScrubModel())
        # by id(owner): an owner's death (weakref.finalize) only notes its id in `_dead`, which
        # the lock's holder purges (a collection may run in any thread, mid-iteration)
        self._owners: dict[int, _Owner] = {}
        self._dead: list[int] = []
        self._span = 1  # the last request's distinct steps: free slots kept warm (`_read`)
        self._read_at = 0.0  # when the last read ended (`_quiet`)
        self.generation = 0  # of the newest request of any owner
        self.reads: Counter[int] = Counter()  # completed reads per step (tests: never twice)
        self.cancelled = 0  # loads dropped before they finished
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()  # LRU order, newest last
        self._loads: dict[int, _Load] = {}
        self._failed: dict[int, BaseException] = {}  # read errors, raised to whoever waits
        self._lock = threading.Condition()
        self._pool = ThreadPoolExecutor(
            max_workers=threads, thread_name_prefix="chronocl-window", initializer=_background
        )
        # Steps are read into slots of one block, where a window integrates in place.
        count = min(series.n_steps, self.capacity)
        self.slots = StepSlots(series.volume_shape, series.dtype, count)
        self._closed = False
        with _managers_lock:
            _managers.add(self)
        # The process's limit, where a viewer set one: its other memory comes first.
        self.limit = process_memory.current()
        if self.limit is not None:
            self.limit.register(self)

    # -- public --------------------------------------------------------------------------
    @property
    def scrub(self) -> ScrubModel:
        """The scrub model of requests without an owner (every read's time is in it)."""
        return self._anyone.scrub

    @property
    def capacity(self) -> int:
        """How many steps fit the budget."""
        return self.budget // self.step_bytes

    @property
    def resident_bytes(self) -> int:
        """Bytes held in resident steps and in loads under way."""
        with self._lock:
            return self.step_bytes * (len(self._cache) + len(self._loads))

    def resident(self) -> list[int]:
        with self._lock:
            return sorted(self._cache)

    def hold(self, steps: Sequence[int]) -> dict[int, np.ndarray]:
        """The steps among `steps` resident now, by step (read-only arrays; those not resident
        are left out: read them elsewhere). While the caller keeps the arrays, the steps are
        held as a session's are: never evicted, shed nor dropped (`_held`); letting go of the
        arrays lets them go."""
        with self._lock:
            return {int(s): self._cache[s] for s in steps if s in self._cache}

    def held_bytes(self) -> int:
        """Bytes of memory the steps may hold: every slot written or warmed (a process limit
        counts them, `chronocl.core.process_memory`)."""
        return self.slots.resident_bytes

    def settled_bytes(self) -> int:
        """`held_bytes` less the slots of steps being read (their pages fill as they are).
        Without the lock: another manager's limit asks while holding its own."""
        loading = len(self._loads)
        return max(0, self.slots.resident_bytes - loading * self.step_bytes)

    def shed(self, nbytes: int, ahead: bool = True, wait: bool = True) -> int:
        """Give back about `nbytes` for a process limit: free slots' pages first, then steps
        the window does not hold (least recently used first; those read ahead too, unless
        not `ahead`), then the window's own once it was handed out and nobody holds it. Steps
        a session holds stay. Without `wait`, nothing if another thread holds the lock. The
        bytes given back."""
        if not self._lock.acquire(blocking=wait):
            return 0
        try:
            freed = self.slots.release(nbytes)
            wanted = self._wanted()
            keep = wanted if ahead else wanted | self._read_ahead()
            steps = [s for s in self._cache if s not in keep]
            # Windows handed out: a session showing one holds its arrays (kept below); one
            # nobody holds any more (its client gone) goes last. Not those still awaited.
            awaited: set[int] = set()
            for o in self._all_owners():
                if o.served != o.generation:
                    awaited |= o.wanted
            steps += [s for s in self._cache if s in wanted and s not in awaited]
            for step in steps:
                if freed >= nbytes:
                    break
                if self._held(step):
                    continue  # another view's window: dropping it would free nothing
                del self._cache[step]
                freed += self.slots.release(nbytes - freed, cold=False)  # its slot, now free
            if ahead:
                for load in [ld for s, ld in self._loads.items() if s not in wanted]:
                    if freed >= nbytes:
                        break
                    self._cancel(load)
                    freed += self.slots.release(nbytes - freed, cold=False)
            return freed
        finally:
            self._lock.release()

    def drop(self, steps) -> int:
        """Let resident `steps` go now where no owner's window or read ahead wants them and
        no session holds them (a window that streams from now on); the bytes given back."""
        freed = 0
        with self._lock:
            keep = self._wanted() | self._read_ahead()
            for step in steps:
                if step in self._cache and step not in keep and not self._held(step):
                    del self._cache[step]
                    freed += self.slots.release(self.step_bytes, cold=False)
        return freed

    def _fits(self, ahead: bool) -> bool:
        """Whether one more step may be read under the process's limit, after dropping what
        may be dropped (locked); always true without a limit."""
        if self.limit is None:
            return True
        extra = 0 if self.slots.next_is_warm() else self.step_bytes
        return self.limit.fit(extra, ahead=ahead, caller=self) <= 0

    def state(self) -> dict[str, list[int]]:
        """What is in memory now, from any thread: `resident` steps, steps `loading` (being
        fetched) and those of them read `ahead` of the last request's window."""
        with self._lock:
            loading = sorted(self._loads)
            ahead = self._read_ahead()
            return {
                "resident": sorted(self._cache),
                "loading": loading,
                "ahead": sorted(s for s in ahead if s in self._loads or s in self._cache),
            }

    def request(self, steps: Sequence[int], direction: int = 0, owner: object = None) -> Request:
        """Start loading `steps` (and prefetching beyond them in `direction`: +1, -1 or 0)
        for `owner` (a session sharing the manager; None: anyone without one).

        Supersedes the owner's earlier requests; loads no owner wants any more are cancelled.
        Raises InvalidParameterError when the steps cannot all be resident at once under the
        budget.
        """
        steps = tuple(int(s) for s in steps)
        n = self.series.n_steps
        bad = [s for s in steps if not 0 <= s < n]
        if bad:
            raise InvalidSelectionError(f"steps {bad} are outside the series' [0, {n})")
        self.series.check_unchanged()
        distinct = len(set(steps))
        if distinct > self.capacity:
            raise InvalidParameterError(
                f"a window of {distinct} steps needs "
                f"{human(distinct * self.step_bytes)} resident but the memory budget is "
                f"{human(self.budget)}; use --memory {_round_up_mb(len(steps) * self.step_bytes)}"
                "MB or more, or a shorter window (integrate streams windows of any size)"
            )
        with self._lock:
            who = self._owner(owner)
        if steps:
            who.scrub.record_request(min(steps), direction)
        ahead = self._prefetch_steps(steps, direction, who.scrub)
        with self._lock:
            if self._closed:
                raise InvalidParameterError("this window manager is closed; make a new one")
            self.generation += 1
            who.generation, who.wanted, who.ahead = self.generation, frozenset(steps), tuple(ahead)
            self._span = max(1, distinct)
            for s in steps:
                self._failed.pop(s, None)
            wanted = self._wanted()
            keep = wanted | self._read_ahead()
            for step, load in list(self._loads.items()):
                if step not in keep:
                    self._cancel(load)
            for s in steps:
                if s in self._cache:
                    self._cache.move_to_end(s)
            # the window, and those of other owners still waiting for theirs; the windows
            # handed out give way where nobody holds their steps (`_held`)
            protect = set(steps) | self._awaited()
            for s in steps:
                if s not in self._cache and s not in self._loads:
                    self._make_room(protect=protect)
                    self._fits(ahead=True)  # the window is read over the limit if it must be
                    self._start(s)
            for s in ahead:
                if s in self._cache or s in self._loads:
                    continue
                # Read ahead only into a free slot: with every slot held (steps the session
                # still reads), a step read ahead would lie apart from its window.
                if not self._make_room(protect=keep) or not self.slots.free:
                    break
                if not self._fits(ahead=False):
                    break
                self._start(s)
            return Request(self, who, self.generation, steps)

    def get(
        self, steps: Sequence[int], direction: int = 0, owner: object = None
    ) -> list[np.ndarray]:
        """Request `steps` and wait for them (the arrays must be treated as read-only)."""
        return self.request(steps, direction, owner).result()

    def brick(self, steps: Sequence[int], z0: int = 0, z1: int | None = None) -> np.ndarray:
        """Rows [z0, z1) of resident steps as an xytz brick (z1 - z0, W, Y, X)."""
        arrays = dict(zip(steps, self.get(steps), strict=True))
        return ResidentBricks(arrays, in_place=False).read(steps, z0, z1)

    def let_go(self, owner: object = None) -> None:
        """The owner that asked for its last window is gone (a viewer's panel or client left,
        or left the data set): its window's steps give way once nobody holds them, and
        nothing is read ahead for it any more."""
        with self._lock:
            if owner is None:
                self._anyone.wanted, self._anyone.ahead = frozenset(), ()
            else:
                self._owners.pop(id(owner), None)
            keep = self._wanted() | self._read_ahead()
            for step, load in list(self._loads.items()):  # loads nobody wants any more
                if step not in keep:
                    self._cancel(load)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            for load in list(self._loads.values()):
                self._cancel(load)
            self._cache.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> WindowManager:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals (the lock is held where noted) ------------------------------------------
    def _owner(self, key: object) -> _Owner:
        """The owner `key` (locked; weakly referenced): made at its first request, its scrub's
        read time that of the reads so far."""
        if key is None:
            return self._anyone
        self._purge()
        who = self._owners.get(id(key))
        if who is None:
            who = self._owners[id(key)] = _Owner(ScrubModel(self.scrub.clock))
            who.scrub.read_s = self.scrub.read_s
            weakref.finalize(key, self._dead.append, id(key))
        return who

    def _purge(self) -> None:
        """Forget the owners that died (locked)."""
        while self._dead:
            self._owners.pop(self._dead.pop(), None)

    def _all_owners(self) -> list[_Owner]:
        self._purge()
        return [self._anyone, *self._owners.values()]

    def _awaited(self) -> set[int]:
        """The steps of the windows requested and not yet handed out (locked)."""
        return set().union(*(o.wanted for o in self._all_owners() if o.served != o.generation))

    def _wanted(self) -> set[int]:
        """The steps of every owner's window (locked)."""
        return set().union(*(o.wanted for o in self._all_owners()))

    def _read_ahead(self) -> set[int]:
        """The steps read ahead of every owner's window (locked)."""
        return set().union(*(o.ahead for o in self._all_owners()))

    def _prefetch_steps(
        self, steps: tuple[int, ...], direction: int, scrub: ScrubModel
    ) -> list[int]:
        if not direction or not steps:
            return []
        stride = abs(steps[-1] - steps[0]) // (len(steps) - 1) if len(steps) > 1 else 1
        stride = max(1, stride)
        if self.prefetch is None:  # time-aware, within the slots the window leaves free
            count = min(scrub.ahead(stride), self.capacity - len(set(steps)))
        else:
            count = self.prefetch
        edge = max(steps) if direction > 0 else min(steps)
        ahead = [edge + direction * stride * (i + 1) for i in range(count)]
        return [s for s in ahead if 0 <= s < self.series.n_steps]

    def _make_room(self, protect: set[int]) -> bool:
        """Evict least recently used steps outside `protect` until one more step fits (locked).
        A step a session still holds (another view's or client's window) is not evicted: that
        would free nothing, and its next frame would read it again."""
        while self.step_bytes * (len(self._cache) + len(self._loads) + 1) > self.budget:
            victim = next((s for s in self._cache if s not in protect and not self._held(s)), None)
            if victim is not None:
                del self._cache[victim]
                continue
            load = next((ld for s, ld in self._loads.items() if s not in protect), None)
            if load is None:
                return False
            self._cancel(load)
        return True

    def _held(self, step: int) -> bool:
        """Whether a session holds the cached step's array (locked)."""
        return sys.getrefcount(self._cache[step]) > HELD_BY_CACHE_ONLY

    def _start(self, step: int) -> None:
        """Reserve the step's memory and submit its read (locked)."""
        load = _Load(step, self.slots.take())  # free slots warmed once reads pause (`_read`)
        self._loads[step] = load
        load.future = self._pool.submit(self._read, load)

    def _quiet(self) -> bool | None:
        """Whether no read of any manager has run for `TUNING.warm_after_s` (None: this one closed):
        slots are warmed then, not beside the reads and the frame made of them, on the same
        cores (a coarse level's reads paused while level 0's, the refine's, went on)."""
        with self._lock:
            if self._closed:
                return None
        with _managers_lock:
            managers = list(_managers)
        now = time.monotonic()
        return all(m._idle(now) for m in managers)

    def _idle(self, now: float) -> bool:
        with self._lock:
            return self._closed or (not self._loads and now - self._read_at >= TUNING.warm_after_s)

    def _cancel(self, load: _Load) -> None:
        """Drop a load nobody wants: not started -> never runs; running -> stops (locked)."""
        load.abort.set()
        if load.future is not None:
            load.future.cancel()
        # A queued read's work item keeps the load until a reader takes it: let go of the
        # slot now, or steps cancelled behind a slow store hold slots that reads ahead need.
        load.array = None
        self._loads.pop(load.step, None)
        self.cancelled += 1
        self._lock.notify_all()

    def _read(self, load: _Load) -> None:
        """Read one step chunk row by chunk row, stopping early when cancelled."""
        nz = self.series.volume_shape[0]
        rows = self.series.z_chunk
        array = load.array
        t0 = time.perf_counter()
        try:
            for z0 in range(0, nz, rows):
                if load.abort.is_set() or array is None:
                    return
                z1 = min(nz, z0 + rows)
                self.series.read_rows(load.step, z0, z1, array[z0:z1])
        except BaseException as exc:
            with self._lock:
                if self._loads.get(load.step) is load:
                    del self._loads[load.step]
                    self._failed[load.step] = exc
                self._lock.notify_all()
            raise
        with self._lock:
            if load.abort.is_set() or self._loads.get(load.step) is not load:
                return
            del self._loads[load.step]
            self._cache[load.step] = array
            self.reads[load.step] += 1
            self._read_at = time.monotonic()
            owners = self._all_owners()
            self._lock.notify_all()  # first: a warm that fails must not strand the waiters
            # Free slots warmed ahead, enough for a jump of a whole window (a scrub's stop reads
            # the steps the drag passed at once, each into a slot never written while the budget
            # was not yet filled), within the budget, once reads have paused (`_quiet`).
            if not self._loads:
                count = min(self.capacity - len(self._cache), self._span)
                if self.limit is not None:
                    count = min(count, max(0, self.limit.room()) // self.step_bytes)
                self.slots.warm(count, self._quiet)
        took = time.perf_counter() - t0
        for o in owners:  # a step's read time is the store's: every owner's scrub learns it
            o.scrub.record_read(took)

    def _wait(self, request: Request, timeout: float | None) -> list[np.ndarray]:
        deadline = None if timeout is None else time.monotonic() + timeout
        # Work that may be given up, or is told of (`chronocl.core.interrupt`), looks up every
        # `TUNING.watched_poll_s` seconds (a load wakes it at once either way).
        poll = TUNING.watched_poll_s if heard() else None
        while True:
            with self._lock:
                missing = [s for s in request.steps if s not in self._cache]
                if request.superseded and missing:
                    raise SupersededError(
                        f"the request for steps {list(request.steps)} was replaced by a newer one"
                    )
                if not missing:
                    for s in request.steps:
                        self._cache.move_to_end(s)
                    if not request.superseded:
                        request.owner.served = request.generation
                    return [self._cache[s] for s in request.steps]
                for s in missing:
                    if s in self._failed:
                        raise self._failed[s]
                    if s not in self._loads:
                        raise SupersededError(
                            f"step {s} of the request was dropped; request the window again"
                        )
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise TimeoutError(f"steps {missing} did not load within {timeout} s")
                wait = left if poll is None else poll if left is None else min(poll, left)
                self._lock.wait(wait)
                loaded = len(request.steps) - len(missing)
            # Outside the lock: a checkpoint may tell the client how far the read got.
            if poll is not None:
                checkpoint("reading steps", loaded, len(request.steps))


# sys.getrefcount of a cached step's array that only the cache holds: the dict's reference and
# the call's argument. A session integrating the step (another view's window) holds one more.
HELD_BY_CACHE_ONLY = 2


def _round_up_mb(n: int) -> int:
    return -(-n // 10**6)


def _background() -> None:
    """Readers run at a lower priority (Linux: a thread's own nice value): a read someone
    waits for has the cores to itself anyway, and reads ahead then take only the cores the
    frames leave idle (on 2 cores they doubled the longest scrub stall at normal priority)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), TUNING.reader_nice)
    except (AttributeError, OSError):  # not Linux, or not allowed: normal priority
        pass
