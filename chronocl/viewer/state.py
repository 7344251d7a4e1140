"""Per-client viewer state and its render worker.

Each WebSocket client owns a `ClientWorker`: the client's desired state (camera, views,
window, transfer functions, ...) and one thread that makes frames from it. Updates are
merged into the desired state at once (validated there, so a bad one is answered with an
error and changes nothing) and leave one "latest pending request" slot filled; the worker
always renders the newest state, so input that arrives while a frame is being made replaces
older pending input instead of queueing behind it. Each view keeps a `Session` (the moving
window: a slide of the window goes through `Session.slide`, which updates incrementally) and
its uploaded texture, so a camera change only re-renders and a window or TF change only
re-integrates what changed.

OpenCL integration is serialised per process (`INTEGRATE_LOCK`: the engine is shared). All
GL work runs on one thread (`on_gl`) that owns the viewer's own EGL context: a context can be
current in only one thread, and the process's context may already be current in another.
"""

from __future__ import annotations

import dataclasses
import io
import logging
import shutil
import tempfile
import threading
import time
import zipfile
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chronocl.core.enhance import Enhance
from chronocl.core.errors import ChronoclError, InvalidParameterError, UnknownNameError
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF, TimeAlpha, TimeColor, TimeTF
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.data.window import WindowManager
from chronocl.integration.session import Session
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.camera import Camera
from chronocl.render.raycaster import Volume, clip_plane, occupied_box
from chronocl.render.views import describe
from chronocl.viewer.protocol import pack_frame

log = logging.getLogger("chronocl.viewer")
INTEGRATE_LOCK = threading.Lock()
_gl_executor: ThreadPoolExecutor | None = None
_gl_raycaster = None
_gl_guard = threading.Lock()
HIST_BINS = 128
HIST_SAMPLE_STEPS = 4
MAX_TASKS = 8
PREVIEW_SCALE = 0.5
JPEG_QUALITY = {"preview": 70, "full": 88}
FLOAT_TEXTURE_VOXELS = 2**23  # 128 MB of float32 RGBA

# The viewer's default data TF: translucent shells rising with the value, white (colour by time).
DEFAULT_POINTS = (
    (0.0, 1.0, 1.0, 1.0, 0.0),
    (0.2, 1.0, 1.0, 1.0, 0.0),
    (0.55, 1.0, 1.0, 1.0, 0.35),
    (1.0, 1.0, 1.0, 1.0, 0.9),
)


def internal_error(exc: BaseException, where: str) -> str:
    """One line for an unexpected error, for the client and the log: the exception's type,
    never its text (which may hold paths) nor a traceback."""
    return (
        f"internal error ({type(exc).__name__}) {where}; the server keeps serving "
        "(please report it)"
    )


def error_text(exc: BaseException, where: str) -> str:
    """What a client is told of an error: a ChronoclError's own line, else `internal_error`
    (then logged in one line, the traceback at debug level only)."""
    if isinstance(exc, ChronoclError):
        return str(exc)
    text = internal_error(exc, where)
    log.error("chronocl viewer: %s", text)
    log.debug("chronocl viewer: %s", where, exc_info=exc)
    return text


# --------------------------------------------------------------------------- GL thread


def on_gl(fn: Callable, *args):
    """fn(raycaster, *args) on the viewer's GL thread; returns its result (or raises)."""
    global _gl_executor
    with _gl_guard:
        if _gl_executor is None:
            _gl_executor = ThreadPoolExecutor(1, thread_name_prefix="chronocl-viewer-gl")
    return _gl_executor.submit(_on_gl, fn, args).result()


def _on_gl(fn: Callable, args: tuple):
    global _gl_raycaster
    if _gl_raycaster is None:
        from chronocl.render.gl import new_egl_context
        from chronocl.render.raycaster import Raycaster

        _gl_raycaster = Raycaster(new_egl_context())
    return fn(_gl_raycaster, *args)


