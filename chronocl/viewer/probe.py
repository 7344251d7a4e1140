"""The probe: which voxel a click on a panel meets, and the reply that plots v(t) there.

The ray through the clicked pixel is marched on the CPU over the shown chronovolume's
opacity, with the raycaster's camera, box, clip plane and compositing, to the voxel where the
accumulated opacity passes `PROBE_THRESHOLD`. `project` puts that voxel back on screen for
each later frame, so the page's marker follows it through orbits and projection changes.
"""

from __future__ import annotations

import numpy as np

from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import Camera, to_panel, world_extent, world_geometry
from chronocl.render.raycaster import clip_plane
from chronocl.render.slices import parse_slice
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.protocol import PROBE_THRESHOLD
from chronocl.viewer.schema import ProtocolError
from chronocl.viewer.slicing import point_voxel
from chronocl.viewer.view_state import ViewState


def probe_ray(
    cv: Chronovolume,
    camera: Camera,
    size: tuple[int, int],
    x: float,
    y: float,
    clip: tuple[float, float, float, float] | None = None,
    threshold: float = PROBE_THRESHOLD,
) -> dict:
    """March the ray through pixel (x, y) (fractions of the panel, top-left origin) over the
    chronovolume's opacity on the CPU, with the raycaster's camera, box and compositing.

    Returns {"voxel": (x, y, z) voxel indices or None, "opacity": accumulated opacity there,
    "reached": whether the accumulated opacity passed `threshold`}. When it never does, the
    voxel of the largest opacity increment is returned (None if the ray sees nothing).
    """
    extent, voxel = world_geometry(cv.shape, cv.spacing)
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
    if cv.rgba.dtype == np.uint8:  # a display chronovolume (RGBA8)
        a /= 255.0
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
    return {"voxel": tuple(int(v) for v in idx[k]), "opacity": float(acc[k]), "reached": reached}


def project(
    cv: Chronovolume, camera: Camera, size: tuple[int, int], where: tuple[float, float, float]
) -> tuple[float, float] | None:
    """Where the point at `where` (x, y, z as fractions of the box) lands on a panel of `size`
    with `camera`: (x, y) fractions, top-left origin; None if behind the camera or off-panel."""
    extent = world_extent(cv.shape, cv.spacing)
    world = (np.asarray(where, dtype=np.float64) - 0.5) * extent
    at = to_panel(camera, extent, size, world[None])
    if at is None:
        return None
    x, y = at[0]
    if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
        return None
    return round(float(x), 5), round(float(y), 5)


