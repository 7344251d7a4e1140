"""`ChronoclWidget`: the browser viewer in a notebook cell, on the widget's comm (anywidget).

The kernel's process renders, with the viewer's own `ClientWorker`: the page's messages
arrive as custom comm messages {"text": JSON} and are answered as the viewer's socket answers
them (`viewer.sockets.answer`: validated by `protocol.parse_message`, applied by `handle`);
frames go back as binary buffers ({"frame": 1} and the packed frame), text messages as
{"text": JSON}, downloads as {"download": JSON} and the file. No port is opened.

The synced attributes (`window`, `mode`, `views`, `data_tf`, `time_tf`, `camera`:
chronocl/notebook/state.py) are the worker's state: setting one sends the update to the
worker (validated as the page's are; a bad value raises and changes nothing) and tells the
page, which shows it; the page's own edits come back into them. `observe` sees both.
JupyterLab 4 sends comm messages over subshells, so ipykernel 7 may hand the page's messages
to the widget on another thread than the cells': an edit and a set from code are applied one
at a time (`_synced`), each whole, and the observers are called after, the widget free for
other threads meanwhile (each thread's in the order of its changes).
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import tempfile
import threading
import time
import zipfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, nullcontext

import anywidget
import numpy as np
import traitlets

from chronocl.core.errors import ChronoclError, InvalidParameterError, RendererUnavailableError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.probe import check_point
from chronocl.notebook import state as synced
from chronocl.notebook import views as shown_views
from chronocl.notebook.bundle import esm
from chronocl.notebook.kernel import KERNEL
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.gl_thread import on_gl
from chronocl.viewer.probe import pinned_reply, project
from chronocl.viewer.protocol import parse_message, unpack_frame
from chronocl.viewer.residency import POLL_S, residency
from chronocl.viewer.saving import Downloads
from chronocl.viewer.snapshot import snapshot_of
from chronocl.viewer.sockets import answer, info_message
from chronocl.viewer.view_state import default_state, describe_state
from chronocl.viewer.worker import ClientWorker

REQUEST_TIMEOUT_S = 120.0
# The ids of the kernel's own requests (attributes set, screenshots, chronovolumes): above any
# the page uses, so that the page takes a frame answering one as the answer to its own.
OWN_IDS = 2**52
FRAMED = ("update", "open", "load")  # the requests a frame answers
LOCKED = (*synced.SYNCED, "height")  # the attributes the page sets too: set under `_synced`
FAILURES_KEPT = 32  # the frame failures remembered, by request id (the newest kept)
# How long a widget no view shows keeps its worker before it is suspended (`suspended`): a
# notebook re-rendering an output (a cell moved, an output area rebuilt, a notebook's tab
# closed and opened) removes the view and adds one a moment later, and that should cost no
# new worker and no steps read again.
SUSPEND_AFTER_S = 3.0


class WidgetClosedError(ChronoclError, RuntimeError):
    """The widget was closed: its worker and resources are gone."""


class FrameFailedError(ChronoclError, RuntimeError):
    """The frame a widget waited for failed: the worker's error (what the page shows)."""


def _voxel_of(point: object, series, world: bool) -> tuple[int, int, int]:
    """`point` (x, y, z) as voxel indices of `series`, checked inside it: as given, or from
    physical coordinates from the box's corner (`world`)."""
    if isinstance(point, str) or not isinstance(point, Sequence) or len(point) != 3:
        raise InvalidParameterError(f"a probe point is (x, y, z), x first, not {point!r}")
    if not world:
        return check_point(point, series.volume_shape)
    try:
        p = np.array([float(v) for v in point])
    except (TypeError, ValueError):
        raise InvalidParameterError(
            f"a world point is three numbers (x, y, z), not {point!r}"
        ) from None
    spacing = np.array(series.spacing, dtype=np.float64)
    extent = spacing * np.array(series.dims)
    if not (np.isfinite(p).all() and (p >= 0).all() and (p < extent).all()):
        raise InvalidParameterError(
            f"world point {tuple(p.tolist())} is outside the box from (0, 0, 0) to "
            f"{tuple(extent.tolist())} (x, y, z, from its corner)"
        )
    return tuple(int(v) for v in np.floor(p / spacing))  # type: ignore[return-value]


def _settled(header: dict) -> bool:
    """A frame's header: it is the settled one (full quality and resolution, not refining)."""
    return header["quality"] == "full" and not header["refining"]


