"""`events(series, window, ...)`: the features of each step of a window, matched through time
into events and tracks (an `EventGraph`).

Every argument is checked first (`prepare`), before any step is read. Then the steps are read
through the series' normal read path and labelled a few at once (at most `AHEAD` steps in
flight, fewer where the memory budget holds fewer: `steps_in_flight`), while this thread takes
them in order and matches each with the step before it: besides the steps in flight, only the
previous step's labels (and its shown voxels' indices) are held, never the window. The
labelling runs on threads (`_Threads`: each step read into a buffer used again, masked and
labelled on its own thread; connected-components-3d holds the GIL, so one labels at a time),
or, for a large window of a stored series on two or more cores (`on_processes`), on worker
processes that read their steps from the store themselves and count each step's overlaps with
the step before (`chronocl.events.processes`): every core labels. Steps a window manager holds
(`resident`: the viewer's) are labelled where they lie, on threads. The events and tracks are
found once every step is matched (`chronocl.events.tracking`). Between steps `find` passes a
`chronocl.core.interrupt.checkpoint`: inside `interruptible` (the viewer's events panel) it is
given up there once unwanted and reports how far it got; elsewhere it does nothing.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import time
from collections import deque
from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from queue import Empty, SimpleQueue

import numpy as np

from chronocl import modes
from chronocl.core.budget import interactive_memory
from chronocl.core.errors import InvalidParameterError, InvalidTransferFunctionError
from chronocl.core.host_threads import workers
from chronocl.core.interrupt import checkpoint
from chronocl.core.memory import aligned_empty
from chronocl.core.progress import track
from chronocl.core.selection import Selection, parse_selection
from chronocl.core.tf import GLOBAL, DataTF, TFSetting
from chronocl.data.series import TimeSeries, open_series
from chronocl.events.features import (
    Feature,
    Mask,
    Periodic,
    StepFeatures,
    check_connectivity,
    label_step,
    parse_periodic,
    periodic_text,
)
from chronocl.events.graph import EventGraph, jsonable
from chronocl.events.processes import Labellers
from chronocl.events.tracking import (
    SIMILARITY,
    Edge,
    check_method,
    classify,
    link,
    tracks_of,
)
from chronocl.integration.fit_range import window_range

AHEAD = 4  # steps read and labelled at once, at most (and at most one per host thread)
ORIGIN_XYZ = (0.0, 0.0, 0.0)  # world position of voxel (0, 0, 0), as chronocl's exports place it
# A window of fewer voxels (steps x voxels a step) labels on threads even from a store:
# starting the worker processes costs about 1.7 s of CPU (each imports chronocl, zarr, dask
# and cc3d and faults its buffers in), which a short window does not win back. Measured on 2
# cores shared with other work (load 3-5), one find per fresh process, the 512^3 vortex of
# bench/events.py, wall seconds, threads (2) against processes (2): 8 steps 5.2-6.8 against
# 6.7-8.7, 12 steps 8.9-9.1 against 7.1-9.6, 20 steps median 15.4 against 11.3 (of 5 each).
PROCESS_MIN_VOXELS = 1_500_000_000  # about 11 steps of 512^3


def memory_budget() -> int:
    """The memory a `find` plans its steps in flight for, unless given one: an interactive
    session's (`chronocl.core.budget.interactive_memory`, half the memory free, at least 2 GB)."""
    return interactive_memory()


# Bytes a voxel of a step in flight may hold besides its read buffer (the series' itemsize).
# On threads: its mask (1), its labels (4) and the indices of its shown voxels (8).
THREAD_BYTES_PER_VOXEL = 13
# On a worker process, every shown (the worst case): its mask (1), its labels (4), a second
# copy of them while periodic faces renumber them (4), its published voxels' indices and
# labels (8 + 4) and their copy in the shared-memory files (12), the step before's voxels and
# labels read back (12), and that step's files, kept until the caller has matched it (12).
PROCESS_BYTES_PER_VOXEL = 57