# --------------------------------------------------------------------------- data sets


class Dataset:
    """One series the server was started with, named for the client; statistics cached."""

    def __init__(self, name: str, series: TimeSeries) -> None:
        self.name = name
        self.series = series
        self._lock = threading.Lock()
        self._sample: np.ndarray | None = None

    def info(self, index: int) -> dict:
        s = self.series
        st = s.stats
        t, z, y, x = s.shape
        return {
            "index": index,
            "name": self.name,
            "shape": {"t": t, "z": z, "y": y, "x": x},
            "dtype": str(s.dtype),
            "vmin": s.vmin,
            "vmax": s.vmax,
            "step_min": [float(v) for v in st.step_min],
            "step_max": [float(v) for v in st.step_max],
            "step_mean": [float(v) for v in st.step_mean],
            "times": [str(v) for v in s.times],
        }

    def sample(self) -> np.ndarray:
        """Normalised values u of a few evenly spaced steps (subsampled), for histograms."""
        with self._lock:
            if self._sample is None:
                s = self.series
                n = min(HIST_SAMPLE_STEPS, s.n_steps)
                steps = sorted({round(v) for v in np.linspace(0, s.n_steps - 1, n)})
                nz = s.volume_shape[0]
                stride = 2 if min(s.volume_shape) >= 64 else 1
                parts = []
                for step in steps:
                    u = s.normalized([step], 0, nz)[0]
                    parts.append(u[::stride, ::stride, ::stride].ravel())
                self._sample = np.concatenate(parts).astype(np.float32)
            return self._sample

    def histogram(self, lo: float = 0.0, hi: float = 1.0) -> dict:
        if not hi > lo:
            raise InvalidParameterError(f"histogram range [{lo}, {hi}] must have lo < hi")
        counts, _ = np.histogram(self.sample(), bins=HIST_BINS, range=(lo, hi))
        return {"range": [lo, hi], "counts": counts.astype(int).tolist()}

    def curve(self, z: int, y: int, x: int) -> list[float]:
        """v(t) at one voxel over every step of the series."""
        values = np.asarray(self.series.data[:, z, y, x].compute(), dtype=np.float64)
        return [float(v) for v in values]


# --------------------------------------------------------------------------- desired state


@dataclass(frozen=True)
class ViewState:
    """Everything a frame depends on (one immutable snapshot per request)."""

    dataset: int = 0
    camera: Camera = field(default_factory=lambda: Camera(azimuth=30.0, elevation=20.0, zoom=1.2))
    views: tuple[tuple[str, str], ...] = (("alpha", "forward"),)
    window: tuple[int, int, int] = (0, 1, 1)
    data_tf: DataTF = field(default_factory=lambda: DataTF(points=DEFAULT_POINTS))
    time_tf: dict = field(
        default_factory=lambda: {
            "color": "rgb",
            "alpha": "constant",
            "value": 1.0,
            "center": 0.5,
            "width": 0.6,
            "floor": 0.1,
            "focus": 1.0,
            "falloff": 1.0,
            "positions": "relative",
        }
    )
    enhance: dict = field(
        default_factory=lambda: {"kind": "none", "k0": None, "k1": None, "k2": None}
    )
    threshold: float = 0.05
    clip: tuple[float, float, float, float] | None = None
    size: tuple[int, int] = (512, 512)
    quality: str = "full"
    background: str = "black"
    outline: bool = False

    def selection(self, n_steps: int) -> Selection:
        t0, t1, stride = self.window
        return Selection.window(t0, t1, stride, n_steps)

    def time_tf_object(self) -> TimeTF:
        t = self.time_tf
        color = (
            TimeColor("luminance", focus=t["focus"], falloff=t["falloff"])
            if t["color"] == "luminance"
            else TimeColor(t["color"])
        )
        if t["alpha"] == "constant":
            alpha = TimeAlpha("constant", value=t["value"])
        else:
            alpha = TimeAlpha(
                t["alpha"], value=t["value"], center=t["center"], width=t["width"], floor=t["floor"]
            )
        return TimeTF(color=color, alpha=alpha, positions=t["positions"])

    def spec(self, view: int, *, view_dir: tuple[float, float, float] | None = None):
        mode, order = self.views[view]
        e = self.enhance
        kwargs = {k: e[k] for k in ("k0", "k1", "k2") if e.get(k) is not None}
        if e["kind"] == "silhouette":
            kwargs["view"] = view_dir or self.camera.view_direction()
        return IntegrationSpec(
            mode=mode,
            order=order,
            data_tf=self.data_tf,
            time_tf=self.time_tf_object(),
            enhance=Enhance(e["kind"], **kwargs),
            threshold=self.threshold,
        )


