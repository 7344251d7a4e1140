"""Per-client render worker.

Each WebSocket client owns a `ClientWorker`: the client's desired state (`ViewState`) and one
thread that makes frames from it. Updates are merged into the desired state at once
(validated there, so a bad one is answered with an error and changes nothing) and leave one
"latest pending request" slot filled; the worker always renders the newest state, so input
that arrives while a frame is being made replaces older pending input instead of queueing
behind it. The views' sessions and textures (`view_sessions.Views`) integrate only what
changed, so a camera change only re-renders and a window slide integrates only the new
window (from steps already resident; incrementally where that pays: `Session`).
Probe and save requests (`tasks.Tasks`) wait in a short queue behind the newest frame;
histogram and fit requests run on the client's side thread (`side_work.SideWork`), so they
never delay a frame. The camera frames the visible region found at a data set's first frame
and again at each camera reset (`refocus`), and keeps that framing while the window moves. GL
work runs on the viewer's GL thread (`gl_thread.on_gl`).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from collections.abc import Callable

from chronocl import modes
from chronocl.core import foreground, process_memory
from chronocl.core.errors import InvalidParameterError, SupersededError
from chronocl.core.interrupt import interruptible
from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.integration.interactive.winners import RECOLOURED
from chronocl.render.framing import framed
from chronocl.render.recolour.bricks import warm_kernels
from chronocl.render.views import describe, parse_color
from chronocl.viewer.box_axes import draw_axes, views_axes
from chronocl.viewer.clip_outline import clip_outline
from chronocl.viewer.datasets import Dataset, find_dataset
from chronocl.viewer.errors import error_text, log
from chronocl.viewer.fit import fit_reply, fitted_default
from chronocl.viewer.frames import (
    JPEG_QUALITY,
    DrawBudget,
    colour_bar,
    count_bar,
    empty_note,
    encode,
    legend,
    render_size,
    visible_fraction,
)
from chronocl.viewer.gl_thread import on_gl
from chronocl.viewer.probe import project
from chronocl.viewer.progress import RefineProgress, reporting
from chronocl.viewer.protocol import pack_frame
from chronocl.viewer.saving import Downloads
from chronocl.viewer.side_work import SideWork
from chronocl.viewer.slots import upload
from chronocl.viewer.snapshot import checked_focus, loaded_state
from chronocl.viewer.tasks import Tasks
from chronocl.viewer.view_sessions import SharedSteps, Views
from chronocl.viewer.view_state import ViewState, default_state, describe_state, merge

MAX_TASKS = 8
# Delays (`TUNING.refine_after_s`, `prepare_after_s`, `left_wait_s`): after a drag's coarse
# frame a refine waits (an edit's end refines at once); after a sharp frame of a mode that
# recolours, its winners are gathered once input pauses, so that the first TF edit only
# recolours (new input gives the gather up); a frame waits for a client that left to let go of
# its frames (a page reloaded: the old socket's frames, 2 GB at 512^3 in max, and the new ones
# held at once), at most that long after it left: one still busy (a movie) stalls the others'
# frames once, not each.
_leaving: dict = {}  # workers closed whose views are not released yet: when they left
_left = threading.Condition()


class ClientWorker(Tasks):
    """The render thread of one client. `send(data, wait=True)` delivers a text (str) or binary
    (bytes) message to the client (with `wait` false not waiting for it to be taken) and
    returns False once the client is gone."""

    def __init__(
        self,
        datasets: list[Dataset],
        send: Callable[..., bool],
        downloads: Downloads,
        *,
        engine: str = "opencl",
        device: str | None = None,
        memory: str | int | None = None,
        shared: SharedSteps | None = None,
    ) -> None:
        self.datasets = datasets
        self.send = send
        self.downloads = downloads
        self.engine, self.device, self.memory = engine, device, memory
        self.state = default_state(0, datasets[0].series)
        self._cond = threading.Condition()
        self._pending: tuple[ViewState, int | None] | None = None
        self._tasks: deque[tuple[str, dict]] = deque()
        self.side = SideWork()  # histograms and fits, beside the frames
        self._closed = False
        self.views = Views(datasets, engine, device, memory, shared)
        self._refine_at: float | None = None  # when the coarse frame shown is to be refined
        self._prepare_at: float | None = None  # when the sharp frame's winners are to be gathered
        self._cancelled = False  # the client cancelled the refine of the frame shown
        self._draw_budget = DrawBudget()  # pixels a frame answering input may draw
        self._last_rid: int | None = None
        self._shown: ViewState | None = None  # the state of the last frame sent
        self._probed: tuple[int, tuple[float, float, float]] | None = None  # view, box fractions
        # The histogram's range and (data set, window) last sent: another window queues one.
        self._hist_range, self._hist_window = [0.0, 1.0], None
        self._frame = 0
        self._warmed: set = set()  # the data types whose recolouring kernels are loaded
        self._released = False  # its views let go (the thread's end)
        # A state to integrate before its first frame is asked for (`open`/`update` with
        # `frame` false): its chronovolumes are ready when the client's first request comes.
        self._warm: ViewState | None = None
        # The framed region: (generation, world box or None); a data set or camera reset adds one.
        self._focus_gen = 0
        self._focus: tuple[int, tuple | None] | None = None
        self.thread = threading.Thread(target=self._run, name="chronocl-view", daemon=True)
        self.thread.start()

    # -- called from the server's event loop ----------------------------------------------
    def open(self, ref: int | str, rid: int | None, fit: bool = True, frame: bool = True) -> dict:
        """The data set's default state, its data TF fitted to the first window and view's
        mode (reads a sample of the window: the socket calls it off its event loop). Not
        fitted where `fit` is false: a page opened again after a reconnect sends the state it
        had next, its own fitted range with it. No frame is made where `frame` is false (a
        notebook widget opens before any page shows it: the first request's frame does)."""
        i = find_dataset(self.datasets, ref)
        series = self.datasets[i].series
        state = default_state(i, series)
        if fit:
            state = fitted_default(series, state)
        with self._cond:
            self.state = state
            self._probed = None
            self._focus_gen += 1
            if frame:
                self._pending = (self.state, rid)
            self._cancelled = False
            self._hist_range, self._hist_window = [0.0, 1.0], None  # sent after its frame
            self._cond.notify()
        if not fit:
            return self._opened(i)
        return self._opened(i) | {"fitted": fit_reply({}, state, series)}  # (cached)

    def _opened(self, i: int) -> dict:
        """The `dataset` reply: the data set, the state, and the data set's opening camera."""
        opening = describe_state(default_state(i, self.datasets[i].series))["camera"]
        return self.datasets[i].info(i) | {
            "state": describe_state(self.state),
            "opening_camera": opening,
        }

    def load(self, snapshot: dict, rid: int | None) -> dict:
        """Apply a validated snapshot (a saved state) as one step (nothing applied when it does not
        fit), framing its `focus` (none: the visible region of its first frame); the reply is
        `open`'s."""
        with self._cond:
            i, state = loaded_state(self.datasets, self.state, snapshot)
            focus = checked_focus(state, snapshot.get("focus"))
            self.state = state
            self._set_focus(focus)
            self._probed = None
            self._pending = (self.state, rid)
            self._cancelled = False
            self._hist_range, self._hist_window = [0.0, 1.0], None  # sent after its frame
            self._cond.notify()
        return self._opened(i)

    def _set_focus(self, box: tuple | None) -> None:
        """Frame `box` from now on (None: the visible region of the next frame)."""
        self._focus_gen += 1
        self._focus = None if box is None else (self._focus_gen, box)

    def pin_probe(self, view: int, where: tuple[float, float, float]) -> None:
        """The probe's mark follows box fractions `where` on view `view` in the frames from
        now on (a probe made from code, as the page's own probe sets it)."""
        with self._cond:
            self._probed = (view, where)

    def shown_focus(self) -> list | None:
        """The world box the views frame now (None: not known yet)."""
        with self._cond:
            known = self._focus
            return None if known is None or known[0] != self._focus_gen else known[1]

    def warm(self) -> None:
        """Integrate the state now, without drawing, where no frame was shown or asked for yet
        (a notebook widget's, once `show` set its window and mode: its page's first frame
        then only draws; warmed earlier, the default window was integrated for nothing)."""
        with self._cond:
            if self._shown is None and self._pending is None:
                self._warm = self.state
                self._cond.notify()

    def update(self, msg: dict, frame: bool = True) -> None:
        """Merge a validated update into the state; its frame is made next, or with `frame`
        false not now (a frame already waiting shows it; else the next request's does)."""
        with self._cond:
            n = self.datasets[self.state.dataset].series.n_steps
            state = merge(self.state, msg, n)
            focus = checked_focus(state, msg.get("focus"))
            self.state = state
            if msg.get("refocus"):
                self._focus_gen += 1
            if "focus" in msg:
                self._set_focus(focus)
            if frame:
                self._pending = (self.state, msg.get("id"))
            elif self._pending is not None:
                self._pending = (self.state, self._pending[1])
            self._cancelled = False
            self._cond.notify()

    def task(self, kind: str, msg: dict) -> None:
        if self._beside_frames(kind, msg):
            return
        with self._cond:
            if len(self._tasks) >= MAX_TASKS:
                raise InvalidParameterError(
                    f"{MAX_TASKS} requests are already waiting; wait for their replies"
                )
            self._tasks.append((kind, msg))
            self._cond.notify()

    def cancel_refine(self) -> None:
        """Stop refining the frame shown (until the next input)."""
        with self._cond:
            self._cancelled = True
            self._refine_at = None
            self._cond.notify()

    def _given_up(self) -> bool:
        with self._cond:
            return self._pending is not None or self._cancelled or self._closed

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()
        with _left:
            if not self._released:  # (a thread that ended on its own let go already)
                _leaving.setdefault(self, time.monotonic())
            _left.notify_all()  # its own frame waiting on others is not wanted any more
        self.side.close()

    # -- the thread ----------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # nothing of the thread's end may print a traceback
            error_text(exc, "in a client's render thread")
        finally:
            try:
                self.views.release()
            except Exception as exc:
                error_text(exc, "releasing a client's views")
            with _left:
                self._released = True
                _leaving.pop(self, None)
                _left.notify_all()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while (
                    not self._closed
                    and self._pending is None
                    and not self._tasks
                    and self._warm is None
                ):
                    due = [t for t in (self._refine_at, self._prepare_at) if t is not None]
                    wait = min(due) - time.monotonic() if due else None
                    if wait is not None and wait <= 0:
                        break
                    self._cond.wait(wait)
                if self._closed:
                    return
                pending, self._pending = self._pending, None
                task = None if pending is not None or not self._tasks else self._tasks.popleft()
                warm, self._warm = (self._warm, None) if task is None else (None, self._warm)
                refine = self._refine_at is not None and self._refine_at <= time.monotonic()
            try:
                if pending is not None:
                    with foreground.working():  # memory warms pause meanwhile
                        self._render(*pending)
                elif task is not None:
                    self._do_task(*task)
                elif warm is not None:
                    self._warm_first(warm)
                elif refine:
                    with foreground.working():
                        self._refine()
                else:
                    self._prepare()
            except Exception as exc:  # reported to the client; the worker keeps serving
                rid = pending[1] if pending is not None else task[1].get("id") if task else None
                what = (
                    f"on {task[0]}" if task is not None and pending is None else "making the frame"
                )
                text = error_text(exc, f"{what} ({self._what_is_shown(pending)})")
                if not self._reply({"type": "error", "id": rid, "message": text}):
                    return

    def _warm_first(self, state: ViewState) -> None:
        """The chronovolumes of `state` integrated before any frame is asked for (a notebook
        widget's, while its page loads); a failure is the first frame's to report."""
        if self._shown is not None:
            return
        try:
            with foreground.working():
                self.views.chronovolumes(state)
        except Exception as exc:
            error_text(exc, "integrating ahead of the first frame")

    def _what_is_shown(self, pending) -> str:
        """The views' modes and windows, the data set's size and the frame's, for an error's
        line (never raising: it is called while an error is handled)."""
        try:
            state = pending[0] if pending is not None else self._shown or self.state
            series = self.datasets[state.dataset].series
            views = ", ".join(f"{mode} {order}" for mode, order in state.views)
            t0, t1, stride = state.window
            size = "x".join(map(str, series.volume_shape))
            w, h = state.size
            return (
                f"views {views}, window {t0}:{t1}:{stride}, data {size} {series.dtype}, "
                f"frame {w}x{h} {state.quality}"
            )
        except Exception as exc:
            return f"views unknown: {type(exc).__name__}"

    def _draw(self, rc, cvs, state, size, bg, given_up=None) -> tuple[list, float, float, float]:
        """Upload what changed and draw every view (on the GL thread); `given_up` (a refine's)
        true between upload slabs, before the draw or between its bands: SupersededError."""
        t_up = time.perf_counter()
        recolouring = self.views.recolouring
        for slot, cv in zip(self.views.slots, cvs, strict=False):
            if slot.uploaded is not cv:
                recolouring.settle(slot)  # a recoloured frame never read: read where held
                upload(rc, slot, cv, given_up)
        t_draw = time.perf_counter()
        panels = [
            rc.draw(
                slot.volume,
                state.panel_camera(i),  # its own camera where it has one
                size,
                background=bg,
                clip=state.clip,
                step=1.0,
                outline=state.outline,
                shading=state.shading,
                stop=given_up,
            )
            for i, slot in enumerate(self.views.slots[: len(cvs)])
        ]
        for slot in self.views.slots[len(cvs) :]:
            recolouring.settle(slot)
            slot.release_gl()
        panels = self._marked(panels, cvs, state)  # the events panel's markers, if shown
        return panels, t_up, t_draw, time.perf_counter()

    def _render(self, state: ViewState, rid: int | None) -> None:
        t_start = time.perf_counter()
        self.views.times.start()  # the frame's own (a probe's read-back came before)
        with _left:  # a client that left lets go of its frames before this one makes more
            while not self._closed and (wait := self._left_wait()) > 0:
                _left.wait(wait)
        if self._closed:
            return  # nobody will see it
        # the page's busy box hears how far it got: reading steps n/N, integrating slab n/N...
        progress = RefineProgress(self._note, len(state.views), "frame", rid)
        try:
            with reporting(progress):
                cvs, integrate_ms, incremental = self.views.chronovolumes(state)
            progress("drawing", 0, len(cvs))
            self._send_frame(state, rid, cvs, integrate_ms, incremental, t_start, progress)
        finally:
            progress.finish()  # (a failed frame's)
        self._memory_after()
        self._histogram_after(state)
        self._warm_after(state)

    def _warm_after(self, state: ViewState) -> None:
        """After the first frame of a data set: the kernels of a first recolouring TF edit
        loaded on the side thread (`warm_kernels`), while the user looks at the picture."""
        dtype = self.datasets[state.dataset].series.dtype
        if dtype not in self._warmed:
            device = self.views.recolouring.device
            if self.side.submit(("warm", dtype), lambda: warm_kernels(dtype, device)):
                self._warmed.add(dtype)

    def _left_wait(self) -> float:
        """Seconds this frame may still wait for the clients that left (`_left` held)."""
        now = time.monotonic()
        ends = [t + TUNING.left_wait_s - now for w, t in _leaving.items() if w is not self]
        return max(ends, default=0.0)

    def _memory_after(self) -> None:
        """The frame's memory noted for the process's limit; a line in the log when over it."""
        over = self.views.frame_done()
        if over:
            log.warning("chronocl viewer: %s", over)

    def _refine(self) -> None:
        """The coarse or reduced frame shown, at full resolution and size; given up as soon as
        new input (or a `cancel`) comes: between views, between the slabs of a view's
        integration, while its steps are read (`chronocl.core.interrupt`; the client hears of
        each in a `progress` message), between its upload's slabs and before its draw."""
        self._refine_at = None
        state = self._shown
        if state is None:
            return
        if any(slot.cv is None for slot in self.views.slots[: len(state.views)]):
            return  # a frame moving the window failed since: nothing shown to refine
        t_start, integrate_ms = time.perf_counter(), 0.0
        self.views.times.start()
        progress = RefineProgress(self._note, len(state.views))
        try:
            with interruptible(self._given_up, progress):
                for i, slot in enumerate(self.views.slots[: len(state.views)]):
                    progress.view = i
                    if self._given_up() or slot.session is None:
                        return  # newer input: the frame for it comes instead
                    if slot.uploaded is not slot.cv:  # its slabs may go into the texture
                        self.views.recolouring.settle(slot)
                    integrate_ms += self.views.refine_slot(slot)
            cvs = [slot.cv for slot in self.views.slots[: len(state.views)]]
            incremental = self.views.refine_incremental  # its views' level 0 slid
            self._send_frame(
                state, self._last_rid, cvs, integrate_ms, incremental, t_start, final=True
            )
        except SupersededError:
            return
        self._memory_after()

    def _prepare(self) -> None:
        """The winners of the sharp frame shown gathered for its views' first TF edit, given up
        as soon as new input comes (`Recolouring.prepare`)."""
        self._prepare_at = None
        limit = process_memory.current()
        if limit is not None and limit.excess() > 0:
            return  # over the memory limit already: the first edit prepares them
        try:
            with interruptible(self._given_up):
                for slot in self.views.slots[: len(self._shown.views) if self._shown else 0]:
                    if self._given_up():
                        return
                    self.views.recolouring.prepare(slot)
        except SupersededError:
            return
        except Exception as exc:  # work nobody asked for: logged, not sent to the page
            error_text(exc, "gathering the winners at idle")
            return
        self._memory_after()

    def _send_frame(
        self,
        state,
        rid,
        cvs,
        integrate_ms,
        incremental,
        t_start,
        progress: RefineProgress | None = None,
        final: bool = False,
    ) -> None:
        """Draw, encode and send the frame. A frame answering input draws what the draw budget
        allows in `TUNING.draw_target_ms`; if that is less than the panels' size (within
        `TUNING.pixel_budget`), the frame is redrawn in full once input stops (`final`), as
        coarse levels are. Its `progress` is finished just before it is sent: no report of it
        goes after it."""
        state = self._framed(state, cvs)
        preview = state.quality == "preview"
        scale = TUNING.preview_scale if preview else 1.0
        w, h = full_w, full_h = render_size(state.size, len(cvs), scale)
        if not final:  # a sharp frame whose full-size draw fits the latency target: at once
            sharp = not preview and self.views.sharp(len(cvs))
            budget = self._draw_budget.pixels(sharp, full_w * full_h * len(cvs))
            w, h = render_size(state.size, len(cvs), scale, budget)
        # Any shrink is redrawn: a settled view is always the same frame (4 % smaller differed).
        reduced = not preview and (w, h) != (full_w, full_h)
        bg = parse_color(state.background)
        t0 = time.perf_counter()
        stop = self._given_up if final else None  # a refine's upload and draw are given up too
        times = self.views.times
        read_ms = times.readback_ms
        panels, t_up, t_draw, t_done = on_gl(self._draw, cvs, state, (w, h), bg, stop)
        # an older recoloured frame read back before its texture took this one: readback_ms's
        upload_s = t_draw - t_up - (times.readback_ms - read_ms) / 1e3
        images = [encode(p, JPEG_QUALITY[state.quality]) for p in panels]
        t_enc = time.perf_counter()
        self._frame += 1
        self._shown, self._last_rid = state, rid
        sessions = [s.session for s in self.views.slots[: len(cvs)] if s.session]
        # The level model predicts frames answering input: a final frame counts as their share.
        share = min(1.0, self._draw_budget.pixels() / max(1, w * h * len(cvs)))
        self._draw_budget.record(1e3 * (t_done - t_draw), w * h * len(cvs))
        display_ms = 1e3 * (upload_s + share * (t_done - t_draw)) / max(1, len(cvs))
        # once a level: the views' sessions share their measured rates (`Views.slide_costs`)
        for session in {s.shown_level: s for s in sessions}.values():
            session.record_display(display_ms)
        level = max((session.shown_level for session in sessions), default=0)
        levels = max((session.stats.get("levels", 1) for session in sessions), default=1)
        refining = (level > 0 or reduced) and not self._cancelled
        # newer input gives the refine up
        wait = TUNING.refine_after_s if state.quality == "preview" else 0.0
        self._refine_at = time.monotonic() + wait if refining else None
        recolours = any(mode in RECOLOURED for mode, _ in state.views)
        self._prepare_at = None if refining or not recolours else t_done + TUNING.prepare_after_s
        header = {
            "type": "frame",
            "id": rid,
            "seq": self._frame,
            "quality": state.quality,
            "format": "jpeg",
            "views": [
                {
                    "width": w,
                    "height": h,
                    "bytes": len(b),
                    "label": describe(cv),
                    "note": empty_note(mode, modes.get(mode).summary, visible_fraction(pixels, bg)),
                    # a TF edit in a mode that recolours integrated instead: why (else null)
                    "why_integrated": slot.why_not_recoloured,
                }
                for b, cv, pixels, (mode, _), slot in zip(
                    images, cvs, panels, state.views, self.views.slots[: len(cvs)], strict=True
                )
            ],
            "probe": self._probe_mark(state, cvs),
            # each view's, under its own camera (the same where the cameras are linked)
            "clip_outlines": [
                clip_outline(cv, state.panel_camera(i), state.size, state.clip)
                for i, cv in enumerate(cvs)
            ],
            "axes": self._axes(state, cvs),
            "legends": [legend(cv) for cv in cvs],  # a view with its own window has its own
            "colorbars": [colour_bar(cv) for cv in cvs],  # null where the data TF is white
            # a count view's bar, drawn instead of its time legend (null where colour is time)
            "countbars": [count_bar(cv) for cv in cvs],
            "focus": None if state.camera.focus is None else list(state.camera.focus),
            "level": level,
            "levels": levels,  # from the sessions: no store metadata read per frame
            "level_shape": list(cvs[0].shape),
            "refining": refining,
            "reduced": reduced,  # drawn smaller than the panels for the latency target
            "timings": {
                "integrate_ms": round(integrate_ms, 2),
                # of it, waiting for steps read from the store (0: resident or read ahead)
                "read_ms": round(times.read_ms, 2),
                # a coarse frame that read no full-resolution step ahead for its refine: why
                "why_not_read_ahead": self.views.said("why_not_read_ahead"),
                "recolour_ms": round(times.recolour_ms, 2),  # a TF edit's, not integrated
                # a GPU recolour's RGBA read back for this frame (framing; an older one still
                # held, its texture taking this one): 0 where nothing read it
                "readback_ms": round(times.readback_ms, 2),
                "incremental": incremental,
                "why_not_incremental": self.views.why_not_incremental,  # integrated again: why
                # + a recolour's texture write; a refine's slabs are written within integrate_ms
                "upload_ms": round(1e3 * upload_s + times.recolour_upload_ms, 2),
                "upload_overlapped_ms": round(times.slab_upload_ms, 2),
                "allocated": self._allocated(),  # textures: 0 once each panel and level has one
                "render_ms": round(1e3 * (t_done - t_draw), 2),
                "gl_wait_ms": round(1e3 * (t_up - t0), 2),
                "encode_ms": round(1e3 * (t_enc - t_done), 2),
                "server_ms": round(1e3 * (t_enc - t_start), 2),
                "steps_on_host": self.views.host_steps_why,  # None: on the device, or a CPU's
                "streamed": self.views.streamed(),  # None: the window is resident
            },
            "sent_at": time.time(),
        }
        if progress is not None:
            progress.finish()
        self.send(pack_frame(header, images))

    def _allocated(self) -> int:
        """The textures the views allocated since the last frame was sent; their counts start
        again."""
        slots = self.views.slots
        allocated = sum(slot.allocated for slot in slots)
        for slot in slots:
            slot.allocated = 0
        return allocated

    def _framed(self, state: ViewState, cvs: list[Chronovolume]) -> ViewState:
        """`state` with its camera framing this generation's visible region."""
        with self._cond:
            gen, known = self._focus_gen, self._focus
        if known is None or known[0] != gen:  # (framing reads the RGBA: a GPU recolour's too)
            known = (gen, framed(dataclasses.replace(state.camera, focus=None), cvs).focus)
            with self._cond:
                if self._focus_gen == gen:
                    self._focus = known
        return dataclasses.replace(state, camera=dataclasses.replace(state.camera, focus=known[1]))

    def _axes(self, state: ViewState, cvs: list[Chronovolume]) -> list | None:
        """`views_axes` of the views shown (None with the box off)."""
        return views_axes(state, cvs, self.datasets[state.dataset].series)

    def _axes_drawn(self, panels: list, state: ViewState, cvs: list[Chronovolume]) -> list:
        """`panels` as drawn with `_axes` on them (a saved PNG's, a movie's frames)."""
        axes = self._axes(state, cvs)
        if axes is None:
            return panels
        return [draw_axes(p, a) for p, a in zip(panels, axes, strict=True)]

    def _probe_mark(self, state: ViewState, cvs: list[Chronovolume]) -> dict | None:
        """Where the probed voxel is on its panel in this frame (None: no probe, or off-panel)."""
        probed = self._probed  # (read once: a probe from code sets it from another thread)
        if probed is None or probed[0] >= len(cvs):
            return None
        view, where = probed
        at = project(cvs[view], state.panel_camera(view), state.size, where)
        return None if at is None else {"view": view, "x": at[0], "y": at[1]}