def steps_in_flight(series: TimeSeries, memory: int, processes: bool = False) -> int:
    """How many steps `find` reads and labels at once within `memory` bytes, at least one, at
    most AHEAD: each costs its read buffer and THREAD_BYTES_PER_VOXEL, or on worker processes
    (`processes`) PROCESS_BYTES_PER_VOXEL a voxel."""
    voxels = int(np.prod(series.volume_shape))
    extra = PROCESS_BYTES_PER_VOXEL if processes else THREAD_BYTES_PER_VOXEL
    per_step = voxels * (np.dtype(series.dtype).itemsize + extra)
    return max(1, min(AHEAD, memory // max(1, per_step)))


@dataclass
class Timings:
    """Where a `find` spent its time, in seconds: reading and labelling (masking, labelling,
    measuring; on worker processes counting the overlaps too) the steps, each summed over the
    threads or processes that did it; matching consecutive steps and finding the tracks and
    the graph, on the calling thread; the calling thread's waits for the next labelled step;
    and the whole. Where processes labelled, how many and their peak memory."""

    read_s: float = 0.0
    label_s: float = 0.0
    match_s: float = 0.0
    wait_s: float = 0.0
    tracks_s: float = 0.0
    total_s: float = 0.0
    processes: int = 0  # worker processes that labelled the steps; 0: threads of this process
    worker_peak_rss: int = 0  # their peak RSS summed (bytes; counts shared label files twice)


@dataclass(frozen=True)
class EventsJob:
    """A checked request: which steps of which series, what a step shows, how to track."""

    series: TimeSeries
    selection: Selection
    mask: Mask
    connectivity: int
    periodic: Periodic
    method: str


def events(
    series: object,
    window: object = None,
    *,
    threshold: float | None = None,
    tf: object = None,
    opacity: float | None = None,
    connectivity: int = 26,
    periodic: object = False,
    tracks: str = "global",
    progress: bool = False,
) -> EventGraph:
    """The features, events and tracks of the window's steps of `series`.

    `series` is a TimeSeries, a store's path (or URL) or an array (T, Z, Y, X); `window` is
    't0:t1[:stride]', a list of steps, a slice or a Selection (default: every step). A step
    shows the voxels whose value is at least `threshold` (data units), or, given a data
    transfer function `tf` (a DataTF, a TFSetting or a TF JSON file's path), those whose TF
    opacity exceeds `opacity` (default 0), values normalised over the TF's value range
    (fitted to the window, where it asks for that, as `chronocl.integrate` fits it).
    Components are `connectivity` 6, 18 or 26 connected; `periodic` names the axes whose
    faces join ("x", "xyz", True for all). `tracks` is "global" (cheapest paths through the
    window) or "local" (each step pair's largest overlaps): `chronocl.events.tracking`.
    """
    job = prepare(
        series,
        window,
        threshold=threshold,
        tf=tf,
        opacity=opacity,
        connectivity=connectivity,
        periodic=periodic,
        tracks=tracks,
    )
    return find(job, progress)


def prepare(
    series: object,
    window: object = None,
    *,
    threshold: float | None = None,
    tf: object = None,
    opacity: float | None = None,
    connectivity: int = 26,
    periodic: object = False,
    tracks: str = "global",
) -> EventsJob:
    """Every argument of `events` checked (one line on the first bad one), the series opened."""
    connectivity = check_connectivity(connectivity)
    axes = parse_periodic(periodic)
    method = check_method(tracks)
    data_tf = _mask_arguments(threshold, tf, opacity)
    if data_tf is not None:  # the opacity checked before the series is opened
        Mask.of_tf(data_tf, (0.0, 1.0), 0.0 if opacity is None else opacity)
    else:
        Mask.of_threshold(threshold)
    opened = as_series(series)
    selection = parse_selection(window, opened.n_steps, opened.times)
    if data_tf is None:
        mask = Mask.of_threshold(threshold)
    else:
        value_range = _value_range(opened, selection, data_tf)
        mask = Mask.of_tf(data_tf, value_range, 0.0 if opacity is None else opacity)
    return EventsJob(opened, selection, mask, connectivity, axes, method)


def as_series(series: object) -> TimeSeries:
    """A TimeSeries as it is; a store's path or URL opened; an array (T, Z, Y, X) wrapped."""
    if isinstance(series, TimeSeries):
        return series
    if isinstance(series, str | os.PathLike):
        return open_series(series)
    if isinstance(series, np.ndarray) or hasattr(series, "__array__"):
        if np.ndim(series) != 4:
            raise InvalidParameterError(
                f"an array of steps must be (T, Z, Y, X); got shape {np.shape(series)}"
            )
        return TimeSeries.from_array(series)
    raise InvalidParameterError(
        f"cannot find events in {type(series).__name__}; give a TimeSeries, a store's path "
        "or an array (T, Z, Y, X)"
    )


def _mask_arguments(threshold: object, tf: object, opacity: object) -> DataTF | None:
    """The data TF a step is masked by, None for a value threshold; the combination checked."""
    if tf is None:
        if opacity is not None:
            raise InvalidParameterError(
                "opacity= is a threshold on a transfer function's opacity: give tf= with it, "
                "or threshold= alone for a threshold on the values"
            )
        if threshold is None:
            raise InvalidParameterError(
                "say what a step shows: threshold= (a value in data units, e.g. "
                "threshold=0.3) or tf= (a data transfer function, with opacity=)"
            )
        return None
    if threshold is not None:
        raise InvalidParameterError(
            "give threshold= (values) or tf= (a TF's opacity), not both; a TF's opacity "
            "threshold is opacity="
        )
    if isinstance(tf, DataTF):
        return tf
    if isinstance(tf, TFSetting):
        return tf.data_tf
    if isinstance(tf, str | os.PathLike):
        return TFSetting.load(tf).data_tf
    raise InvalidTransferFunctionError(
        f"tf {tf!r} is not a transfer function; give a DataTF, a TFSetting or a TF JSON file"
    )


def _value_range(series: TimeSeries, selection: Selection, data_tf: DataTF) -> tuple[float, float]:
    """What normalises the values for `data_tf`: its own range, the series' recorded range,
    or the range fitted to the window as the default mode fits it."""
    kind = data_tf.range_kind
    if kind == "given":
        return data_tf.value_range  # type: ignore[return-value]
    if kind == GLOBAL:
        return (series.vmin, series.vmax)
    return window_range(series, selection, modes.get(modes.DEFAULT))


def on_processes(series: TimeSeries, count: int, steps: int) -> bool:
    """Whether `find` labels `steps` steps of `series` on `count` worker processes
    (`chronocl.events.processes`) rather than on threads: where there are two or more, the
    series is read from a store (so each worker reads its steps itself) and the window is
    large enough to repay starting them (`PROCESS_MIN_VOXELS`)."""
    stored = series.zarr_array is not None and series.host is None
    voxels = steps * int(np.prod(series.volume_shape))
    return count > 1 and stored and voxels >= PROCESS_MIN_VOXELS


@dataclass(frozen=True)
class _Labelled:
    """A step labelled on a thread: its features and what its read and labelling took."""

    found: StepFeatures
    read_s: float
    label_s: float


class _Threads:
    """Steps labelled on `count` threads of this process, with the interface of
    `chronocl.events.processes.Labellers`: `submit`, `features`, `edges`, `release`."""

    def __init__(
        self,
        job: EventsJob,
        spacing: tuple[float, ...],
        count: int,
        resident: Mapping[int, np.ndarray],
    ) -> None:
        self.job, self.spacing, self.resident = job, spacing, resident
        series = job.series
        # The steps are read, and masked, into buffers used again and again: a fresh
        # step-sized array costs a page fault per page, which on a busy host took as long as
        # the read itself.
        self.buffers: SimpleQueue[tuple[np.ndarray, np.ndarray]] = SimpleQueue()
        self.brick = (series.volume_shape[0], 1, *series.volume_shape[1:])
        # A pool of its own: a step's read may itself split its copies over the host pool
        # (`host_threads.copy_all`), which would wait forever for threads that are all busy
        # labelling.
        self.pool = ThreadPoolExecutor(count, thread_name_prefix="chronocl-events")

    def __enter__(self) -> _Threads:
        return self

    def __exit__(self, *exc: object) -> None:
        self.pool.shutdown()

    def submit(self, step: int, previous: int | None = None) -> Future:
        """The step's `_Labelled`; `previous` is for `Labellers`' interface (matching is
        `edges`')."""
        return self.pool.submit(self._label, step)

    def _label(self, step: int) -> _Labelled:
        job, series, clock = self.job, self.job.series, time.perf_counter
        t0 = clock()
        try:
            out, shown = self.buffers.get_nowait()
        except Empty:
            out, shown = (
                aligned_empty(self.brick, series.dtype),
                np.empty(series.volume_shape, bool),
            )
        try:
            if step in self.resident:
                values = self.resident[step]  # labelled where it lies
            else:
                values = series.read_brick([step], out=out, per_call=1)[:, 0]
            t1 = clock()
            found = label_step(
                values,
                job.mask,
                step,
                job.connectivity,
                job.periodic,
                self.spacing,
                ORIGIN_XYZ,
                scratch=shown,
            )
        finally:
            self.buffers.put((out, shown))
        return _Labelled(found, t1 - t0, clock() - t1)

    @staticmethod
    def features(done: _Labelled) -> tuple[Feature, ...]:
        return done.found.features

    @staticmethod
    def edges(before: _Labelled, done: _Labelled) -> list[Edge]:
        """The overlap edges from the features of the step before (`before`) to `done`'s."""
        a, b = before.found, done.found
        return link(a.step, a.labels, a.features, b.step, b.labels, b.features, a.voxels)

    @staticmethod
    def release(done: _Labelled) -> None:
        """Nothing to remove: the step's arrays go with the last reference to them."""


def find(
    job: EventsJob,
    progress: bool = False,
    max_features: int | None = None,
    timings: Timings | None = None,
    memory: int | None = None,
    resident: Mapping[int, np.ndarray] | None = None,
    processes: bool = True,
) -> EventGraph:
    """Label, match and track the steps of a prepared job (the module's docstring).
    `max_features`: a step of more features than this is refused as it is labelled
    (InvalidParameterError, before any matching or tracking of it). `timings`, if given, is
    filled in (`Timings`). `memory` (bytes, default `memory_budget`) bounds the steps in
    flight (`steps_in_flight`). `resident`: steps of the series already in memory, by step
    (a window manager's, `WindowManager.hold`), labelled where they lie, not read again."""
    clock = time.perf_counter
    start = clock()
    spent = Timings() if timings is None else timings
    series, steps = job.series, job.selection.steps
    spacing = tuple(float(s) for s in series.spacing)

    budget = memory_budget() if memory is None else memory
    ahead = steps_in_flight(series, budget)
    count = max(1, min(workers(), ahead))
    resident = resident or {}
    use_processes = False
    if processes and not resident:  # planned for processes: a step on a worker holds more
        on_ahead = steps_in_flight(series, budget, processes=True)
        on_count = max(1, min(workers(), on_ahead))
        use_processes = on_processes(series, on_count, len(steps))
        if use_processes:
            ahead, count = on_ahead, on_count
    features, edges, found = [], [], []
    with contextlib.ExitStack() as stack:
        labeller = None
        if use_processes:
            with contextlib.suppress(pickle.PicklingError, TypeError, AttributeError):
                labeller = stack.enter_context(
                    Labellers(
                        series,
                        job.mask,
                        job.connectivity,
                        job.periodic,
                        spacing,
                        ORIGIN_XYZ,
                        count,
                    )
                )  # a series that does not pickle (a remote store's session) stays on threads
        if labeller is None:
            labeller = stack.enter_context(_Threads(job, spacing, count, resident))
        spent.processes = count if isinstance(labeller, Labellers) else 0
        queue: deque[Future] = deque()
        todo = iter(steps)
        given: list[int] = []  # the steps given out, in order

        def submit() -> None:
            step = next(todo, None)
            if step is not None:
                queue.append(labeller.submit(step, given[-1] if given else None))
                given.append(step)

        try:
            for _ in range(ahead):
                submit()
            before = None
            for k in track(range(len(steps)), len(steps), "labelling steps", progress):
                checkpoint("labelling steps", k, len(steps))  # a viewer's find: given up here
                t0 = clock()
                done = queue.popleft().result()
                now = labeller.features(done)
                t1 = clock()
                spent.wait_s += t1 - t0
                spent.read_s += done.read_s
                spent.label_s += done.label_s
                if max_features is not None and len(now) > max_features:
                    raise InvalidParameterError(
                        f"{len(now)} features in step {steps[k]}: raise the threshold "
                        f"or the opacity, or narrow the window (at most {max_features} a step)"
                    )
                submit()
                features += now
                if before is not None:
                    pair = labeller.edges(before, done)
                    edges += pair
                    found += classify(steps[k - 1], steps[k], labeller.features(before), now, pair)
                    labeller.release(before)
                before = done
                spent.match_s += clock() - t1
        finally:
            for pending in queue:
                pending.cancel()
            if isinstance(labeller, Labellers):
                spent.worker_peak_rss = sum(labeller.peaks.values())
    t0 = clock()
    nodes = [(f.step, f.id) for f in features]
    paths = tracks_of(job.method, nodes, edges, steps)
    track_of = {node: k for k, path in enumerate(paths) for node in path}
    times = series.times
    graph = EventGraph(
        features=[
            {**f.to_dict(), "time": jsonable(times[f.step]), "track": track_of[f.step, f.id]}
            for f in features
        ],
        edges=[e.to_dict() for e in edges],
        events=[e.to_dict() for e in found],
        tracks=[
            {
                "id": k,
                "start": path[0][0],
                "end": path[-1][0],
                "length": len(path),
                "features": [list(node) for node in path],
            }
            for k, path in enumerate(paths)
        ],
        meta=_meta(job, spacing),
    )
    spent.tracks_s = clock() - t0
    spent.total_s = clock() - start
    return graph


def _meta(job: EventsJob, spacing: tuple[float, ...]) -> dict:
    series, steps = job.series, job.selection.steps
    return {
        "source": series.source or (str(series.path) if series.path is not None else ""),
        "store": str(series.path.resolve()) if series.path is not None else None,
        "steps": list(steps),
        "times": [jsonable(series.times[s]) for s in steps],
        "time_unit": series.time_unit,
        "volume_shape_zyx": list(series.volume_shape),
        "spacing_xyz": list(spacing),
        "origin_xyz": list(ORIGIN_XYZ),
        "mask": job.mask.to_dict(),
        "connectivity": job.connectivity,
        "periodic": periodic_text(job.periodic),
        "similarity": SIMILARITY,
        "tracks_method": job.method,
    }