def default_state(dataset: int, series: TimeSeries) -> ViewState:
    n = series.n_steps
    width = min(n, 10)
    t0 = (n - width) // 2
    return ViewState(dataset=dataset, window=(t0, t0 + width, 1))


def merge(state: ViewState, msg: dict, n_steps: int) -> ViewState:
    """`state` with the fields of a validated update message applied; raises ChronoclError
    (nothing applied) when the combination does not fit the data set."""
    changes: dict = {}
    if "camera" in msg:
        cam = dataclasses.asdict(state.camera) | msg["camera"]
        changes["camera"] = Camera(**cam)
    if "views" in msg:
        changes["views"] = tuple((v["mode"], v.get("order", "forward")) for v in msg["views"])
    if "window" in msg:
        w = msg["window"]
        window = (w["t0"], w["t1"], w.get("stride", 1))
        Selection.window(*window, n_steps)  # validates
        changes["window"] = window
    if "data_tf" in msg:
        d = msg["data_tf"]
        vr = d.get("value_range")
        changes["data_tf"] = DataTF(points=d["points"], value_range=tuple(vr) if vr else None)
    if "time_tf" in msg:
        changes["time_tf"] = state.time_tf | msg["time_tf"]
    if "enhance" in msg:
        e = msg["enhance"]
        kind = e.get("kind", state.enhance["kind"])
        base = state.enhance if kind == state.enhance["kind"] else {"k0": None, "k1": None}
        changes["enhance"] = {"k0": None, "k1": None, "k2": None} | base | e | {"kind": kind}
    if "threshold" in msg:
        changes["threshold"] = msg["threshold"]
    if "clip" in msg:
        c = msg["clip"]
        if c is not None:
            n = c["normal"]
            if not any(abs(v) > 1e-6 for v in n):
                raise InvalidParameterError("clip.normal is (0, 0, 0); give a direction")
            c = (n[0], n[1], n[2], c.get("offset", 0.0))
        changes["clip"] = c
    for key in ("quality", "background", "outline"):
        if key in msg:
            changes[key] = msg[key]
    if "size" in msg:
        changes["size"] = tuple(msg["size"])
    new = dataclasses.replace(state, **changes)
    new.time_tf_object()  # validates
    if "enhance" in msg:
        new.spec(0)  # validates the enhancement parameters
    return new


# --------------------------------------------------------------------------- views


@dataclass
class ViewSlot:
    """One panel: its session (window + spec), current chronovolume and texture."""

    session: Session | None = None
    cv: Chronovolume | None = None
    volume: Volume | None = None
    uploaded: Chronovolume | None = None

    def release_gl(self) -> None:
        if self.volume is not None:
            self.volume.release()
            self.volume = None
            self.uploaded = None

    def drop_session(self) -> None:
        if self.session is not None:
            self.session.close()
        self.session, self.cv = None, None


