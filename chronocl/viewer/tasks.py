"""The requests a client's render worker answers beside its frames: probe and saves (image,
chronovolume, session, movie) between frames, on the worker's thread (they use its views);
histogram and fit on the client's side thread (`chronocl.viewer.side_work`), events' finds
(`chronocl.viewer.events_panel`) on a thread of their own (a long find never holds a histogram
back), so that they never delay a frame. `Tasks` is a part of
`ClientWorker` (chronocl.viewer.worker), kept here so that each file holds one concern; it uses
the worker's views, shown state and reply channel.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Hashable

from chronocl.core.budget import interactive_memory, parse_memory
from chronocl.core.errors import InvalidParameterError
from chronocl.core.selection import Selection
from chronocl.engine import get_engine
from chronocl.render.views import parse_color
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.errors import error_text
from chronocl.viewer.events_panel import EventTasks
from chronocl.viewer.fit import fit_reply
from chronocl.viewer.gl_thread import on_gl
from chronocl.viewer.movie import movie_states, render_movie
from chronocl.viewer.probe import probe_reply
from chronocl.viewer.protocol import MOVIE_FORMATS
from chronocl.viewer.saving import full_precision, picture, save_chronovolume, save_image
from chronocl.viewer.slicing import slice_reply
from chronocl.viewer.snapshot import save_snapshot
from chronocl.viewer.view_state import ViewState


class Tasks(EventTasks):
    """Histogram, fit, probe and save requests (the methods `ClientWorker` answers them with);
    events (`EventTasks`, chronocl.viewer.events_panel)."""

    # what the page's last histogram request counted (`Dataset.histogram`'s `of` and
    # `value_range`, and the view whose window: its own or the shared one), counted again
    # after a frame of another window
    _hist_of: tuple[str, list | None, int] = ("value", None, 0)

    def _reply(self, obj: dict) -> bool:
        return self.send(json.dumps(obj))

    def _note(self, obj: dict) -> bool:
        """Send without waiting for the client to take it (a refine's progress)."""
        return self.send(json.dumps(obj), False)

    # -- on the side thread (the worker's `side`) -------------------------------------------
    def _beside(self, key: Hashable, rid: int | None, what: str, job: Callable[[], None]) -> None:
        """Run `job` on the side thread, in place of a waiting job of `key`; its error goes
        to the client as the answer to `rid`."""

        def run() -> None:
            try:
                job()
            except Exception as exc:
                self._reply({"type": "error", "id": rid, "message": error_text(exc, f"on {what}")})

        if not self.side.submit(key, run) and not self._closed:
            raise InvalidParameterError("too many requests are waiting; wait for their replies")

    def _beside_frames(self, kind: str, msg: dict) -> bool:
        """Send a histogram or fit request to the side thread, an events message to
        `EventTasks` (a find: its own thread; one that only shows or hides markers: a frame);
        False for other kinds."""
        if kind == "histogram":
            self._hist_of = (msg.get("of", "value"), msg.get("value_range"), msg.get("view", 0))
            self._request_histogram(msg.get("id"), list(msg["range"]))
        elif kind == "fit":
            self._request_fit(msg)
        elif kind == "events":
            self._events_message(msg)
        return kind in ("histogram", "fit", "events")

    def _histogram_after(self, state: ViewState) -> None:
        """After a full-quality frame of another window than the histogram's: its histogram
        (unless one waits: it counts the window wanted when it runs)."""
        window = (state.dataset, *self._hist_view_window(state))
        if state.quality == "full" and window != self._hist_window:
            self._hist_window = window
            if not self.side.waiting("histogram"):
                self._request_histogram(None, self._hist_range)

    def _request_histogram(self, rid: int | None, value_range: list[float]) -> None:
        """Count the histogram over `value_range` of the window wanted when it runs; a newer
        request replaces one still waiting (its `id` then gets no answer of its own)."""
        self._hist_range = list(value_range)
        lo, hi = value_range
        of = self._hist_of
        self._beside("histogram", rid, "histogram", lambda: self._histogram(rid, lo, hi, *of))

    def _hist_view_window(self, state: ViewState, view: int | None = None) -> tuple[int, int, int]:
        """The window a histogram counts: its view's own (default: the last request's view),
        else the shared one."""
        view = self._hist_of[2] if view is None else view
        return state.own_window(view if view < len(state.views) else None) or state.window

    def _histogram(
        self, rid: int | None, lo: float, hi: float, of: str, value_range: list | None, view: int
    ) -> None:
        with self._cond:
            state = self.state
        ds = self.datasets[state.dataset]
        t0, t1, stride = self._hist_view_window(state, view)
        steps = Selection.window(t0, t1, stride, ds.series.n_steps).steps
        hist = ds.histogram(
            lo,
            hi,
            steps,
            stride,
            given_up=lambda: self.side.waiting("histogram"),
            of=of,
            value_range=value_range,
        )
        if hist is None:
            return  # a newer request waits: it answers instead
        self._hist_window = (state.dataset, t0, t1, stride)
        window = [t0, t1, stride]
        self._reply(
            {
                "type": "histogram",
                "id": rid,
                **hist,
                "value_range": value_range,  # a change histogram's (None: the series')
                "view": view,  # whose window: its own, else the shared one
                "window": window,
                "dataset": state.dataset,
            }
        )

    def _request_fit(self, msg: dict) -> None:
        def fit() -> None:
            with self._cond:
                state = self.state
            self._reply(fit_reply(msg, state, self.datasets[state.dataset].series))

        self._beside(("fit", id(msg)), msg.get("id"), "fit", fit)

    # -- on the render thread, between frames ---------------------------------------------

    def _do_task(self, kind: str, msg: dict) -> None:
        rid = msg.get("id")
        ds = self.datasets[self.state.dataset]
        if kind == "save" and msg["what"] == "session":
            key, name = save_snapshot(self.downloads, self.state, ds, self.shown_focus())
            self._reply(
                {"type": "download", "id": rid, "url": f"/download/{key}", "filename": name}
            )
        elif kind == "probe":
            self._probe(msg)
        elif kind == "slice":
            state, view = self._shown_view(msg)
            self.views.full_resolution(range(view, view + 1))
            cv = self.views.slots[view].cv
            self._reply(slice_reply(msg, view, state, cv, self.datasets[state.dataset]))
        elif kind == "save":
            self._save(msg)

    def _shown_view(self, msg: dict) -> tuple[ViewState, int]:
        state = self._shown
        view = msg.get("view", 0)
        if state is None or view >= len(state.views) or view >= len(self.views.slots):
            raise InvalidParameterError(f"view {view} is not shown; choose a view on the page")
        return state, view

    def _probe(self, msg: dict) -> None:
        state, view = self._shown_view(msg)
        self.views.full_resolution(range(view, view + 1))
        cv = self.views.slots[view].cv
        assert cv is not None
        reply = probe_reply(msg, view, state, cv, self.datasets[state.dataset])
        track = self._probed_track(reply, state.dataset)  # a feature of the events found
        if track is not None:
            reply["track"] = track
        where = reply.pop("where", None)
        self._probed = None if where is None else (view, where)
        self._reply(reply)

    def _save(self, msg: dict) -> None:
        state, view = self._shown_view(msg)
        self.views.full_resolution(range(len(state.views)))
        ds = self.datasets[state.dataset]
        sel = state.selection(ds.series.n_steps).describe().replace(":", "-")
        if msg["what"] == "movie":
            self._movie(msg, state, ds, sel)
            return
        if msg["what"] == "image":
            cvs = [s.cv for s in self.views.slots[: len(state.views)]]
            bg = parse_color(state.background)
            panels, *_ = on_gl(self._draw, cvs, state, state.size, bg)
            panels = self._axes_drawn(panels, state, cvs)  # with the box on, as the page
            name = f"{ds.name}-{sel}.png"
            key, layout = save_image(
                self.downloads,
                panels,
                cvs,  # type: ignore[arg-type]
                bg,
                name,
                _columns(msg, len(cvs)),
                ds.name,
            )
            extra = {"layout": dataclasses.asdict(layout)}
        else:
            cv = self.views.slots[view].cv
            assert cv is not None
            mode = state.views[view][0]
            name = f"{ds.name}-{mode}-{sel}.zarr.zip"
            eng = self.views.engine
            eng = get_engine(eng, self.views.device) if isinstance(eng, str) else eng
            budget = interactive_memory() if self.views.memory is None else self.views.memory
            cv = full_precision(cv, ds.series, eng, parse_memory(budget))
            key = save_chronovolume(self.downloads, cv, name)
            extra = {}
        self._reply(
            {
                "type": "download",
                "id": msg.get("id"),
                "url": f"/download/{key}",
                "filename": name,
                **extra,
            }
        )

    def _movie(self, msg: dict, state: ViewState, ds: Dataset, sel: str) -> None:
        """An orbit or a play-through of the shown views as a video download, with a
        `progress` message after every frame; the views are then as shown again."""
        kind, fmt, rid = msg.get("movie", "orbit"), msg.get("format", "mp4"), msg.get("id")
        states = movie_states(state, kind, msg.get("frames", 36), ds.series.n_steps)
        bg = parse_color(state.background)

        def frame(shown: ViewState):
            self.views.chronovolumes(shown)
            self.views.full_resolution(range(len(shown.views)))
            cvs = [s.cv for s in self.views.slots[: len(shown.views)]]
            panels, *_ = on_gl(self._draw, cvs, shown, shown.size, bg)
            panels = self._axes_drawn(panels, shown, cvs)
            columns = _columns(msg, len(cvs))
            return picture(panels, cvs, bg, columns, ds.name)[0].array  # type: ignore[arg-type]

        def progress(done: int, total: int) -> None:
            self._reply(
                {"type": "progress", "id": rid, "what": "movie", "done": done, "total": total}
            )

        try:
            path = render_movie(
                states, frame, fmt, msg.get("fps", 12), self.downloads.dir, progress
            )
        finally:
            self.views.chronovolumes(state)
            self.views.full_resolution(range(len(state.views)))
        name = f"{ds.name}-{'orbit-' + sel if kind == 'orbit' else 'play-through'}.{fmt}"
        key = self.downloads.add(path, name, MOVIE_FORMATS[fmt])
        self._reply({"type": "download", "id": rid, "url": f"/download/{key}", "filename": name})


def _columns(msg: dict, n: int) -> int | None:
    """The panels per row a save asks for (the page's layout), at most the number of views."""
    columns = msg.get("columns")
    return None if columns is None else min(int(columns), max(1, n))
