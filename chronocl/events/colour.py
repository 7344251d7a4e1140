"""Track colouring: every voxel of a chronovolume takes the colour of the track that reached it,
so a merge of two features shows as two colours flowing into one.

**Which voxels, which track.** Only a mode that keeps one winning step per voxel can say which
feature reached a voxel: first_hit (the first step over the opacity threshold), max and min
(the step of the extreme value) and change (the step the largest change happened at): the
registry's modes with a ``t_index`` (`WINNER_MODES`). A voxel's track is the track of the
feature holding the voxel at its winning step s = t_index: the label of the voxel in step s,
as `chronocl.events` labelled that step (the events file's own mask, connectivity and
periodic axes), gives the feature (s, id), and the event graph gives that feature's track. A
mode that blends many steps into a voxel (alpha, additive, mean, count) has no such step and
is refused before any work (`check_mode`).

**Its colour.** The voxel keeps the opacity the mode gave it and takes the track's colour,
premultiplied: RGBA = (α·r, α·g, α·b, α). By ``id`` (the default) the colour is the track id's
in a qualitative palette (`chronocl.events.palette`), the events picture's for its tracks
(`chronocl.events.plot`): track k has colour k mod 20, whatever the window or the mode, so a
track keeps its colour from picture to picture. By ``time`` the colour is the chronovolume's
time TF colour rgb_t(p) (its opacity a_t is not used) at the first of the chronovolume's steps
where the track has a feature, i.e. when the track first shows in the window: old tracks and
new ones read as the time legend reads.

first_hit wins at the first step whose opacity exceeds its threshold (default 0), which may
be the faint leading edge of a moving feature, under the events' threshold: that voxel is then
transparent. Find the events with the render's data TF, its value range given (not fitted,
which differs from mode to mode), and give first_hit the same opacity threshold (``chronocl
events --tf TF.json --opacity 0.1``, ``chronocl render --tf TF.json --mode first_hit
--threshold 0.1``): every voxel first_hit shows then lies in a feature at its winning step.

**The rest.** A voxel with no winning step (t_index -1), or outside every feature at its
winning step (its value there under the events' threshold: e.g. the faint halo of a max), is
transparent: the picture shows the features the event graph tracks and nothing else.

The labels are not kept in the events file: each winning step is read again through the
read path of the series given (else of the store the chronovolume or the events name; data
given as an array, an xarray or a URL name none, so the series must be given) and labelled
again (only the steps some voxel won at, a few at once on threads, as `chronocl.events`
labels them, and each dropped once its voxels are looked up), with
`chronocl.events.features.label_step`, which numbers a step's features as `chronocl.events`
numbered them; the features found must match the graph's (their sizes), else the events were
found in other data and the colouring is refused.
"""

from __future__ import annotations

import itertools
import os
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from chronocl import modes as _modes
from chronocl.core.errors import InvalidDataError, InvalidParameterError
from chronocl.core.tf import DataTF
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.events.features import (
    Mask,
    StepFeatures,
    check_connectivity,
    label_step,
    parse_periodic,
)
from chronocl.events.graph import EventGraph
from chronocl.events.palette import track_rgb

BY = ("id", "time")  # what a track's colour says: which track, or when it first shows
# what colours a render's voxels (`chronocl.render(colour=)`, `chronocl render --colour`):
# the transfer functions as the mode applies them, or the track, by id or by time
COLOURINGS = {"tf": None, "track": "id", "track-time": "time"}
META_KEY = "track_colour"  # a track-coloured chronovolume's metadata: how, and its tracks


def winner_modes() -> tuple[str, ...]:
    """The modes that keep one winning step per voxel (a t_index): those track colouring takes."""
    return tuple(m.name for m in _modes.REGISTRY.values() if m.has_t_index)


def check_by(by: object) -> str:
    """'id' or 'time', else one line naming them."""
    if by not in BY:
        raise InvalidParameterError(
            f"track colour by {by!r}: choose id (a colour per track) or time (the time TF's "
            "colour where the track first shows)"
        )
    return str(by)


def parse_colouring(colour: object) -> str | None:
    """The track colouring `colour` names ("track": by "id", "track-time": by "time"), None
    for "tf" (the mode's own colours); else one line naming the choices."""
    if not isinstance(colour, str) or colour not in COLOURINGS:
        raise InvalidParameterError(
            f"colour {colour!r} is not one of tf (the transfer functions, as the mode applies "
            "them), track (a colour per track) or track-time (the time colour where each "
            "track first shows)"
        )
    return COLOURINGS[colour]