def upload(rc, slot: ViewSlot, cv: Chronovolume) -> Volume:
    """The chronovolume as a 3D texture, rewriting the slot's texture in place when its shape
    and type are unchanged (allocating a new 3D texture costs more than the write).

    Volumes up to `FLOAT_TEXTURE_VOXELS` go up as float32: no conversion on the host, and
    llvmpipe samples them about twice as fast as half floats; larger ones as half floats.
    """
    import moderngl

    nz, ny, nx, _ = cv.rgba.shape
    if nz * ny * nx <= FLOAT_TEXTURE_VOXELS:
        dtype, data = "f4", np.ascontiguousarray(cv.rgba, dtype=np.float32)
    else:
        dtype, data = "f2", cv.rgba.astype(np.float16)
    vol = slot.volume
    if vol is not None and vol.texture.size == (nx, ny, nz) and vol.texture.dtype == dtype:
        vol.texture.write(data)
    else:
        slot.release_gl()
        tex = rc.ctx.texture3d((nx, ny, nz), 4, data, dtype=dtype)
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        vol = Volume(tex, np.zeros(3), 0.0, (np.zeros(3), np.zeros(3)))
    extent, voxel = geometry(cv)
    vol.extent, vol.unit = extent, float(np.min(voxel))
    vol.occupied = occupied_box(cv.rgba[..., 3], extent, voxel)
    slot.volume, slot.uploaded = vol, cv
    return vol


def geometry(cv: Chronovolume) -> tuple[np.ndarray, np.ndarray]:
    """World extent (x, y, z; longest side 1) and voxel size, as the raycaster lays them out."""
    nz, ny, nx = cv.shape
    dz, dy, dx = cv.spacing
    physical = np.array([nx * dx, ny * dy, nz * dz], dtype=np.float64)
    extent = physical / physical.max()
    return extent, extent / np.array([nx, ny, nz])


def probe_ray(
    cv: Chronovolume,
    camera: Camera,
    size: tuple[int, int],
    x: float,
    y: float,
    clip: tuple[float, float, float, float] | None = None,
    threshold: float = 0.5,
) -> dict:
    """March the ray through pixel (x, y) (fractions of the panel, top-left origin) over the
    chronovolume's opacity on the CPU, with the raycaster's camera, box and compositing.

    Returns {"voxel": (z, y, x) or None, "opacity": accumulated opacity there,
    "reached": whether the accumulated opacity passed `threshold`}. When it never does, the
    voxel of the largest opacity increment is returned (None if the ray sees nothing).
    """
    extent, voxel = geometry(cv)
    w, h = size
    view, proj = camera.matrices(extent, w / h)
    inv = np.linalg.inv(proj @ view)
    ndc = np.array([2.0 * x - 1.0, 1.0 - 2.0 * y])
    near = inv @ np.array([ndc[0], ndc[1], -1.0, 1.0])
    far = inv @ np.array([ndc[0], ndc[1], 1.0, 1.0])
    origin = near[:3] / near[3]
    direction = far[:3] / far[3] - origin
    direction /= np.linalg.norm(direction)
    half = extent / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (-half - origin) / direction
        t1 = (half - origin) / direction
    t_enter = max(float(np.nanmax(np.minimum(t0, t1))), 0.0)
    t_exit = float(np.nanmin(np.maximum(t0, t1)))
    if clip is not None:
        *n, d = clip_plane(clip, extent)
        denom = float(np.dot(n, direction))
        side = float(np.dot(n, origin)) + d
        if abs(denom) < 1e-12:
            if side < 0:
                t_exit = -1.0
        else:
            t_plane = -side / denom
            if denom > 0:
                t_enter = max(t_enter, t_plane)
            else:
                t_exit = min(t_exit, t_plane)
    none = {"voxel": None, "opacity": 0.0, "reached": False}
    if not t_exit > t_enter:
        return none
    step = float(np.min(voxel)) / 2
    t = t_enter + (np.arange(int((t_exit - t_enter) / step) + 1) + 0.5) * step
    t = t[t < t_exit]
    if t.size == 0:
        return none
    points = origin + t[:, None] * direction
    n_xyz = np.array(cv.shape[::-1])
    idx = np.clip(np.floor((points + half) / extent * n_xyz).astype(int), 0, n_xyz - 1)
    a = cv.rgba[idx[:, 2], idx[:, 1], idx[:, 0], 3].astype(np.float64)
    a = 1.0 - np.power(np.clip(1.0 - a, 0.0, 1.0), 0.5)  # half-voxel steps
    transmitted = np.cumprod(1.0 - a)
    acc = 1.0 - transmitted
    passed = np.flatnonzero(acc >= threshold)
    if passed.size:
        k, reached = int(passed[0]), True
    else:
        gained = a * np.concatenate([[1.0], transmitted[:-1]])
        if not (gained > 0).any():
            return none
        k, reached = int(np.argmax(gained)), False
    ix, iy, iz = (int(v) for v in idx[k])
    return {"voxel": (iz, iy, ix), "opacity": float(acc[k]), "reached": reached}