def box_fractions(
    cv: Chronovolume, voxel: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The centre of voxel (x, y, z) of `cv` (a fractional index: between voxels) as x, y, z
    fractions of its box."""
    return tuple((v + 0.5) / n for v, n in zip(voxel, cv.dims, strict=True))  # type: ignore[return-value]


BOX_RAYS = 12  # rays along each side of a dragged rectangle (at most one per pixel)


def _rectangle_rays(msg: dict, size: tuple[int, int]) -> list[tuple[float, float]]:
    """Pixel fractions of a grid of rays over the rectangle from (x, y) to (x2, y2), its
    corners and edges included."""
    (x0, x1), (y0, y1) = sorted((msg["x"], msg["x2"])), sorted((msg["y"], msg["y2"]))
    nx = max(2, min(BOX_RAYS, round((x1 - x0) * size[0]) + 1))
    ny = max(2, min(BOX_RAYS, round((y1 - y0) * size[1]) + 1))
    return [(x, y) for y in np.linspace(y0, y1, ny) for x in np.linspace(x0, x1, nx)]


def probe_reply(msg: dict, view: int, state: ViewState, cv: Chronovolume, ds: Dataset) -> dict:
    """The `probe` reply to `msg` for the shown `view` of `state`: the voxel met and v(t) there
    over every step, or with a second corner (x2, y2) the box spanned by the voxels the two
    rays meet and its mean, min and max per step; the window's steps, and the curve as CSV.

    The box is the smallest one holding every voxel that the rays through the dragged
    rectangle meet (a grid of up to BOX_RAYS x BOX_RAYS rays), so a box drawn around a feature
    from empty space probes the feature; only a rectangle whose rays all miss is refused.
    """
    camera = state.panel_camera(view)  # its own camera where it has one
    pixel, pinned = {"x", "y", "x2", "y2"} & set(msg), {"slice", "u", "v"} & set(msg)
    if pinned == {"slice", "u", "v"} and not pixel:
        return _pinned_reply(msg, view, state, cv, ds, camera)
    if pinned or not {"x", "y"} <= pixel or len(pixel) == 3:
        raise ProtocolError(
            "probe takes a view's pixel (x, y; a box: x2, y2 too) or a slice and its point "
            "(slice, u, v), one of them"
        )
    box_drag = "x2" in msg and "y2" in msg
    rays = _rectangle_rays(msg, state.size) if box_drag else [(msg["x"], msg["y"])]
    hits = [probe_ray(cv, camera, state.size, x, y, state.clip) for x, y in rays]
    reply = {"type": "probe", "id": msg.get("id"), "view": view, "x": msg["x"], "y": msg["y"]}
    if box_drag:
        reply |= {"x2": msg["x2"], "y2": msg["y2"]}
        hits = [h for h in hits if h["voxel"] is not None] or hits[:1]  # the rays that met one
    reply |= {"reached": all(h["reached"] for h in hits)}
    reply["opacity"] = round(min(h["opacity"] for h in hits), 4)
    reply["threshold"] = PROBE_THRESHOLD
    window = list(state.selection(ds.series.n_steps, view).steps)
    reply["window"] = window
    empty = {"voxel": None, "box": None, "values": None, "min": None, "max": None, "csv": None}
    if any(h["voxel"] is None for h in hits):
        return reply | empty
    voxels = np.array([h["voxel"] for h in hits])  # (x, y, z) per ray
    lo, hi = voxels.min(axis=0), voxels.max(axis=0) + 1
    if not box_drag:
        x, y, z = hits[0]["voxel"]
        curve = ds.curve((x, y, z))
        reply |= {"voxel": {"x": x, "y": y, "z": z}, "box": None}
    else:
        box = tuple((int(a), int(b)) for a, b in zip(lo, hi, strict=True))  # x, y, z ranges
        curve = ds.curve(box=box)
        reply |= {"voxel": None, "box": {a: list(r) for a, r in zip("xyz", box, strict=True)}}
    centre = tuple(float(v) for v in (lo + hi - 1) / 2)
    reply["values"] = [float(v) for v in curve.values]
    reply["min"] = None if curve.min is None else [float(v) for v in curve.min]
    reply["max"] = None if curve.max is None else [float(v) for v in curve.max]
    reply["csv"] = curve.csv_text(window)
    reply["mark"] = project(cv, camera, state.size, box_fractions(cv, centre))
    reply["where"] = box_fractions(cv, centre)
    return reply


def _pinned_reply(msg: dict, view: int, state: ViewState, cv: Chronovolume, ds: Dataset, camera):
    """The `probe` reply pinned on a slice: v(t) at the voxel under (`u`, `v`) of the slice's
    grid (the one its read-out names), and where it lies on the view (`x`, `y`: None where
    off the picture)."""
    voxel = point_voxel(msg, parse_slice(msg["slice"], cv.shape), cv.shape)
    where = box_fractions(cv, voxel)
    mark = project(cv, camera, state.size, where)
    window = list(state.selection(ds.series.n_steps, view).steps)
    at = dict(zip("xyz", voxel, strict=True))
    reply = pinned_reply(view, at, None, ds.curve(voxel), window, mark, "slice")
    return reply | {"id": msg.get("id"), "where": where}


def pinned_reply(view: int, voxel, box, curve, window: list, mark, by: str) -> dict:
    """The `probe` reply for a probe pinned at a voxel ({x, y, z}) or a box ({x: [x0, x1],
    ...}) rather than met by a ray (`by`: "slice", a click on the slice; "code", the notebook
    widget's `probe`): `curve` (`Dataset.curve`'s) there, `window` its view's steps, `mark`
    where it lies on the view (`x`, `y` too: None where off the picture)."""
    x, y = mark if mark is not None else (None, None)
    return {
        "type": "probe",
        "id": None,
        "view": view,
        "x": x,
        "y": y,
        "reached": True,
        "opacity": None,
        "threshold": PROBE_THRESHOLD,
        "window": window,
        "voxel": voxel,
        "box": box,
        "values": [float(t) for t in curve.values],
        "min": None if curve.min is None else [float(t) for t in curve.min],
        "max": None if curve.max is None else [float(t) for t in curve.max],
        "csv": curve.csv_text(window),
        "mark": mark,
        "pinned": by,
    }