def check_mode(mode: object) -> str:
    """`mode` when it keeps a winning step per voxel, else one line naming the modes that do."""
    name = _modes.get(mode).name  # an unknown mode: one line naming them all
    if not _modes.get(name).has_t_index:
        raise InvalidParameterError(
            f"track colouring needs a mode that keeps each voxel's winning step: "
            f"{', '.join(winner_modes())}; {name} blends many steps into a voxel, so no "
            "one feature reached it"
        )
    return name


def check_graph(graph: object) -> EventGraph:
    """`graph` when it is an EventGraph, else one line saying where one comes from."""
    if not isinstance(graph, EventGraph):
        raise InvalidParameterError(
            f"track colouring needs the window's events: give events=chronocl.events(...) "
            f"or chronocl.load_events(path), not {type(graph).__name__}"
        )
    return graph


def check_steps(graph: EventGraph, steps: Sequence[int], shape_zyx: Sequence[int]) -> None:
    """One line where the events cannot colour a chronovolume of `steps` and `shape_zyx`: they
    lack one of its steps, or lie in a volume of another shape."""
    known = set(graph.meta.get("steps") or {f["step"] for f in graph.features})
    missing = [s for s in steps if s not in known]
    if missing:
        some = ", ".join(map(str, missing[:5])) + (" ..." if len(missing) > 5 else "")
        raise InvalidParameterError(
            f"the events were found over other steps than the window's: step {some} has none; "
            "find the events over a window that holds the rendered one (chronocl events "
            "--window)"
        )
    shape = graph.meta.get("volume_shape_zyx")
    if shape is not None and list(shape) != list(shape_zyx):
        raise InvalidParameterError(
            f"the events lie in a {'x'.join(map(str, shape[::-1]))} volume, the chronovolume "
            f"is {'x'.join(map(str, list(shape_zyx)[::-1]))}; colour a chronovolume of the "
            "events' own series at level 0"
        )


def check(
    chronovolume: Chronovolume, graph: object, by: object = "id", series: object = None
) -> EventGraph:
    """Every reason `track_colour` would refuse, checked without reading a step."""
    check_by(by)
    check_mode(chronovolume.metadata.get("spec", {}).get("mode"))
    if chronovolume.t_index is None:
        raise InvalidParameterError(
            "this chronovolume has no t_index (the winning step per voxel); integrate it again "
            f"in one of {', '.join(winner_modes())}"
        )
    graph = check_graph(graph)
    check_records(graph)
    check_steps(graph, chronovolume.steps, chronovolume.shape)
    check_series(chronovolume, graph, series)
    return graph


# no series given, and no store named to read the steps again from
NO_SERIES = (
    "colouring by track reads the winning steps again, and neither the chronovolume nor the "
    "events name a store to read them from (data given as an array, an xarray or a URL do "
    "not): give series= (the TimeSeries they came from, e.g. chronocl.open(...) or "
    "TimeSeries.from_array(...))"
)


def named_store(chronovolume: Chronovolume, graph: EventGraph) -> str | None:
    """The local store the chronovolume or the events came from (None: neither names one)."""
    for where in (chronovolume.metadata.get("store"), graph.meta.get("store")):
        if where:
            return str(where)
    return None


def check_series(chronovolume: Chronovolume, graph: EventGraph, series: object) -> None:
    """One line where the steps cannot be read again: no `series` given and no store named
    (`NO_SERIES`), a series of another kind than a TimeSeries, a store's path or an array
    (T, Z, Y, X), or one whose volume or steps are not the chronovolume's. Nothing is read
    (a store's path is opened when the steps are)."""
    if series is None:
        if named_store(chronovolume, graph) is None:
            raise InvalidParameterError(NO_SERIES)
        return
    if isinstance(series, str | os.PathLike):
        return
    if isinstance(series, TimeSeries):
        shape, n_steps = tuple(series.volume_shape), series.n_steps
    elif isinstance(series, np.ndarray) or hasattr(series, "__array__"):
        shape4 = tuple(np.shape(series))
        if len(shape4) != 4:
            raise InvalidParameterError(
                f"series= as an array must be (T, Z, Y, X); got shape {shape4}"
            )
        shape, n_steps = shape4[1:], shape4[0]
    else:
        raise InvalidParameterError(
            f"series= is the series the steps are read again from: a TimeSeries, a store's "
            f"path or an array (T, Z, Y, X), not {type(series).__name__}"
        )
    if list(shape) != list(chronovolume.shape):
        raise InvalidParameterError(
            f"series= has {'x'.join(map(str, shape[::-1]))} volumes, the chronovolume is "
            f"{'x'.join(map(str, list(chronovolume.shape)[::-1]))}: give the series it came "
            "from (at level 0)"
        )
    beyond = [s for s in chronovolume.steps if s >= n_steps]
    if beyond:
        raise InvalidParameterError(
            f"series= has {n_steps} steps, the chronovolume shows step {beyond[-1]}: give the "
            "series it came from"
        )


