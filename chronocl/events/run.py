"""`events(series, window, ...)`: the features of each step of a window, matched through time
into events and tracks (an `EventGraph`).

Every argument is checked first (`prepare`), before any step is read. Then the steps are read
through the series' normal read path and labelled on a few threads at once (at most
`AHEAD` steps in flight, each read, masked and labelled on its own thread), while this thread
takes them in order and matches each with the step before it: besides the steps in flight,
only the labels of the previous step are held, never the window. The events and tracks are
found once every step is matched (`chronocl.events.tracking`). Between steps `find` passes a
`chronocl.core.interrupt.checkpoint`: inside `interruptible` (the viewer's events panel) it is
given up there once unwanted and reports how far it got; elsewhere it does nothing.
"""

from __future__ import annotations

import os
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from chronocl import modes
from chronocl.core.errors import InvalidParameterError, InvalidTransferFunctionError
from chronocl.core.host_threads import workers
from chronocl.core.interrupt import checkpoint
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


def find(job: EventsJob, progress: bool = False, max_features: int | None = None) -> EventGraph:
    """Label, match and track the steps of a prepared job (the module's docstring).
    `max_features`: a step of more features than this is refused as it is labelled
    (InvalidParameterError, before any matching or tracking of it)."""
    series, steps = job.series, job.selection.steps
    spacing = tuple(float(s) for s in series.spacing)

    def labelled(step: int) -> StepFeatures:
        values = series.read_brick([step], per_call=1)[:, 0]
        return label_step(
            values, job.mask, step, job.connectivity, job.periodic, spacing, ORIGIN_XYZ
        )

    features, edges, found = [], [], []
    queue: deque[Future] = deque()
    todo = iter(steps)
    # A pool of its own, as many threads as the host pool's: a step's read may itself split
    # its copies over the host pool (`host_threads.copy_all`), which would wait forever for
    # threads that are all busy labelling.
    with ThreadPoolExecutor(
        max(1, min(workers(), AHEAD)), thread_name_prefix="chronocl-events"
    ) as pool:

        def submit() -> None:
            step = next(todo, None)
            if step is not None:
                queue.append(pool.submit(labelled, step))

        try:
            for _ in range(AHEAD):
                submit()
            before: StepFeatures | None = None
            for k in track(range(len(steps)), len(steps), "labelling steps", progress):
                checkpoint("labelling steps", k, len(steps))  # a viewer's find: given up here
                now = queue.popleft().result()
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
                    )
                    edges += pair
                    found += classify(before.step, now.step, before.features, now.features, pair)
                before = now
        finally:
            for pending in queue:
                pending.cancel()
    nodes = [(f.step, f.id) for f in features]
    paths = tracks_of(job.method, nodes, edges, steps)
    track_of = {node: k for k, path in enumerate(paths) for node in path}
    times = series.times
    return EventGraph(
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