def _plain(value: object) -> object:
    """A numpy scalar or array as the Python numbers it holds (`json.dumps`'s `default`)."""
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not a number, a list or a dict")


def _json(message: dict, what: str) -> str:
    """`message` as JSON text, numpy numbers as the numbers they hold; InvalidParameterError
    naming `what` where it holds anything else."""
    try:
        return json.dumps(message, default=_plain)
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"{what} is not plain data: {exc}") from None


def check_gl() -> None:
    """RendererUnavailableError, saying what to do, where this process cannot make the OpenGL
    context the viewer draws with (no EGL, no GL driver)."""
    try:
        on_gl(lambda rc: None)
    except RendererUnavailableError as exc:
        raise RendererUnavailableError(
            f"chronocl.show draws in the kernel's process, which has no OpenGL context: {exc}. "
            "Still pictures need it too; run the kernel where EGL works (a headless Linux with "
            "libegl1 and Mesa does)."
        ) from None


class ChronoclWidget(anywidget.AnyWidget):
    """The viewer of one data set in a notebook cell (`chronocl.show` makes it)."""

    _esm = esm()
    height = traitlets.Int(620, help="the widget's height on the page, CSS pixels").tag(sync=True)
    window = traitlets.Tuple(help="(t0, t1, stride): the window of steps, t1 exclusive")
    mode = traitlets.Unicode(help="the first view's integration mode")
    views = traitlets.List(
        help="the views side by side: {'mode', 'order', 'window', 'camera', 'data_tf', "
        "'time_tf'} each (a view's own, None where linked to the shared one)"
    )
    data_tf = traitlets.Dict(help="the data transfer function: points and value range")
    time_tf = traitlets.Dict(help="the time transfer function")
    camera = traitlets.Dict(help="azimuth, elevation, zoom, fov, projection, up")
    # How often each view says it is alive (chronocl/notebook/views.py), for widget.js.
    _heartbeat_s = traitlets.Float(shown_views.HEARTBEAT_S).tag(sync=True)
    _syncing_in: int | None = None  # (`__init__`)
    _sync = nullcontext()  # (`__init__`; kept by a widget `check_gl` refused: nothing to order)
    _closed = True  # until its worker runs (a widget that failed to start has nothing to free)
    _live: ClientWorker | None = None  # the worker; None while suspended (`_worker` resumes)
    # Set while a suspended worker is being ended (outside `_life`): cleared, with its share of
    # the kernel let go, before anything resumes (`_let_go`).
    _ending: threading.Event | None = None

    def __init__(
        self,
        dataset: Dataset,
        *,
        engine: str = "opencl",
        device: str | None = None,
        memory: str | int | None = None,
        height: int = 620,
        store: tuple | None = None,
    ) -> None:
        check_gl()
        # The page's edits (the comm's thread) and sets from code (a cell's), one at a time
        # (`_synced`); `_syncing_in`: the thread setting the attributes to the worker's state
        # (at first, this one: their first values are the worker's), whose sets are not sent
        # back; `_due`: per thread, the changes whose observers are still to be called.
        self._sync = threading.RLock()
        self._due = threading.local()
        self._syncing_in = threading.get_ident()
        super().__init__(height=height, _heartbeat_s=shown_views.HEARTBEAT_S)
        self._datasets = [dataset]
        self._downloads = Downloads()
        self._cond = threading.Condition()
        # Held while the worker is made, suspended or freed (the kernel's thread and the
        # suspend timer's): one of them at a time; before `_cond` where both are taken.
        self._life = threading.RLock()
        self._engine, self._device, self._store = engine, device, store
        self._saved: tuple | None = None  # while suspended: the worker's state and focus
        shown_views.CELL_TIME.watch()  # a view's silence while a cell runs is the kernel's
        self._views = shown_views.Views()  # the page's views showing the widget now
        self._view_gen = 0  # counts the views shown and gone (a suspend timer's turn)
        self._used_at = time.monotonic()  # the worker's last use (`_worker`)
        self._busy = 0  # the kernel's waits on the worker in progress (no suspending then)
        self._requests: dict[int, dict | None] = {}
        self._next_own = OWN_IDS
        self._newest_id: int | None = None  # the newest request a frame answers
        # The worker's errors making frames, by the request they answer (its one line each).
        self._failed: dict[int, str] = {}
        self._frames = 0
        self.last_frame: dict | None = None  # the newest frame's header (and its digest)
        # No frame until one is wanted: a page's first request (its panels' size), or the
        # kernel's (`wait_frame`, a screenshot); a frame of the default size made before the
        # page comes only delays the page's own.
        self._drawing = False
        self._shared, memory = KERNEL.join(id(self), dataset.series, store, memory)
        self._memory = memory  # the worker's budget (a resumed one keeps it)
        try:
            self._live = ClientWorker(
                self._datasets, self._deliver, self._downloads, engine=engine, device=device,
                memory=memory, shared=self._shared,
            )  # fmt: skip
        except Exception:
            KERNEL.leave(id(self), dataset.series)
            raise
        self._closed = False
        try:
            opened = self._live.open(0, None, frame=False)
        except Exception:  # (the data set's sample unreadable): nothing left running
            self.close()
            raise
        self._fitted = opened.get("fitted")
        self._opened_tf = opened["state"]["data_tf"]
        self._pull(tell_page=False)
        self.on_msg(self._on_msg)
        # The front end closed the model (its notebook closed, the widget closed from
        # JavaScript): the worker goes as with `close()`.
        self.comm.on_close(lambda _msg: self._front_end_closed())
        self._poller = threading.Thread(target=self._poll, daemon=True)
        self._poller.start()

    # -- the page's messages (the kernel's shell or a subshell's thread) ---------------------
    def _on_msg(self, _widget, content, _buffers) -> None:
        if self._closed or not isinstance(content, dict):
            return
        if content.get("view") in ("shown", "alive", "gone"):  # widget.js: a view's news
            if isinstance(content.get("id"), str):
                self._view_said(content["view"], content["id"], bool(content.get("hidden")))
            return
        if content.get("type") == "hello":  # a view was rendered: it starts as a socket does
            self.send({"text": json.dumps(info_message(self._datasets))})
            return
        if "text" not in content:
            return  # not the viewer's (anywidget's own messages)
        with self._synced():
            if self._closed:  # (by a cell meanwhile)
                return
            with self._life:  # (where a suspend clears it: the worker resumed and used now)
                self._worker  # noqa: B018
                self._drawing = True  # the page's requests are answered with frames from now on
            reply = self._answer(content["text"])
            if reply is not None:
                self.send({"text": json.dumps(reply)})
            if reply is None or reply.get("type") == "dataset":
                self._pull(tell_page=False)  # the page's edit, into the attributes

    def _answer(self, text: object) -> dict | None:
        """The page's message answered as the socket answers it; an `open` (a view shown, or
        shown again) gets the state the widget has, not a new default, and makes no frame:
        the page's next update (its panels' size) does."""
        try:
            msg = parse_message(text)
        except ChronoclError:
            return answer(self._worker, text)  # the error reply, as the socket's
        rid, newest = msg.get("id"), self._newest_id
        if msg["type"] in FRAMED:
            self._newest_id = rid
            with self._cond:  # (a page shown again numbers its requests from 1 again)
                self._failed.pop(rid, None)
        if msg["type"] != "open":
            reply = answer(self._worker, text)
            if reply is not None and reply.get("type") == "error":
                self._newest_id = newest  # refused: nothing changed, no frame answers it
            return reply
        ds = self._datasets[0]
        opening = default_state(0, ds.series)
        reply = {"type": "dataset", "id": rid, **ds.info(0)}
        reply |= {"state": self._described(), "opening_camera": describe_state(opening)["camera"]}
        if self._fitted is not None and self.data_tf == self._opened_tf:
            reply["fitted"] = self._fitted  # the page's fit note, as a data set opens
        return reply

    # -- the worker's messages (its threads) ------------------------------------------------
    def _deliver(self, data: str | bytes, wait: bool = True) -> bool:
        """The worker's `send`: a frame as a buffer; a download or error that answers the
        kernel's own request to it; anything else to the page."""
        if self._closed:
            return False
        if isinstance(data, bytes):
            header, images = unpack_frame(data)
            digest = hashlib.blake2b(b"".join(images), digest_size=8).hexdigest()
            # sent before it is announced: whoever waited for it finds it sent to the page
            self.send({"frame": 1}, buffers=[data])
            with self._cond:
                self._frames += 1
                self.last_frame = header | {"digest": digest, "received_at": time.time()}
                self._cond.notify_all()
            return True
        if data.startswith(('{"type": "download"', '{"type": "error"')):
            reply = json.loads(data)
            with self._cond:
                if reply.get("id") in self._requests:
                    self._requests[reply["id"]] = reply
                    self._cond.notify_all()
                    return True
                if reply["type"] == "error":
                    self._note_failure(reply)
            if reply["type"] == "download":
                self._send_download(reply)
                return True
        self.send({"text": data})
        return True

    def _note_failure(self, reply: dict) -> None:
        """A worker's error (under `_cond`), kept for `wait_frame` where it ends a frame: the
        request's it answers, or (no id) the refine's of the frame shown, where that frame
        answers the newest request and is not settled yet."""
        rid = reply.get("id")
        if rid is None:
            last = self.last_frame
            if last is None or last["id"] != self._newest_id or _settled(last):
                return
            rid = last["id"]
        self._failed[rid] = " ".join(str(reply.get("message", "")).split())
        while len(self._failed) > FAILURES_KEPT:
            del self._failed[next(iter(self._failed))]
        self._cond.notify_all()

    def _send_download(self, reply: dict) -> None:
        key = reply.pop("url").rsplit("/", 1)[-1]
        found = self._downloads.get(key)
        if found is None:
            return
        path, filename, media_type = found
        head = reply | {"filename": filename, "media_type": media_type}
        self.send({"download": json.dumps(head)}, buffers=[path.read_bytes()])

    def _poll(self) -> None:
        """Every POLL_S: the views whose heartbeats stopped counted gone (`_expire_views`), and
        the timeline's resident steps (`viewer.residency`) reported as the socket reports them."""
        last = None
        while not self._closed:
            self._expire_views()
            worker = self._live  # (not `_worker`: a suspended widget stays suspended)
            if worker is None:
                last = None  # a resumed worker's steps are reported afresh
                time.sleep(POLL_S)
                continue
            try:
                now = residency(worker.views)
            except Exception:  # the views changing under the poll: the next one reads them
                now = last
            if now != last and any(v is not None for v in now or []):
                self.send({"text": json.dumps({"type": "steps", "views": now})})
                last = now
            time.sleep(POLL_S)

    # -- the synced attributes ---------------------------------------------------------------
    def _described(self) -> dict:
        return describe_state(self._worker.state)

    def _pull(self, tell_page: bool) -> None:
        """The attributes set from the worker's state; `tell_page`: the page is sent the state
        too. The observers of those that changed are called once the edit or set that pulled
        is done (`_synced`)."""
        with self._synced():
            described = self._described()
            self._syncing_in = threading.get_ident()
            try:
                for name, value in synced.from_state(described).items():
                    setattr(self, name, value)
            finally:
                self._syncing_in = None
            if tell_page:
                told = ("window", "views", "camera", "data_tf", "time_tf")
                fields = {k: described[k] for k in told}
                self.send({"text": json.dumps({"type": "state", "state": fields})})

    @contextmanager
    def _synced(self) -> Iterator[None]:
        """`_sync` held: a page's edit or a set from code, whole. Once this thread's outermost
        one is done and the lock let go, the observers of the attributes it changed are called,
        in order; a set an observer makes is applied at once and its changes are called after
        (two widgets whose observers set each other never wait for each other's lock)."""
        due = self._due
        outer = not getattr(due, "depth", 0) and not getattr(due, "calling", False)
        if outer:
            due.changes = []
        try:
            with self._sync:
                due.depth = getattr(due, "depth", 0) + 1
                try:
                    yield
                finally:
                    due.depth -= 1
        finally:
            if outer:
                due.calling = True
                try:
                    while due.changes:
                        super()._notify_observers(due.changes.pop(0))
                finally:
                    due.calling, due.changes = False, None

    def _notify_observers(self, event) -> None:
        # A change made under `_synced` on this thread (a pull, the front end's `set_state`)
        # reaches its observers once the lock is let go; the page was told already
        # (`Widget.notify_change`).
        due = getattr(self, "_due", None)
        changes = getattr(due, "changes", None) if getattr(due, "depth", 0) else None
        if changes is not None and event["type"] == "change":
            changes.append(event)
        else:
            super()._notify_observers(event)

    def _set(self, name: str, value: object) -> object:
        """Apply `name = value` to the worker (as the page's update would be) and tell the
        page; returns the value the attribute then has."""
        self._check_open()
        fields = synced.to_fields(name, value, self._described())
        text = _json({"type": "update", "id": self._own_id(), **fields}, f"{name} = {value!r}")
        msg = parse_message(text)  # ProtocolError naming the field, before anything changes
        if self._drawing:
            reply = answer(self._worker, text)
            if reply is not None and reply.get("type") == "error":
                raise InvalidParameterError(reply["message"])
        else:  # nothing shows it yet: the first frame wanted will
            self._worker.update(msg, frame=False)
        self._newest_id = msg["id"]
        self._pull(tell_page=True)
        return getattr(self, name)

    def _set_from_code(self, name: str):
        """Where a set of `name` waits while a page's edit is applied on another thread (the
        set and the edit each whole, in one order for the worker and the attributes)."""
        if name in LOCKED and self._syncing_in != threading.get_ident():
            return self._synced()
        return nullcontext()

    def __setattr__(self, name: str, value: object) -> None:
        with self._set_from_code(name):
            super().__setattr__(name, value)

    def set_trait(self, name: str, value: object) -> None:
        with self._set_from_code(name):
            super().set_trait(name, value)

    def set_state(self, sync_data) -> None:
        with self._synced():  # (the front end's sync of `height`)
            super().set_state(sync_data)

    @contextmanager
    def hold_trait_notifications(self) -> Iterator[None]:
        # Sets in it are applied and checked at once, as plain sets are (traitlets' deferred
        # check of each would find it overwritten by the pull of the one checked before);
        # the observers wait until the block is done and the lock let go (`_synced`), and a
        # page's edit waits for the block. (`trait_set`, ipywidgets' `set_state` use it.)
        with self._synced():
            yield

    @traitlets.validate(*synced.SYNCED)
    def _validate(self, proposal):
        if self._syncing_in == threading.get_ident():
            return proposal["value"]
        return self._set(proposal["trait"].name, proposal["value"])

    # -- pictures, chronovolumes, sessions ---------------------------------------------------
    def warm(self) -> None:
        """Integrate the widget's window now, while its page loads (`ClientWorker.warm`): the
        page's first frame then only draws."""
        self._check_open()
        self._worker.warm()

    def _check_open(self) -> None:
        if self._closed:
            raise WidgetClosedError("this widget was closed; chronocl.show(...) makes a new one")

    def _own_id(self) -> int:
        with self._cond:
            self._next_own += 1
            return self._next_own

    def wait_frame(self, after: int = 0, timeout: float = REQUEST_TIMEOUT_S) -> dict:
        """The header of the settled frame (full quality and resolution) answering the newest
        request (an attribute set, or the page's edit), once more than `after` frames were
        made (`frames`), waited for. Where no frame was wanted yet (no page has shown the
        widget), one is made for the state now. FrameFailedError at once where the worker
        failed to make it (the error the page shows, in one line)."""
        with self._cond:
            self._busy += 1  # not suspended while it waits
        try:
            # (a page's first request may come meanwhile: the newest then; a suspend clears
            # `_drawing` and a close sets `_closed` under `_life`)
            with self._sync, self._life:
                self._check_open()
                if not self._drawing:
                    rid = self._own_id()
                    self._worker.update({"type": "update", "id": rid})
                    self._drawing, self._newest_id = True, rid
            end = time.monotonic() + timeout
            with self._cond:
                while True:
                    last = self.last_frame
                    if (
                        self._frames > after
                        and last is not None
                        and last["id"] == self._newest_id
                        and _settled(last)
                    ):
                        return last
                    failed = self._failed.get(self._newest_id)
                    if failed is not None:
                        raise FrameFailedError(f"the frame failed: {failed}")
                    self._check_open()
                    left = end - time.monotonic()
                    if left <= 0:
                        raise InvalidParameterError(f"no settled frame came in {timeout:.0f} s")
                    self._cond.wait(min(left, 0.5))
        finally:
            with self._cond:
                self._busy -= 1

    @property
    def frames(self) -> int:
        """Frames made so far."""
        return self._frames

    def _request(self, msg: dict) -> dict:
        """A request of the kernel's own to the worker (as the page's save requests), its
        reply waited for; ChronoclError with the worker's message where it failed. Checked as
        the page's are first (ProtocolError naming the field: `screenshot(columns=-1)` was a
        worker's internal error, `chronovolume(view=-1)` another view's chronovolume)."""
        self._check_open()
        rid = self._own_id()
        msg = parse_message(_json(msg | {"id": rid}, f"the {msg['type']} request"))
        with self._cond:
            self._requests[rid] = None
            self._busy += 1  # not suspended while it waits
        try:
            self._worker.task(msg["type"], msg | {"id": rid})
            end = time.monotonic() + REQUEST_TIMEOUT_S
            with self._cond:
                while self._requests[rid] is None:
                    self._check_open()
                    left = end - time.monotonic()
                    if left <= 0:
                        raise InvalidParameterError(f"{msg['type']} got no answer")
                    self._cond.wait(min(left, 0.5))
                reply = self._requests[rid]
        finally:
            with self._cond:
                self._requests.pop(rid, None)
                self._busy -= 1
        if reply["type"] == "error":
            raise InvalidParameterError(reply["message"])
        return reply

    def _download(self, msg: dict) -> tuple[bytes, str]:
        self.wait_frame()  # a save draws the views shown
        reply = self._request(msg)
        found = self._downloads.get(reply["url"].rsplit("/", 1)[-1])
        if found is None:
            raise InvalidParameterError("the saved file is gone; save it again")
        path, filename, _ = found
        return path.read_bytes(), filename

    def screenshot(self, *, columns: int | None = None):
        """The views shown, at full resolution, captioned and titled as the page's Save PNG
        draws them: an IPython Image of the PNG (its bytes: `.data`)."""
        from IPython.display import Image

        msg = {"type": "save", "what": "image"}
        if columns is not None:
            msg["columns"] = columns
        data, _ = self._download(msg)
        return Image(data=data, format="png")

    def chronovolume(self, view: int = 0) -> Chronovolume:
        """The chronovolume of `view` as shown, integrated again at full resolution and
        precision (as the page's Save chronovolume writes it), in memory."""
        data, _ = self._download({"type": "save", "what": "chronovolume", "view": view})
        with tempfile.TemporaryDirectory(dir=self._downloads.dir) as folder:  # (loaded whole)
            with zipfile.ZipFile(io.BytesIO(data)) as zf:
                zf.extractall(folder)
            return Chronovolume.load(folder)

    def snapshot(self) -> dict:
        """The state as a snapshot: the session file the page's Save session writes, which
        its Load session and `chronocl render --state` read."""
        self._check_open()
        ds = self._datasets[0]
        state = self._worker.state
        return snapshot_of(state, ds.name, ds.series, ds.path, self._worker.shown_focus())

    def probe(
        self,
        point: object = None,
        *,
        box: object = None,
        world: bool = False,
        view: int = 0,
        show: bool = True,
    ) -> dict:
        """v(t) at a point over every step of the series, as the page's probe plots it (its
        reply, the same fields): `point` is (x, y, z), x first, voxel indices of the full
        resolution series, or with `world` physical coordinates from the box's corner (voxel
        i spans [i*dx, (i+1)*dx) along x; `spacing` is the series'); or `box` (x, y and z
        ranges, or 'x0:x1,y0:y1,z0:z1', as `chronocl.probe` takes them): the mean, min and max
        over it per step. `view` gives the window whose steps are marked (`window`, and the
        CSV's in_window column). Keys: view, voxel ({x, y, z} or None), box ({x: [x0, x1],
        ...} or None), world (the voxel's or box's centre, physical x, y, z), values (one per
        step), min, max (a box's, else None), window (its steps), times, csv, mark (where the
        centre is on the view's panel in the last frame, (x, y) fractions; None: off it or no
        frame yet). It reads the point's steps (one small read per run of steps). With `show`
        the page's probe panel plots it too ("probed from code") and the view marks it, as a
        probe made on the page."""
        self._check_open()
        ds = self._datasets[0]
        series = ds.series
        state = self._worker.state
        if isinstance(view, bool) or not isinstance(view, int) or not 0 <= view < len(state.views):
            raise InvalidParameterError(
                f"view {view!r} is not shown; views 0..{len(state.views) - 1}"
            )
        if (point is None) == (box is None):
            raise InvalidParameterError("give a point (x, y, z) or a box, not both or neither")
        if box is not None:
            if world:
                raise InvalidParameterError("a box is in voxel indices; world= is for a point")
            curve = ds.curve(box=box)
            lo = np.array([r[0] for r in curve.box], dtype=np.float64)
            hi = np.array([r[1] for r in curve.box], dtype=np.float64)
            voxel, boxed = (
                None,
                {a: [int(a0), int(a1)] for a, a0, a1 in zip("xyz", lo, hi, strict=True)},
            )
        else:
            index = _voxel_of(point, series, world)
            curve = ds.curve(index)
            lo = np.array(index, dtype=np.float64)
            hi = lo + 1
            voxel, boxed = dict(zip("xyz", index, strict=True)), None
        dims = np.array(series.dims, dtype=np.float64)
        fractions = tuple(float(v) for v in (lo + hi) / 2 / dims)
        window = list(state.selection(series.n_steps, view).steps)
        got = {
            "view": view,
            "voxel": voxel,
            "box": boxed,
            "world": [
                float(f * n * d) for f, n, d in zip(fractions, dims, series.spacing, strict=True)
            ],
            "values": [float(v) for v in curve.values],
            "min": None if curve.min is None else [float(v) for v in curve.min],
            "max": None if curve.max is None else [float(v) for v in curve.max],
            "window": window,
            "times": list(series.times),
            "csv": curve.csv_text(window),
            "mark": self._mark(view, fractions),
        }
        if show:  # the page's probe panel plots it, and the frames mark it from now on
            self._worker.pin_probe(view, fractions)
            shown = pinned_reply(view, voxel, boxed, curve, window, got["mark"], "code")
            self.send({"text": json.dumps(shown)})
        return got

    def _mark(self, view: int, fractions: tuple) -> tuple[float, float] | None:
        """Where the box fractions `fractions` are on `view`'s panel as the frames show it (the
        last frame's chronovolume; the state's camera framing the region the frames frame)."""
        state = self._worker.state
        slots = self._worker.views.slots
        focus = self._worker.shown_focus()  # the region the frames frame (None: no frame yet)
        if focus is None or view >= len(state.views) or view >= len(slots):
            return None
        cv = slots[view].cv
        if cv is None:
            return None
        shown = dataclasses.replace(state, camera=dataclasses.replace(state.camera, focus=focus))
        return project(cv, shown.panel_camera(view), shown.size, fractions)  # its own camera

    # -- the end -----------------------------------------------------------------------------
    def close(self) -> None:
        """Free the worker (its thread, GL textures, OpenCL buffers, and the steps no other
        widget shows) and the comm (its views on the page go)."""
        with self._sync:  # (a close from the front end, on a subshell's thread, and an edit)
            self._free()
            super().close()

    def _front_end_closed(self) -> None:
        """The front end closed the comm: free the worker; the comm is closed already."""
        with self._sync:
            self._free()
            super().close()  # (forgets the comm; sends nothing more: it is closed)

    def _send(self, msg, buffers=None) -> None:
        comm = self.comm  # (read once: a close on another thread sets it to None)
        if comm is not None and getattr(comm, "kernel", True) is not None:
            comm.send(data=msg, buffers=buffers)

    def _free(self) -> None:
        if self._closed:  # closed, or never started (no `_life` either: `check_gl` refused)
            return
        with self._life:
            if self._closed:
                return
            self._closed = True
            with self._cond:
                self._cond.notify_all()
            if self._live is not None:  # (a suspended widget let its worker go already)
                self._end(self._live)  # (kept: what it was stays readable, `_worker.thread`)
            self._let_go()  # (one being suspended: ended by its timer's thread)
            self._downloads.close()

    def _end(self, worker: ClientWorker) -> None:
        """`worker` ended (its thread, GL textures, OpenCL buffers) and the widget's share of
        the kernel (the series' steps no other widget shows) let go."""
        worker.close()
        worker.thread.join(timeout=30)
        KERNEL.leave(id(self), self._datasets[0].series)

    @property
    def closed(self) -> bool:
        return self._closed

    # -- suspended while no view shows it ------------------------------------------------------
    @property
    def suspended(self) -> bool:
        """No view has shown the widget for SUSPEND_AFTER_S (its output cleared, its cell
        deleted), or its views' heartbeats stopped (their page reloaded, closed or crashed:
        chronocl/notebook/views.py): its worker is let go (its render thread, GL textures,
        OpenCL buffers, and its share of the kernel's memory and steps), its attributes and
        state kept. A view shown again (`display(w)`) or any use from code resumes it as it was."""
        return self._live is None and not self._closed and self._ending is None

    @property
    def _worker(self) -> ClientWorker:
        """The worker: every use of it goes through here, and a suspended widget's is made
        again here (`_resume`); WidgetClosedError where one closed while suspended has none."""
        with self._life:
            self._used_at = time.monotonic()
            if self._live is None:
                self._check_open()
                self._resume()
            return self._live  # type: ignore[return-value]

    def _let_go(self) -> None:
        """(Under `_life`.) Wait until a worker being suspended has ended and its share of the
        kernel is let go: a widget's share is one per widget (`KERNEL.join` by its id), so a
        new one joined before the old one left would be the one let go."""
        ending = self._ending
        if ending is not None:
            ending.wait()

    def _resume(self) -> None:
        """A new worker (under `_life`), showing what the suspended one showed: its state (the
        window, views, TFs, camera, panel size) and the region its frames framed."""
        self._let_go()
        state, focus = self._saved  # type: ignore[misc]
        series = self._datasets[0].series
        shared, _ = KERNEL.join(id(self), series, self._store, fallback=self._memory)
        try:
            worker = ClientWorker(
                self._datasets, self._deliver, self._downloads, engine=self._engine,
                device=self._device, memory=self._memory, shared=shared,
            )  # fmt: skip
        except Exception:
            KERNEL.leave(id(self), series)
            raise
        try:
            worker.open(0, None, fit=False, frame=False)  # nothing read: the state follows
            worker.state = state  # its thread idle: no frame is asked for yet
            if focus is not None:
                worker.update({"type": "update", "focus": list(focus)}, frame=False)
        except Exception:
            self._end(worker)
            raise
        self._shared, self._live, self._saved = shared, worker, None

    def _view_said(self, what: str, view: str, hidden: bool) -> None:
        """View `view` of the widget said it was rendered ("shown"), is alive ("alive", every
        HEARTBEAT_S; `hidden`: its page is) or was removed ("gone": its output cleared, its
        cell deleted, its page hidden for good). With none left for SUSPEND_AFTER_S the widget
        is suspended; a view counted shown anew resumes it now (its page's requests follow),
        its state integrated meanwhile."""
        with self._cond:
            changed = self._views.gone(view) if what == "gone" else self._views.heard(view, hidden)
            if not changed:
                return
            self._view_gen += 1
            gen, none = self._view_gen, not self._views
        if what != "gone":
            with self._life:
                was = self._live is None  # (suspended, or being suspended)
                worker = self._worker
            if was:
                worker.warm()
        elif none:
            self._suspend_after(gen, SUSPEND_AFTER_S)

    def _expire_views(self) -> None:
        """The views silent for longer than their bound (views.LOST_AFTER_S: a page reloaded,
        closed or crashed, which never said "gone") counted gone; with none left the widget is
        suspended at once (their silence was the grace)."""
        with self._cond:
            if not self._views.expire():
                return
            self._view_gen += 1
            gen, none = self._view_gen, not self._views
        if none:
            self._suspend_after(gen, 0.0)

    def _suspend_after(self, gen: int, delay: float) -> None:
        timer = threading.Timer(delay, self._suspend, args=(gen,))
        timer.daemon = True
        timer.start()

    def _suspend(self, gen: int) -> None:
        """(The timer's thread.) Let the worker go where no view was shown since turn `gen`,
        keeping its state for `_resume`; later where the kernel used the worker less than
        SUSPEND_AFTER_S ago or waits on it now. The worker is taken under `_life` and ended
        after it (its thread's join can take long): a use meanwhile resumes once it has ended
        and its share is let go (`_let_go`)."""
        with self._life:
            with self._cond:
                if self._closed or self._live is None or self._views or gen != self._view_gen:
                    return
                busy = self._busy
            left = self._used_at + SUSPEND_AFTER_S - time.monotonic()
            if busy or left > 0:
                self._suspend_after(gen, max(left, POLL_S))
                return
            worker = self._live
            self._saved = (worker.state, worker.shown_focus())
            # No frame until one is wanted again: a view's first request, or the kernel's; the
            # new worker's answer it (its frames numbered afresh).
            self._drawing = False
            self._ending = threading.Event()  # (first: `suspended` reads both)
            self._live = None
        try:
            self._end(worker)
        finally:
            with self._cond:
                self.last_frame = None
            # suspended (`suspended`) only now, its last frames delivered and forgotten
            self._shared = None
            ending, self._ending = self._ending, None
            ending.set()
