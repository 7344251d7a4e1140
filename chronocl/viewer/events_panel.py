"""The viewer's events panel: the features of a view's window, matched through time into events
and tracks (`chronocl.events`), found beside the frames and drawn in them.

`EventTasks` is a part of `ClientWorker` (through `tasks.Tasks`), as the other requests are; it
answers the `events` message:

- `find` runs on a thread of its own (one find at a time), never on the frame thread nor on the
  side thread (`side_work`: a long find would hold histograms and fits back): the steps of
  the view's window at full resolution (labelled where the view's window manager holds them,
  read from the store where it does not; on threads, never on worker processes), a step
  showing where the data TF's opacity exceeds `opacity` (as `chronocl.events(..., tf=...)`)
  or the values reach `value`. After a second it
  sends `progress` messages ({"what": "events", "done", "total"}); it is given up (at the next
  step, `chronocl.core.interrupt`, and once more before its result is kept) once the window or
  the data set changes, or a newer find comes, and then answers {"type": "events", "cancelled":
  why}. A step of more than MAX_FEATURES_PER_STEP features is refused as it is labelled (an
  error reply in one line). Its answer is `events_reply`:
  the events other than continuations with where they happened (a voxel centroid and the world
  box a camera frames to look at it: the update message's `focus`) and the tracks with their
  size, mean value and centroid at each step. Without the ``events`` extra the answer is
  {"type": "events", "missing": "pip install 'chronocl[events]'"}; nothing else changes.
- `markers` shows or hides the found events in every panel (`render.markers`: labelled rings at
  their centroids, those within the panel's window), in the frames, saved PNGs and movies alike:
  `marked` is called on the panels as drawn (at most MAX_EVENTS markers a panel, kept per
  panel's steps: a frame draws them without working them out again). `track` highlights a
  track there as well: a line through its centroids at the panel's steps
  (`render.markers.draw_path`), shown with them; it names the find (`find`: its id) whose list
  it was chosen in, and is ignored when another find's events are kept now.
  The frame these redraw answers the newest framed request (the one waiting, else the one last
  shown): a frame's id is always an update's, which a notebook widget waits for.
- `clear` forgets the events found.

A probe (a click on a view) that meets a voxel of a feature of the events found also answers
with that feature's track (`picked_feature`), which the page plots and highlights.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from chronocl.core.errors import InvalidParameterError, SupersededError
from chronocl.core.interrupt import interruptible
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import world_extent
from chronocl.render.markers import draw_markers, draw_path
from chronocl.viewer.errors import error_text

PROGRESS_AFTER_S = 1.0  # a find that takes longer says how far it got
MAX_EVENTS = 400  # events listed (besides continuations); more: the first ones, and the count
# Features a step may hold: past it a find is refused as that step is labelled. Such a step is
# noise under the threshold, not events, and what follows grows with the features: 6 steps of
# 96^3 noise gave 449,756 features, 91 s and ~1 GB to track, and 28.8 s to place the markers
# of a panel's frame.
MAX_FEATURES_PER_STEP = 10_000
MAX_CACHED = 32  # the markers and paths kept per find (a panel's steps each)
MAX_TRACKS = 400  # tracks sent, the longest first
MIN_FOCUS_HALF = 0.1  # the smallest half side of the box a click on an event frames (world)
FOCUS_MARGIN = 1.5  # the box frames the event's features with this much room


class EventTasks:
    """The `events` message (the module's docstring); a part of `ClientWorker`."""

    # (data set, EventGraph, Mask, the find's id, {markers and paths drawn}) of the last find;
    # whether its markers are drawn (under _cond).
    _events_found: tuple | None = None
    _events_markers: bool = False
    _events_track: int | None = None  # the track highlighted
    _events_gen = 0  # finds asked (the newest runs; an older one gives up)
    _events_lock: threading.Lock | None = None  # one find at a time (made with the first)

    def _events_message(self, msg: dict) -> None:
        """Answer an `events` message (called on the server's event loop: nothing here waits)."""
        action, rid = msg["action"], msg.get("id")
        if action == "find":
            self._request_events(msg)
            return
        with self._cond:
            shown = self._events_markers and self._events_found is not None
            if action == "markers":
                self._events_markers = msg["show"]
            elif action == "track":
                found = self._events_found
                if found is not None and msg.get("find", found[3]) != found[3]:
                    return  # chosen in an older find's list: not a track of these events
                self._events_track = msg["track"]
            else:
                self._events_found, self._events_track = None, None
            redraw = shown != (self._events_markers and self._events_found is not None)
        if action == "clear":  # (on the server's event loop: a reply not waited for)
            self._note({"type": "events", "id": rid, "cleared": True})
        if redraw or action != "clear":  # the same state drawn again, with or without them
            self._redraw()

    def _redraw(self) -> None:
        """The state drawn again (its markers changed), the frame answering the newest framed
        request: the one waiting, else the one last shown. Never the events message's own id
        (a notebook widget waits for frames of its updates' ids only), never an older
        request's than the one waiting."""
        with self._cond:  # (re-entrant: update takes it too)
            rid = self._last_rid if self._pending is None else self._pending[1]
            self.update({"id": rid})

    def _request_events(self, msg: dict) -> None:
        rid, view = msg.get("id"), msg.get("view", 0)
        with self._cond:
            state = self.state
        if view >= len(state.views):
            raise InvalidParameterError(f"view {view} is not shown; choose a view on the page")
        from chronocl.events import extra

        try:
            extra.cc3d()
            extra.networkx()
        except extra.MissingExtraError as exc:
            missing = {"missing": extra.INSTALL, "message": str(exc)}
            self._note({"type": "events", "id": rid, **missing})  # (not waited for: the loop's)
            return
        with self._cond:
            self._events_gen += 1
            gen = self._events_gen
            if self._events_lock is None:
                self._events_lock = threading.Lock()
        threading.Thread(
            target=self._find_thread,
            args=(gen, rid, view, msg),
            name="chronocl-events",
            daemon=True,
        ).start()

    def _find_thread(self, gen: int, rid: int | None, view: int, msg: dict) -> None:
        """A find on its own thread, once the older one running has given up."""
        assert self._events_lock is not None
        try:
            with self._events_lock:
                if self._events_gen != gen or self._closed:
                    why = "a newer find replaced it; find again"
                    self._reply({"type": "events", "id": rid, "cancelled": why})
                    return
                self._find_events(gen, rid, view, msg)
        except Exception as exc:
            if self._closed:  # (the client gone: no one to tell)
                return
            message = error_text(exc, "on finding events")
            self._reply({"type": "error", "id": rid, "message": message})

    def _find_events(self, gen: int, rid: int | None, view: int, msg: dict) -> None:
        from chronocl.events.run import find, prepare

        with self._cond:
            state = self.state
        ds = self.datasets[state.dataset]
        window = state.own_window(view) or state.window
        selection = state.selection(ds.series.n_steps, view)
        why: list[str] = []

        def given_up() -> bool:
            with self._cond:
                now = self.state
            if now.dataset != state.dataset:
                why.append("the data set changed")
            elif (now.own_window(view) or now.window) != window:
                why.append("the window changed")
            elif self._events_gen != gen:
                why.append("a newer find replaced it")
            elif self._closed:
                why.append("the viewer closed")
            return bool(why)

        started = time.monotonic()

        def progress(stage: str, done: int, total: int) -> None:
            if time.monotonic() - started >= PROGRESS_AFTER_S:
                note = {"what": "events", "stage": stage, "done": done, "total": total}
                self._note({"type": "progress", "id": rid, **note})

        if "show" in msg:  # the markers of what it finds, drawn (or not) once found
            with self._cond:
                self._events_markers = msg["show"]
        if msg.get("by", "opacity") == "value":
            mask: dict = {"threshold": msg["value"]}
        else:
            # the view's data TF: its own where it has one
            mask = {"tf": state.data_tf_of(view), "opacity": msg.get("opacity", 0.1)}
        try:
            with interruptible(given_up, progress):
                job = prepare(
                    ds.series, selection, connectivity=msg.get("connectivity", 26), **mask
                )
                held = self._resident_steps(view, ds.series, job.selection.steps)
                # on threads of this process: the viewer's --memory (`ProcessLimit`) is a
                # promise about this process, whose /proc/self/statm no worker's memory shows
                graph = find(
                    job, max_features=MAX_FEATURES_PER_STEP, resident=held, processes=False
                )
        except SupersededError:
            why.append("it was given up")
        finally:
            held = {}  # the window manager may evict them again
        with self._cond:  # (tracking has no checkpoint: the window may have moved meanwhile)
            if not why and not given_up():
                self._events_found = (state.dataset, graph, job.mask, rid, {})
                self._events_track = None
            redraw = self._events_markers and not why
        if why:
            self._reply({"type": "events", "id": rid, "cancelled": f"{why[0]}; find again"})
            return
        if redraw:  # before the reply: what the page asks on hearing of it is newer
            self._redraw()
        reply = events_reply(graph, ds.series.volume_shape, ds.series.spacing)
        self._reply(
            {
                "type": "events",
                "id": rid,
                "dataset": state.dataset,
                "view": view,
                "window": list(window),
                "mask": job.mask.describe(),
                "seconds": round(time.monotonic() - started, 2),
                **reply,
            }
        )

    def _resident_steps(self, view: int, series, steps) -> dict[int, np.ndarray]:
        """The steps of `steps` the view's full-resolution window manager holds now (the
        window shown), held there while the find labels them (`WindowManager.hold`): read
        again only where they are not resident."""
        managers = self.views.shown_managers  # (published whole by the render thread)
        manager = managers[view] if view < len(managers) else None
        if manager is None or manager.series is not series:
            return {}
        return manager.hold(steps)

    def _probed_track(self, reply: dict, dataset: int) -> dict | None:
        """The track of the feature a probe's voxel lies in (`picked_feature`), where events of
        the data set were found and the probe met a voxel; else None."""
        with self._cond:
            found = self._events_found
        if found is None or found[0] != dataset or not reply.get("voxel") or not reply["values"]:
            return None
        v = reply["voxel"]
        picked = picked_feature(found[1], found[2], (v["x"], v["y"], v["z"]), reply["values"])
        return None if picked is None else {**picked, "find": found[3]}

    def _marked(self, panels: list, cvs: list[Chronovolume], state) -> list:
        """`panels` as drawn, with the found events' markers where they are shown (each panel
        those within its own window's steps)."""
        with self._cond:
            found, show, track = self._events_found, self._events_markers, self._events_track
        if not show or found is None or found[0] != state.dataset:
            return panels
        graph, cache = found[1], found[4]
        out = []
        for i, (panel, cv) in enumerate(zip(panels, cvs, strict=False)):
            camera = state.panel_camera(i)  # its own camera where it has one
            if cv is None:
                out.append(panel)
                continue
            steps = tuple(int(s) for s in cv.steps)
            if track is not None:
                path = _cached(cache, ("path", track, steps), track_path, graph, track, steps)
                if path:
                    panel = draw_path(panel, camera, cv, path, f"track {track}")
            markers = _cached(cache, ("markers", steps), graph.markers, steps, MAX_EVENTS)
            out.append(draw_markers(panel, camera, cv, markers) if markers else panel)
        return out + panels[len(out) :]


def _cached(cache: dict, key: tuple, make, *args):
    """`cache[key]`, made once (the cache of a find's markers and paths, at most MAX_CACHED;
    dict operations are atomic: the frame thread and the saves' draw alike)."""
    got = cache.get(key)
    if got is None:
        if len(cache) >= MAX_CACHED:
            cache.clear()
        got = cache[key] = make(*args)
    return got


def picked_feature(graph, mask, voxel_xyz, values) -> dict | None:
    """The feature the voxel `voxel_xyz` (full resolution) lies in, at the last step of
    `graph`'s window where it lies in one: a step whose value there (`values`, one per step of
    the series) the `mask` shows, and whose features' boxes only one holds the voxel.
    {"track", "step", "id"}, or None (the voxel in no feature, or in several boxes)."""
    x, y, z = voxel_xyz
    steps = [s for s in graph.meta.get("steps", []) if 0 <= s < len(values)]
    shown = mask(np.asarray([values[s] for s in steps], dtype=np.float32))
    by_step: dict[int, list[dict]] = {}
    for f in graph.features:
        by_step.setdefault(f["step"], []).append(f)
    for step, on in zip(reversed(steps), reversed(shown.tolist()), strict=True):
        if not on:
            continue
        holding = [f for f in by_step.get(step, []) if _holds(f["bbox_zyx"], (z, y, x))]
        if len(holding) == 1:
            f = holding[0]
            return {"track": f["track"], "step": step, "id": f["id"]}
    return None


def _holds(box, zyx) -> bool:
    return all(lo <= v < hi for (lo, hi), v in zip(box, zyx, strict=True))


def track_path(graph, track: int, steps) -> list[tuple[float, float, float]]:
    """The centroids of `track`'s features at `steps` (its merged ones size-weighted), as
    (x, y, z) fractions of the box, in step order."""
    shape = graph.meta.get("volume_shape_zyx")
    if not shape:
        return []
    wanted = set(int(s) for s in steps)
    at: dict[int, list[dict]] = {}
    for f in graph.features:
        if f["track"] == track and f["step"] in wanted:
            at.setdefault(f["step"], []).append(f)
    out = []
    for step in sorted(at):
        sizes = np.array([f["size"] for f in at[step]], dtype=np.float64)
        zyx = np.array([f["centroid_zyx"] for f in at[step]], dtype=np.float64)
        centre = (sizes[:, None] * zyx).sum(axis=0) / sizes.sum()
        fractions = (centre[::-1] + 0.5) / np.asarray(shape[::-1], dtype=np.float64)
        out.append(tuple(float(v) for v in fractions))
    return out


def events_reply(graph, shape_zyx, spacing_xyz) -> dict:
    """What the panel lists of `graph` (an EventGraph of a series of `shape_zyx` voxels of
    `spacing_xyz`): its summary, the events other than continuations (at most MAX_EVENTS, in
    step order) with their size, voxel centroid and a world `focus` box around them, and the
    tracks (at most MAX_TRACKS, the longest first) with their steps, sizes, mean values and
    centroids."""
    shape = np.asarray(shape_zyx[::-1], dtype=np.float64)  # x, y, z
    extent = world_extent(tuple(shape_zyx), tuple(spacing_xyz))
    at = {(f["step"], f["id"]): f for f in graph.features}
    events = []
    places = graph.places()
    for e, fractions in places[:MAX_EVENTS]:
        step, ids = (e["next_step"], e["targets"]) if e["targets"] else (e["step"], e["sources"])
        feats = [at[step, i] for i in ids if (step, i) in at]
        centre = (np.asarray(fractions) - 0.5) * extent
        events.append(
            {
                "kind": e["kind"],
                "step": e["step"],
                "next_step": e["next_step"],
                "at": step,  # the step whose features place it
                "sources": e["sources"],
                "targets": e["targets"],
                "at_boundary": e["at_boundary"],
                "size": int(sum(f["size"] for f in feats)),
                "centroid": [round(float(v), 2) for v in np.asarray(fractions) * shape - 0.5],
                "tracks": sorted({f["track"] for f in feats}),
                "focus": focus_box(centre, _half_side(feats, shape, extent)),
            }
        )
    by_track: dict[int, list[dict]] = {}
    for f in graph.features:
        by_track.setdefault(f["track"], []).append(f)
    tracks = sorted(graph.tracks, key=lambda t: (-t["length"], t["id"]))[:MAX_TRACKS]
    return {
        "describe": graph.describe(),
        "counts": graph.counts(),
        "method": graph.method,
        "events": events,
        "events_total": len(places),
        "tracks": [_track(t, by_track.get(t["id"], [])) for t in tracks],
        "tracks_total": len(graph.tracks),
    }


def _track(track: dict, feats: list[dict]) -> dict:
    feats = sorted(feats, key=lambda f: f["step"])
    return {
        "id": track["id"],
        "start": track["start"],
        "end": track["end"],
        "length": track["length"],
        "steps": [f["step"] for f in feats],
        "size": [int(f["size"]) for f in feats],
        "value": [float(f["value_sum"]) / max(1, f["size"]) for f in feats],  # mean value
        "centroid": [[round(float(v), 2) for v in f["centroid_zyx"][::-1]] for f in feats],
    }


def _half_side(feats: list[dict], shape_xyz: np.ndarray, extent: np.ndarray) -> float:
    """Half the side of a box (world units) that holds the features' boxes with room."""
    if not feats:
        return MIN_FOCUS_HALF
    lo = np.min([[b[0] for b in f["bbox_zyx"]][::-1] for f in feats], axis=0)
    hi = np.max([[b[1] for b in f["bbox_zyx"]][::-1] for f in feats], axis=0)
    side = float(((hi - lo) / shape_xyz * extent).max())
    return max(MIN_FOCUS_HALF, FOCUS_MARGIN * side / 2)


def focus_box(centre: np.ndarray, half: float) -> list[float]:
    """A cube of half side `half` about `centre` (world), as the camera's focus (x0, y0, z0,
    x1, y1, z1), within the protocol's bounds (-1..1)."""
    half = min(half, 0.5)
    lo = np.clip(np.asarray(centre) - half, -1.0, 1.0)
    hi = np.clip(np.asarray(centre) + half, -1.0, 1.0)
    return [round(float(v), 4) for v in (*lo, *hi)]