# --------------------------------------------------------------------------- the worker


class Downloads:
    """Files prepared for download (a saved image or chronovolume), by random key."""

    MAX = 16

    def __init__(self) -> None:
        import secrets

        self._secrets = secrets
        self.dir = Path(tempfile.mkdtemp(prefix="chronocl-viewer-"))
        self._items: dict[str, tuple[Path, str, str]] = {}
        self._lock = threading.Lock()

    def add(self, data: bytes | Path, filename: str, media_type: str) -> str:
        key = self._secrets.token_urlsafe(16)
        path = self.dir / key
        if isinstance(data, Path):
            data.replace(path)
        else:
            path.write_bytes(data)
        with self._lock:
            self._items[key] = (path, filename, media_type)
            while len(self._items) > self.MAX:
                old = next(iter(self._items))
                self._items.pop(old)[0].unlink(missing_ok=True)
        return key

    def get(self, key: str) -> tuple[Path, str, str] | None:
        with self._lock:
            return self._items.get(key)

    def close(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)


class ClientWorker:
    """The render thread of one client. `send(data)` delivers a text (str) or binary (bytes)
    message to the client and returns False once the client is gone."""

    def __init__(
        self,
        datasets: list[Dataset],
        send: Callable[[str | bytes], bool],
        downloads: Downloads,
        *,
        engine: str = "opencl",
        device: str | None = None,
        memory: str | int | None = None,
    ) -> None:
        self.datasets = datasets
        self.send = send
        self.downloads = downloads
        self.engine, self.device, self.memory = engine, device, memory
        self.state = default_state(0, datasets[0].series)
        self._cond = threading.Condition()
        self._pending: tuple[ViewState, int | None] | None = None
        self._tasks: deque[tuple[str, dict]] = deque()
        self._closed = False
        self._slots: list[ViewSlot] = []
        self._slots_dataset = -1
        # The views show one window of one data set: their sessions share its resident steps.
        self._manager: WindowManager | None = None
        self._shown: ViewState | None = None  # the state of the last frame sent
        self._frame = 0
        self.thread = threading.Thread(target=self._run, name="chronocl-view", daemon=True)
        self.thread.start()

    # -- called from the server's event loop ----------------------------------------------
    def find_dataset(self, ref: int | str) -> int:
        if isinstance(ref, int):
            if ref < len(self.datasets):
                return ref
        else:
            for i, d in enumerate(self.datasets):
                if d.name == ref:
                    return i
        names = ", ".join(f"{i}: {d.name}" for i, d in enumerate(self.datasets))
        raise UnknownNameError(f"unknown data set {ref!r}; choose one of {names}")

    def open(self, ref: int | str, rid: int | None) -> dict:
        i = self.find_dataset(ref)
        with self._cond:
            self.state = default_state(i, self.datasets[i].series)
            self._pending = (self.state, rid)
            self._tasks.append(("histogram", {"id": rid, "range": [0.0, 1.0]}))
            self._cond.notify()
        return self.datasets[i].info(i) | {"state": describe_state(self.state)}

    def update(self, msg: dict) -> None:
        with self._cond:
            n = self.datasets[self.state.dataset].series.n_steps
            self.state = merge(self.state, msg, n)
            self._pending = (self.state, msg.get("id"))
            self._cond.notify()

    def task(self, kind: str, msg: dict) -> None:
        with self._cond:
            if len(self._tasks) >= MAX_TASKS:
                raise InvalidParameterError(
                    f"{MAX_TASKS} requests are already waiting; wait for their replies"
                )
            self._tasks.append((kind, msg))
            self._cond.notify()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()

    # -- the thread ----------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # nothing of the thread's end may print a traceback
            error_text(exc, "in a client's render thread")
        finally:
            try:
                self._release()
            except Exception as exc:
                error_text(exc, "releasing a client's views")

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._closed and self._pending is None and not self._tasks:
                    self._cond.wait()
                if self._closed:
                    return
                pending, self._pending = self._pending, None
                task = None if pending is not None else self._tasks.popleft()
            try:
                if pending is not None:
                    self._render(*pending)
                else:
                    self._do_task(*task)  # type: ignore[misc]
            except Exception as exc:  # reported to the client; the worker keeps serving
                rid = pending[1] if pending is not None else task[1].get("id")  # type: ignore[index]
                text = error_text(exc, "making the frame" if pending else f"on {task[0]}")  # type: ignore[index]
                if not self._reply({"type": "error", "id": rid, "message": text}):
                    return

    def _reply(self, obj: dict) -> bool:
        import json

        return self.send(json.dumps(obj))

    def _release(self) -> None:
        slots, self._slots = self._slots, []
        if any(s.volume is not None for s in slots):
            on_gl(lambda rc: [s.release_gl() for s in slots])
        for s in slots:
            s.drop_session()
        self._close_manager()

    def _close_manager(self) -> None:
        if self._manager is not None:
            self._manager.close()
            self._manager = None

    def _chronovolumes(self, state: ViewState) -> tuple[list[Chronovolume], float, bool]:
        """The views' chronovolumes for `state`, integrating only where something changed."""
        series = self.datasets[state.dataset].series
        if self._slots_dataset != state.dataset:
            for s in self._slots:
                s.drop_session()
            self._close_manager()
            self._slots_dataset = state.dataset
        if self._manager is None:
            self._manager = WindowManager(series, self.memory)
        while len(self._slots) < len(state.views):
            self._slots.append(ViewSlot())
        sel = state.selection(series.n_steps)
        integrate_ms, incremental = 0.0, False
        cvs = []
        for i in range(len(state.views)):
            slot = self._slots[i]
            spec = state.spec(i)
            if (
                state.quality == "preview"
                and spec.enhance.kind == "silhouette"
                and slot.session is not None
                and slot.cv is not None
            ):
                # Silhouettes follow the camera; while dragging keep the last ones.
                old = slot.session.spec
                spec = dataclasses.replace(spec, enhance=old.enhance)
            with INTEGRATE_LOCK:
                cv, ms, inc = self._integrate(slot, series, spec, sel)
            integrate_ms += ms
            incremental = incremental or inc
            cvs.append(cv)
        for slot in self._slots[len(state.views) :]:
            slot.drop_session()
        return cvs, integrate_ms, incremental

    def _integrate(self, slot: ViewSlot, series, spec, sel) -> tuple[Chronovolume, float, bool]:
        s = slot.session
        if s is not None and slot.cv is not None and s.spec == spec and s.selection == sel:
            return slot.cv, 0.0, False
        if s is None or (s.spec != spec and s.selection != sel):
            if s is not None:
                s.close()
            s = slot.session = Session(
                series,
                memory=self.memory,
                engine=self.engine,
                device=self.device,
                spec=spec,
                manager=self._manager,
            )
            cv = s.set_window(sel)
        elif s.spec != spec:
            cv = s.set_spec(spec)
        else:
            cv = s.set_window(sel)  # the session slides where the new window overlaps the old
        slot.cv = cv
        stats = s.stats or {}
        return cv, float(stats.get("integrate_ms", 0.0)), bool(stats.get("incremental", False))

    def _draw(self, rc, cvs, state: ViewState, size, bg) -> tuple[list, float, float, float]:
        """Upload what changed and draw every view (on the GL thread)."""
        t_up = time.perf_counter()
        for slot, cv in zip(self._slots, cvs, strict=False):
            if slot.uploaded is not cv:
                upload(rc, slot, cv)
        t_draw = time.perf_counter()
        panels = [
            rc.draw(
                slot.volume,
                state.camera,
                size,
                background=bg,
                clip=state.clip,
                step=1.0,
                outline=state.outline,
            )
            for slot in self._slots[: len(cvs)]
        ]
        for slot in self._slots[len(cvs) :]:
            slot.release_gl()
        return panels, t_up, t_draw, time.perf_counter()

    def _render(self, state: ViewState, rid: int | None) -> None:
        from chronocl.render.views import parse_color

        t_start = time.perf_counter()
        cvs, integrate_ms, incremental = self._chronovolumes(state)
        preview = state.quality == "preview"
        w, h = state.size
        if preview:
            w, h = max(32, int(w * PREVIEW_SCALE)), max(32, int(h * PREVIEW_SCALE))
        bg = parse_color(state.background)
        t0 = time.perf_counter()
        panels, t_up, t_draw, t_done = on_gl(self._draw, cvs, state, (w, h), bg)
        images = [encode(p, JPEG_QUALITY[state.quality]) for p in panels]
        t_enc = time.perf_counter()
        self._frame += 1
        self._shown = state
        header = {
            "type": "frame",
            "id": rid,
            "seq": self._frame,
            "quality": state.quality,
            "format": "jpeg",
            "views": [
                {"width": w, "height": h, "bytes": len(b), "label": describe(cv)}
                for b, cv in zip(images, cvs, strict=True)
            ],
            "legend": legend(cvs[0]),
            "timings": {
                "integrate_ms": round(integrate_ms, 2),
                "incremental": incremental,
                "upload_ms": round(1e3 * (t_draw - t_up), 2),
                "render_ms": round(1e3 * (t_done - t_draw), 2),
                "gl_wait_ms": round(1e3 * (t_up - t0), 2),
                "encode_ms": round(1e3 * (t_enc - t_done), 2),
                "server_ms": round(1e3 * (t_enc - t_start), 2),
            },
            "sent_at": time.time(),
        }
        self.send(pack_frame(header, images))

    # -- tasks ---------------------------------------------------------------------------
    def _do_task(self, kind: str, msg: dict) -> None:
        rid = msg.get("id")
        ds = self.datasets[self.state.dataset]
        if kind == "histogram":
            lo, hi = msg["range"]
            self._reply({"type": "histogram", "id": rid, **ds.histogram(lo, hi)})
        elif kind == "probe":
            self._probe(msg)
        elif kind == "save":
            self._save(msg)

    def _shown_view(self, msg: dict) -> tuple[ViewState, int]:
        state = self._shown
        view = msg.get("view", 0)
        if state is None or view >= len(state.views) or view >= len(self._slots):
            raise InvalidParameterError(f"view {view} is not shown; choose a view on the page")
        return state, view

    def _probe(self, msg: dict) -> None:
        state, view = self._shown_view(msg)
        cv = self._slots[view].cv
        assert cv is not None
        hit = probe_ray(cv, state.camera, state.size, msg["x"], msg["y"], state.clip)
        ds = self.datasets[state.dataset]
        reply = {"type": "probe", "id": msg.get("id"), "view": view, "x": msg["x"], "y": msg["y"]}
        reply |= {"reached": hit["reached"], "opacity": round(hit["opacity"], 4)}
        if hit["voxel"] is None:
            reply |= {"voxel": None, "values": None}
        else:
            z, y, x = hit["voxel"]
            reply |= {"voxel": {"z": z, "y": y, "x": x}, "values": ds.curve(z, y, x)}
        reply["window"] = list(state.selection(ds.series.n_steps).steps)
        self._reply(reply)

    def _save(self, msg: dict) -> None:
        from chronocl.render.image import Image
        from chronocl.render.views import compose_panels, parse_color

        state, view = self._shown_view(msg)
        ds = self.datasets[state.dataset]
        sel = state.selection(ds.series.n_steps).describe().replace(":", "-")
        if msg["what"] == "image":
            cvs = [s.cv for s in self._slots[: len(state.views)]]
            bg = parse_color(state.background)
            panels, *_ = on_gl(self._draw, cvs, state, state.size, bg)
            labels = [describe(cv) for cv in cvs]  # type: ignore[arg-type]
            image = Image(compose_panels(panels, labels, cvs, None, bg))
            name = f"{ds.name}-{sel}.png"
            key = self.downloads.add(image.png_bytes(), name, "image/png")
        else:
            cv = self._slots[view].cv
            assert cv is not None
            mode = state.views[view][0]
            name = f"{ds.name}-{mode}-{sel}.zarr.zip"
            with tempfile.TemporaryDirectory(dir=self.downloads.dir) as tmp:
                store = cv.save(Path(tmp) / "chronovolume.zarr")
                archive = Path(tmp) / "chronovolume.zip"
                zip_store(store, archive)
                key = self.downloads.add(archive, name, "application/zip")
        self._reply(
            {"type": "download", "id": msg.get("id"), "url": f"/download/{key}", "filename": name}
        )