def check_records(graph: EventGraph) -> None:
    """One line, before any step is read, where what colouring by track reads of the events is
    missing or not a number (a file edited or cut short): what a step showed, the connectivity,
    the periodic axes, and each feature's step, id, size and track."""
    try:
        mask_of(graph)
        check_connectivity(int(graph.meta.get("connectivity", 26)))
        parse_periodic(graph.meta.get("periodic") or False)
        {int(s) for s in graph.meta.get("steps") or ()}  # (what `check_steps` reads)
        for f in graph.features:
            int(f["step"]), int(f["id"]), int(f["size"]), int(f["track"])
    except InvalidDataError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidDataError(
            f"the events cannot colour by track: a record is missing or wrong "
            f"({type(exc).__name__}: {exc}); write them again with chronocl events"
        ) from None


def mask_of(graph: EventGraph) -> Mask:
    """What a step showed when the events were found (`meta["mask"]`)."""
    d = graph.meta.get("mask") or {}
    d = d if isinstance(d, dict) else {}
    if d.get("kind") == "threshold":
        return Mask.of_threshold(d.get("threshold"))
    if d.get("kind") == "opacity":
        lo, hi = d["value_range"]
        return Mask.of_tf(DataTF.from_dict(d["data_tf"]), (lo, hi), d.get("opacity"))
    raise InvalidDataError(
        "the events file does not say what a step showed (its meta.mask); write it again with "
        "chronocl events"
    )


def _series(chronovolume: Chronovolume, graph: EventGraph, series: object) -> TimeSeries:
    from chronocl.events.run import as_series

    if series is not None:
        return as_series(series)
    where = named_store(chronovolume, graph)
    if where is None:
        raise InvalidParameterError(NO_SERIES)
    return as_series(where)


def track_volumes(
    t_indices: Sequence[np.ndarray], graph: EventGraph, series: object
) -> list[np.ndarray]:
    """Per t_index (Z, Y, X), the track id of every voxel (int32, -1: none): the track of the
    feature holding the voxel at its winning step (the module's docstring). The winning steps of
    all of them are read and labelled once each, one at a time."""
    if not isinstance(series, TimeSeries):
        from chronocl.events.run import as_series

        series = as_series(series)
    mask = mask_of(graph)
    connectivity = int(graph.meta.get("connectivity", 26))
    periodic = parse_periodic(graph.meta.get("periodic") or False)
    track_of = {(f["step"], f["id"]): int(f["track"]) for f in graph.features}
    size_of = {(f["step"], f["id"]): int(f["size"]) for f in graph.features}
    out = [np.full(t.shape, -1, np.int32) for t in t_indices]
    won = np.unique(np.concatenate([np.unique(t) for t in t_indices]))

    def labelled(step: int) -> StepFeatures:
        values = series.read_brick([step], per_call=1)[:, 0]
        return label_step(values, mask, step, connectivity, periodic)

    for found in _ahead(labelled, [int(s) for s in won if s >= 0]):
        step = found.step
        sizes = {(step, f.id): f.size for f in found.features}
        expected = {k: v for k, v in size_of.items() if k[0] == step}
        if sizes != expected:
            raise InvalidDataError(
                f"step {step} holds {len(sizes)} features here, the events file "
                f"{len(expected)} (or other sizes): the events were found in other data; "
                "find them again in this series"
            )
        lut = np.full(len(found.features) + 1, -1, np.int32)
        for f in found.features:
            lut[f.id] = track_of[step, f.id]
        for t, tracks in zip(t_indices, out, strict=True):
            here = t == step
            tracks[here] = lut[found.labels[here]]
    return out


def _ahead(work, steps: list[int]) -> Iterator[StepFeatures]:
    """`work(step)` of each step in order, a few steps read and labelled at once on threads of
    their own (as `chronocl.events.run.find` labels them: at most `AHEAD` in flight)."""
    from chronocl.core.host_threads import workers
    from chronocl.events.run import AHEAD

    queue: deque[Future] = deque()
    todo = iter(steps)
    with ThreadPoolExecutor(
        max(1, min(workers(), AHEAD)), thread_name_prefix="chronocl-tracks"
    ) as pool:
        try:
            for step in itertools.islice(todo, AHEAD):
                queue.append(pool.submit(work, step))
            while queue:
                found = queue.popleft().result()
                step = next(todo, None)
                if step is not None:
                    queue.append(pool.submit(work, step))
                yield found
        finally:
            for pending in queue:
                pending.cancel()


