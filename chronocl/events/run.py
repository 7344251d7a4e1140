"""`events(series, window, ...)`: the features of each step of a window, matched through time
into events and tracks (an `EventGraph`).

Every argument is checked first (`prepare`), before any step is read. Then the steps are read
through the series' normal read path and labelled on a few threads at once (at most
`AHEAD` steps in flight, fewer where the memory budget holds fewer: `steps_in_flight`; each
read into a buffer used again, masked and labelled on its own thread), while this thread
takes them in order and matches each with the step before it: besides the steps in flight,
only the labels of the previous step (and its shown voxels' indices) are held, never the
window. The events and tracks are found once every step is matched
(`chronocl.events.tracking`). Between steps `find` passes a
`chronocl.core.interrupt.checkpoint`: inside `interruptible` (the viewer's events panel) it is
given up there once unwanted and reports how far it got; elsewhere it does nothing.
"""

from __future__ import annotations

import os
import time
from collections import deque
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
    Mask,
    Periodic,
    StepFeatures,
    check_connectivity,
    label_step,
    parse_periodic,
    periodic_text,
)
from chronocl.events.graph import EventGraph, jsonable
from chronocl.events.tracking import SIMILARITY, check_method, classify, link, tracks_of
from chronocl.integration.fit_range import window_range

AHEAD = 4  # steps read and labelled at once, at most (and at most one per host thread)
ORIGIN_XYZ = (0.0, 0.0, 0.0)  # world position of voxel (0, 0, 0), as chronocl's exports place it


def memory_budget() -> int:
    """The memory a `find` plans its steps in flight for, unless given one: an interactive
    session's (`chronocl.core.budget.interactive_memory`, half the memory free, at least 2 GB)."""
    return interactive_memory()


def steps_in_flight(series: TimeSeries, memory: int) -> int:
    """How many steps `find` reads and labels at once within `memory` bytes: each costs its
    read buffer, its mask (a byte a voxel), its labels (4) and the indices of its shown voxels
    (up to 8): at least one, at most AHEAD."""
    voxels = int(np.prod(series.volume_shape))
    per_step = voxels * (np.dtype(series.dtype).itemsize + 13)
    return max(1, min(AHEAD, memory // max(1, per_step)))


@dataclass
class Timings:
    """Where a `find` spent its time, in seconds: reading and labelling (masking, labelling,
    measuring) the steps, each summed over the threads that did it; matching consecutive steps
    and finding the tracks and the graph, on the calling thread; the calling thread's waits
    for the next labelled step; and the whole."""

    read_s: float = 0.0
    label_s: float = 0.0
    match_s: float = 0.0
    wait_s: float = 0.0
    tracks_s: float = 0.0
    total_s: float = 0.0


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


def find(
    job: EventsJob,
    progress: bool = False,
    max_features: int | None = None,
    timings: Timings | None = None,
    memory: int | None = None,
) -> EventGraph:
    """Label, match and track the steps of a prepared job (the module's docstring).
    `max_features`: a step of more features than this is refused as it is labelled
    (InvalidParameterError, before any matching or tracking of it). `timings`, if given, is
    filled in (`Timings`). `memory` (bytes, default `memory_budget`) bounds the steps in
    flight (`steps_in_flight`)."""
    clock = time.perf_counter
    start = clock()
    spent = Timings() if timings is None else timings
    series, steps = job.series, job.selection.steps
    spacing = tuple(float(s) for s in series.spacing)

    # The steps are read, and masked, into buffers used again and again: a fresh step-sized
    # array costs a page fault per page, which on a busy host took as long as the read itself.
    buffers: SimpleQueue[tuple[np.ndarray, np.ndarray]] = SimpleQueue()
    brick = (series.volume_shape[0], 1, *series.volume_shape[1:])

    def labelled(step: int) -> tuple[StepFeatures, float, float]:
        t0 = clock()
        try:
            out, shown = buffers.get_nowait()
        except Empty:
            out, shown = aligned_empty(brick, series.dtype), np.empty(series.volume_shape, bool)
        try:
            values = series.read_brick([step], out=out, per_call=1)[:, 0]
            t1 = clock()
            found = label_step(
                values,
                job.mask,
                step,
                job.connectivity,
                job.periodic,
                spacing,
                ORIGIN_XYZ,
                scratch=shown,
            )
        finally:
            buffers.put((out, shown))
        return found, t1 - t0, clock() - t1

    features, edges, found = [], [], []
    queue: deque[Future] = deque()
    todo = iter(steps)
    # A pool of its own, as many threads as the host pool's: a step's read may itself split
    # its copies over the host pool (`host_threads.copy_all`), which would wait forever for
    # threads that are all busy labelling.
    ahead = steps_in_flight(series, memory_budget() if memory is None else memory)
    with ThreadPoolExecutor(
        max(1, min(workers(), ahead)), thread_name_prefix="chronocl-events"
    ) as pool:

        def submit() -> None:
            step = next(todo, None)
            if step is not None:
                queue.append(pool.submit(labelled, step))

        try:
            for _ in range(ahead):
                submit()
            before: StepFeatures | None = None
            for k in track(range(len(steps)), len(steps), "labelling steps", progress):
                checkpoint("labelling steps", k, len(steps))  # a viewer's find: given up here
                t0 = clock()
                now, read_s, label_s = queue.popleft().result()
                t1 = clock()
                spent.wait_s += t1 - t0
                spent.read_s += read_s
                spent.label_s += label_s
                if max_features is not None and len(now.features) > max_features:
                    raise InvalidParameterError(
                        f"{len(now.features)} features in step {now.step}: raise the threshold "
                        f"or the opacity, or narrow the window (at most {max_features} a step)"
                    )
                submit()
                features += now.features
                if before is not None:
                    pair = link(
                        before.step,
                        before.labels,
                        before.features,
                        now.step,
                        now.labels,
                        now.features,
                        before.voxels,
                    )
                    edges += pair
                    found += classify(before.step, now.step, before.features, now.features, pair)
                before = now
                spent.match_s += clock() - t1
        finally:
            for pending in queue:
                pending.cancel()
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
