"""The viewer's events panel: the features of a view's window, matched through time into events
and tracks (`chronocl.events`), found beside the frames and drawn in them.

`EventTasks` is a part of `ClientWorker` (through `tasks.Tasks`), as the other requests are; it
answers the `events` message:

- `find` runs on the client's side thread (`side_work`), never on the frame thread: the steps of
  the view's window at full resolution, a step showing where the data TF's opacity exceeds
  `opacity` (as `chronocl.events(..., tf=...)`) or the values reach `value`. After a second it
  sends `progress` messages ({"what": "events", "done", "total"}); it is given up (at the next
  step, `chronocl.core.interrupt`) once the window or the data set changes, or a newer find
  waits, and then answers {"type": "events", "cancelled": why}. Its answer is `events_reply`:
  the events other than continuations with where they happened (a voxel centroid and the world
  box a camera frames to look at it: the update message's `focus`) and the tracks with their
  size, mean value and centroid at each step. Without the ``events`` extra the answer is
  {"type": "events", "missing": "pip install 'chronocl[events]'"}; nothing else changes.
- `markers` shows or hides the found events in every panel (`render.markers`: labelled rings at
  their centroids, those within the panel's window), in the frames, saved PNGs and movies alike:
  `marked` is called on the panels as drawn. `track` highlights a track there as well: a line
  through its centroids at the panel's steps (`render.markers.draw_path`), shown with them.
- `clear` forgets the events found.

A probe (a click on a view) that meets a voxel of a feature of the events found also answers
with that feature's track (`picked_feature`), which the page plots and highlights.
"""

from __future__ import annotations

import time

import numpy as np

from chronocl.core.errors import InvalidParameterError, SupersededError
from chronocl.core.interrupt import interruptible
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import world_extent
from chronocl.render.markers import draw_markers, draw_path

PROGRESS_AFTER_S = 1.0  # a find that takes longer says how far it got
MAX_EVENTS = 400  # events listed (besides continuations); more: the first ones, and the count
MAX_TRACKS = 400  # tracks sent, the longest first
MIN_FOCUS_HALF = 0.1  # the smallest half side of the box a click on an event frames (world)
FOCUS_MARGIN = 1.5  # the box frames the event's features with this much room


class EventTasks:
    """The `events` message (the module's docstring); a part of `ClientWorker`."""

    # (data set, EventGraph, Mask) of the last find; whether its markers are drawn (under _cond).
    _events_found: tuple | None = None
    _events_markers: bool = False
    _events_track: int | None = None  # the track highlighted

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
                self._events_track = msg["track"]
            else:
                self._events_found, self._events_track = None, None
            redraw = shown != (self._events_markers and self._events_found is not None)
        if action == "clear":  # (on the server's event loop: a reply not waited for)
            self._note({"type": "events", "id": rid, "cleared": True})
        if redraw or action != "clear":  # the same state drawn again, with or without them
            self._redraw(rid)

    def _redraw(self, rid: int | None) -> None:
        """The state drawn again (its markers changed), the frame answering `rid` or the
        newer request of a frame waiting already (a client's ids grow: a find's redraw, asked
        after the user moved on, never answers in place of the newer input)."""
        with self._cond:  # (re-entrant: update takes it too)
            waiting = None if self._pending is None else self._pending[1]
            if rid is None or (waiting is not None and waiting > rid):
                rid = waiting
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
        self._beside("events", rid, "finding events", lambda: self._find_events(rid, view, msg))

    def _find_events(self, rid: int | None, view: int, msg: dict) -> None:
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
            elif self.side.waiting("events"):
                why.append("a newer find replaced it")
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
            mask = {"tf": state.data_tf, "opacity": msg.get("opacity", 0.1)}
        try:
            with interruptible(given_up, progress):
                job = prepare(
                    ds.series, selection, connectivity=msg.get("connectivity", 26), **mask
                )
                graph = find(job)
        except SupersededError:
            reason = why[0] if why else "it was given up"
            self._reply({"type": "events", "id": rid, "cancelled": f"{reason}; find again"})
            return
        with self._cond:
            self._events_found, self._events_track = (state.dataset, graph, job.mask), None
            redraw = self._events_markers
        if redraw:  # before the reply: what the page asks on hearing of it is newer
            self._redraw(rid)
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

    def _probed_track(self, reply: dict, dataset: int) -> dict | None:
        """The track of the feature a probe's voxel lies in (`picked_feature`), where events of
        the data set were found and the probe met a voxel; else None."""
        with self._cond:
            found = self._events_found
        if found is None or found[0] != dataset or not reply.get("voxel") or not reply["values"]:
            return None
        v = reply["voxel"]
        return picked_feature(found[1], found[2], (v["x"], v["y"], v["z"]), reply["values"])

    def _marked(self, panels: list, cvs: list[Chronovolume], state) -> list:
        """`panels` as drawn, with the found events' markers where they are shown (each panel
        those within its own window's steps)."""
        with self._cond:
            found, show, track = self._events_found, self._events_markers, self._events_track
        if not show or found is None or found[0] != state.dataset:
            return panels
        graph, camera = found[1], state.panel_camera()
        out = []
        for panel, cv in zip(panels, cvs, strict=False):
            if cv is None:
                out.append(panel)
                continue
            if track is not None:
                path = track_path(graph, track, cv.steps)
                if path:
                    panel = draw_path(panel, camera, cv, path, f"track {track}")
            markers = graph.markers(cv.steps)
            out.append(draw_markers(panel, camera, cv, markers) if markers else panel)
        return out + panels[len(out) :]


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