def track_colours(graph: EventGraph, chronovolume: Chronovolume, by: str) -> np.ndarray:
    """(n_tracks, 3) float32: each track's colour in [0, 1], by id or by time (the module's
    docstring; a track without a feature at the chronovolume's steps: its id's colour)."""
    n = max((int(t["id"]) for t in graph.tracks), default=-1) + 1
    colours = np.array([track_rgb(k) for k in range(n)], np.float32).reshape(n, 3)
    if check_by(by) == "time":
        spec = chronovolume.spec
        steps = chronovolume.steps
        p = spec.time_tf.positions_of(steps, chronovolume.metadata["selection"]["n_steps"])
        position = dict(zip(steps, p.tolist(), strict=True))
        for t in graph.tracks:
            shown = [s for s, _ in t["features"] if s in position]
            if shown:
                rgb, _ = spec.time_tf.evaluate(np.array([position[min(shown)]]))
                colours[int(t["id"])] = np.clip(rgb[0], 0.0, 1.0)
    return colours


def coloured(
    chronovolume: Chronovolume,
    tracks: np.ndarray,
    graph: EventGraph,
    by: str = "id",
) -> Chronovolume:
    """`chronovolume` with its colour replaced by the colour of each voxel's track `tracks`
    (-1: transparent), its opacity kept; the metadata says so and lists the tracks shown."""
    colours = track_colours(graph, chronovolume, by)
    alpha = chronovolume.float_rgba()[..., 3]
    shown = tracks >= 0
    rgba = np.zeros((*tracks.shape, 4), np.float32)
    a = alpha[shown]
    rgba[shown, :3] = a[:, None] * colours[tracks[shown]]
    rgba[shown, 3] = a
    ids, counts = np.unique(tracks[shown & (alpha > 0)], return_counts=True)
    first = {int(t["id"]): int(t["start"]) for t in graph.tracks}
    steps = set(chronovolume.steps)
    for t in graph.tracks:
        inside = [s for s, _ in t["features"] if s in steps]
        if inside:
            first[int(t["id"])] = min(inside)
    total = float(alpha.sum(dtype=np.float64))
    lost = total - float(a.sum(dtype=np.float64))
    meta = dict(chronovolume.metadata)
    meta[META_KEY] = {
        "by": by,
        "events_method": graph.method,
        # of the mode's opacity, the share in no feature at its winning step (now transparent)
        "untracked_opacity": lost / total if total > 0 else 0.0,
        "tracks": [
            {
                "id": int(k),
                "rgb": [float(c) for c in colours[k]],
                "first_step": first.get(int(k)),
                "voxels": int(c),
            }
            for k, c in zip(ids.tolist(), counts.tolist(), strict=True)
        ],
    }
    return replace(chronovolume, rgba=rgba, metadata=meta)


def track_colour(
    chronovolume: Chronovolume, events: EventGraph, series: object = None, *, by: str = "id"
) -> Chronovolume:
    """`chronovolume` (first_hit, max, min or change) coloured by the track that reached each
    voxel (the module's docstring): `events` is the window's EventGraph; `series` the series
    its steps are read again from (default: the store the chronovolume or the events name);
    `by` is "id" (a qualitative colour per track) or "time" (the time TF's colour where the
    track first shows). Everything is checked before a step is read."""
    return TrackColour(events, series, by).apply([chronovolume])[0]


def is_track_coloured(chronovolume: Chronovolume) -> bool:
    return META_KEY in chronovolume.metadata


@dataclass(frozen=True)
class TrackColour:
    """A track colouring to apply to chronovolumes of one series: `apply` recolours several at
    once, labelling each winning step once for all of them."""

    events: EventGraph
    series: object = None
    by: str = "id"

    def __post_init__(self) -> None:
        check_graph(self.events)
        check_by(self.by)

    def check(self, chronovolume: Chronovolume) -> None:
        check(chronovolume, self.events, self.by, self.series)

    def apply(self, chronovolumes: Sequence[Chronovolume]) -> list[Chronovolume]:
        todo = [cv for cv in chronovolumes if not is_track_coloured(cv)]
        for cv in todo:
            self.check(cv)
        if not todo:
            return list(chronovolumes)
        series = _series(todo[0], self.events, self.series)
        volumes = track_volumes([cv.t_index for cv in todo], self.events, series)
        done = {
            id(cv): coloured(cv, v, self.events, self.by)
            for cv, v in zip(todo, volumes, strict=True)
        }
        return [done.get(id(cv), cv) for cv in chronovolumes]
