"""A client's desired view state: one immutable snapshot of everything a frame depends on
(data set, camera, views, window, transfer functions, enhancement, clip plane, size, ...),
how a validated update message is merged into it, and how it is described back to the page."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from chronocl import modes
from chronocl.core.enhance import Enhance
from chronocl.core.errors import ChronoclError, InvalidParameterError
from chronocl.core.selection import Selection
from chronocl.core.tf import GLOBAL, DataTF, TimeAlpha, TimeColor, TimeTF
from chronocl.data.series import TimeSeries
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.camera import Camera
from chronocl.render.shading import OFF, Shading
from chronocl.viewer.protocol import ORDERS

# A data TF sent without a value range normalises by the series' recorded range, the axis the
# TF editor, histogram and probe plots are drawn over; a fitted TF carries its range (lo, hi)
# (chronocl/viewer/fit.py; a data set opens fitted, as the CLI fits; docs/display.md).
VIEWER_RANGE = GLOBAL


@dataclass(frozen=True)
class ViewState:
    """Everything a frame depends on (one immutable snapshot per request)."""

    dataset: int = 0
    camera: Camera = field(default_factory=lambda: Camera(azimuth=30.0, elevation=20.0, zoom=1.2))
    # One view of the first registered mode.
    views: tuple[tuple[str, str], ...] = field(
        default_factory=lambda: ((modes.names()[0], ORDERS[0]),)
    )
    window: tuple[int, int, int] = (0, 1, 1)
    # Each view's own window (t0, t1, stride), or None where it follows `window` (linked);
    # as long as `views` or shorter (views past its end are linked).
    view_windows: tuple[tuple[int, int, int] | None, ...] = ()
    # Each view's own camera, data TF and time TF, or None where it follows the shared one
    # (linked), as `view_windows`: two viewpoints or two colourings side by side. An own
    # camera frames what the shared one frames (its `focus` is the shared camera's).
    view_cameras: tuple[Camera | None, ...] = ()
    view_data_tfs: tuple[DataTF | None, ...] = ()
    view_time_tfs: tuple[dict | None, ...] = ()
    data_tf: DataTF = field(default_factory=lambda: DataTF(value_range=VIEWER_RANGE))
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
    shading: Shading = OFF  # lighting; off by default (llvmpipe draws a lit frame 3-7x slower)

    def selection(self, n_steps: int, view: int | None = None) -> Selection:
        """The steps of the shared window, or of `view`'s own window where it has one."""
        t0, t1, stride = self.own_window(view) or self.window
        return Selection.window(t0, t1, stride, n_steps)

    def own_window(self, view: int | None) -> tuple[int, int, int] | None:
        """`view`'s own window, None where it is linked to the shared one."""
        return _own(self.view_windows, view)

    def camera_of(self, view: int | None = None) -> Camera:
        """The camera `view` is drawn with: its own (framing the shared camera's focus), else
        the shared one."""
        own = _own(self.view_cameras, view)
        return self.camera if own is None else dataclasses.replace(own, focus=self.camera.focus)

    def data_tf_of(self, view: int | None = None) -> DataTF:
        """`view`'s own data TF, else the shared one."""
        own = _own(self.view_data_tfs, view)
        return self.data_tf if own is None else own

    def time_tf_of(self, view: int | None = None) -> dict:
        """`view`'s own time TF (the page's fields), else the shared one."""
        own = _own(self.view_time_tfs, view)
        return self.time_tf if own is None else own

    def panel_camera(self, view: int | None = None) -> Camera:
        """`view`'s camera (none: the shared one) as the panels are drawn: on a panel taller
        than wide the camera's field of view spans the panel's width instead of its height
        (zoom scaled by w / h), so the box fits across a tall panel as it fits down a wide one."""
        camera = self.camera_of(view)
        w, h = self.size
        if w >= h:
            return camera
        return dataclasses.replace(camera, zoom=camera.zoom * w / h)

    def time_tf_object(self, view: int | None = None) -> TimeTF:
        t = self.time_tf_of(view)
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

    def spec(self, view: int):
        mode, order = self.views[view]
        e = self.enhance
        kwargs = {k: e[k] for k in ("k0", "k1", "k2") if e.get(k) is not None}
        if e["kind"] == "silhouette":
            kwargs["view"] = self.camera_of(view).view_direction()
        return IntegrationSpec(
            mode=mode,
            order=order,
            data_tf=self.data_tf_of(view),
            time_tf=self.time_tf_object(view),
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
    if "window" in msg:
        w = msg["window"]
        window = (w["t0"], w["t1"], w.get("stride", 1))
        Selection.window(*window, n_steps)  # validates
        changes["window"] = window
    if "data_tf" in msg:
        changes["data_tf"] = _data_tf(msg["data_tf"])
    if "time_tf" in msg:
        changes["time_tf"] = state.time_tf | msg["time_tf"]
    if "views" in msg:  # after the shared camera and TFs: an own one given in part takes theirs
        changes |= _views(
            msg["views"],
            changes.get("camera", state.camera),
            changes.get("time_tf", state.time_tf),
            n_steps,
        )
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
    if "shading" in msg:  # any subset of the fields; the rest as they were
        changes["shading"] = Shading.from_dict(state.shading.to_dict() | msg["shading"])
    new = dataclasses.replace(state, **changes)
    new.time_tf_object()  # validates
    for view in range(len(new.view_time_tfs)):
        new.time_tf_object(view)  # each view's own
    if "enhance" in msg:
        new.spec(0)  # validates the enhancement parameters
    return new


def _views(views: list[dict], camera: Camera, time_tf: dict, n_steps: int) -> dict:
    """The `views` of an update: modes and orders, and each view's own window, camera, data TF
    and time TF (None where it is linked); an own camera or time TF given in part takes the
    rest from the shared `camera` or `time_tf`."""
    windows, cameras, data_tfs, time_tfs = [], [], [], []
    for i, v in enumerate(views):
        w = v.get("window")
        if w is not None:
            w = (w["t0"], w["t1"], w.get("stride", 1))
            try:
                Selection.window(*w, n_steps)
            except ChronoclError as exc:
                raise type(exc)(f"view {i + 1}'s own window: {exc}") from None
        windows.append(w)
        c = v.get("camera")
        own = None if c is None else dataclasses.asdict(camera) | c | {"focus": None}
        cameras.append(None if own is None else Camera(**own))  # (it frames the shared focus)
        d = v.get("data_tf")
        data_tfs.append(None if d is None else _data_tf(d))
        t = v.get("time_tf")
        time_tfs.append(None if t is None else time_tf | t)
    return {
        "views": tuple((v["mode"], v.get("order", ORDERS[0])) for v in views),
        "view_windows": tuple(windows),
        "view_cameras": tuple(cameras),
        "view_data_tfs": tuple(data_tfs),
        "view_time_tfs": tuple(time_tfs),
    }


def _data_tf(d: dict) -> DataTF:
    vr = d.get("value_range")
    return DataTF(points=d["points"], value_range=tuple(vr) if vr else VIEWER_RANGE)


def describe_state(state: ViewState) -> dict:
    """The state in the protocol's terms (the page starts from it)."""
    e = state.enhance
    spec = state.spec(0)
    return {
        "camera": _camera_dict(state.camera),
        "views": [
            {
                "mode": m,
                "order": o,
                "window": _window_dict(state.own_window(i)),
                "camera": _maybe(_camera_dict, _own(state.view_cameras, i)),
                "data_tf": _maybe(_data_tf_dict, _own(state.view_data_tfs, i)),
                "time_tf": _maybe(dict, _own(state.view_time_tfs, i)),
            }
            for i, (m, o) in enumerate(state.views)
        ],
        "window": dict(zip(("t0", "t1", "stride"), state.window, strict=True)),
        "data_tf": _data_tf_dict(state.data_tf),
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
        "shading": state.shading.to_dict(),
    }


def _own(items: tuple, view: int | None):
    """`items[view]`: a view's own window, camera or TF; None where it has none (linked)."""
    return None if view is None or view >= len(items) else items[view]


def _maybe(describe, value):
    return None if value is None else describe(value)


def _camera_dict(cam: Camera) -> dict:
    return {
        "azimuth": cam.azimuth,
        "elevation": cam.elevation,
        "zoom": cam.zoom,
        "fov": cam.fov,
        "projection": cam.projection,
        "up": cam.up,
    }


def _data_tf_dict(data_tf: DataTF) -> dict:
    """Points, and the value range where one is given (a fitted TF's); none: the series'."""
    vr = data_tf.value_range
    d: dict = {"points": [list(p) for p in data_tf.points]}
    return d | {"value_range": list(vr)} if isinstance(vr, tuple) else d


def _window_dict(window: tuple[int, int, int] | None) -> dict | None:
    return None if window is None else dict(zip(("t0", "t1", "stride"), window, strict=True))