def zip_store(store: Path, archive: Path) -> None:
    """A zarr directory store as a zip whose root is the store's root (zarr's ZipStore reads it)."""
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_STORED) as zf:
        for path in sorted(store.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(store).as_posix())


def encode(pixels: np.ndarray, quality: int) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(pixels).save(buf, format="JPEG", quality=quality)
    return buf.getvalue()


def legend(cv: Chronovolume) -> list[dict]:
    """Each selected step's time colour and opacity (the timeline colours its ticks by them)."""
    spec = cv.spec
    steps = cv.steps
    n = cv.metadata["selection"]["n_steps"]
    rgb, alpha = spec.time_tf.evaluate(spec.time_tf.positions_of(steps, n))
    return [
        {
            "step": int(s),
            "rgb": [round(float(c), 3) for c in rgb[k]],
            "a": round(float(alpha[k]), 3),
        }
        for k, s in enumerate(steps)
    ]


def describe_state(state: ViewState) -> dict:
    """The state in the protocol's terms (the page starts from it)."""
    cam = state.camera
    e = state.enhance
    spec = state.spec(0)
    return {
        "camera": {
            "azimuth": cam.azimuth,
            "elevation": cam.elevation,
            "zoom": cam.zoom,
            "fov": cam.fov,
            "projection": cam.projection,
        },
        "views": [{"mode": m, "order": o} for m, o in state.views],
        "window": dict(zip(("t0", "t1", "stride"), state.window, strict=True)),
        "data_tf": {"points": [list(p) for p in state.data_tf.points]},
        "time_tf": dict(state.time_tf),
        "enhance": {
            "kind": e["kind"],
            "k0": spec.enhance.k0,
            "k1": spec.enhance.k1,
            "k2": spec.enhance.k2,
        },
        "threshold": state.threshold,
        "clip": None
        if state.clip is None
        else {"normal": list(state.clip[:3]), "offset": state.clip[3]},
        "size": list(state.size),
        "background": state.background,
        "outline": state.outline,
    }
