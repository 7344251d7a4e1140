"""The box's axes on a panel, as ParaView's cube axes: with the box outline on, three of its
edges (one along x, one along y, one along z) carry ticks at 1-2-5 values of the data's
coordinates and the axis' name, projected with the panel's camera so the page draws them over
the picture (views.js `showAxes`) and the saved PNG carries them (`draw_axes`).

Coordinates: voxel i's centre lies at i times the series' (level 0's) spacing along its axis,
so an axis' ticks run over 0 .. (n - 1) * spacing, where the probe puts the voxels
(`probe.box_fractions`); a coarse level keeps level 0's box, so its ticks are the same.

With a clip plane the box is the one around the part the plane keeps (`visible_bounds`: the
kept half exactly for a plane along an axis, as the bounds of ParaView's Clip output), and an
edge of it is labelled only over its part on the kept side, so no tick sits where the plane has
cut the box away; a plane that keeps nothing leaves no axes.

Which edges: of the four edges along an axis, those on the projected box's outline (one of the
edge's two faces towards the camera, the other not; usually two), so that the labels, set off
from the edge away from the box's projected centre (`out`), lie outside the volume's box; of
those, one long enough on the panel (`LAYOUT.edge_min_px`, counting only its part on the panel: the
camera frames the visible region, so the box may reach past the panel), then one with room on
the panel for its labels outside the box (an edge along the panel's border has none), then
inside it, then one mostly on the panel, then the one whose projected middle lies farthest
towards the panel's lower left (largest y - x in panel fractions, y downwards), as ParaView's
cube axes sit; that also keeps them off the triad in the bottom-right corner of a saved
picture. Where more of the edge's labels fit inside the box than outside, `out` points inside:
an axis along the border keeps its labels. An axis seen nearly end-on gets no ticks nor name.
The name sits off the middle of the edge's part on the panel, beyond
its tick labels (where ParaView puts an axis' title), not at an end: the edges often share a
corner, which holds the ticks at 0 already. Where labels would overlap (at a shared corner, on
a foreshortened edge) the later one is left out, and so is one reaching past the panel, by the
page that knows its font (and by `draw_axes` alike).
"""

from __future__ import annotations

import itertools

import numpy as np

from chronocl.core.ticks import multiples, nice_step, tick_text
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.render.camera import Camera, to_panel, world_extent
from chronocl.render.layout import LAYOUT
from chronocl.render.markers import boxes_overlap
from chronocl.render.raycaster import clip_plane
from chronocl.render.triad import AXIS_COLOURS
from chronocl.viewer.clip_outline import plane_polygon
from chronocl.viewer.view_state import ViewState


def box_axes(
    cv: Chronovolume,
    camera: Camera,
    size: tuple[int, int],
    dims: tuple[int, int, int],
    spacing: tuple[float, float, float],
    clip: tuple[float, float, float, float] | None = None,
) -> list[dict] | None:
    """The labelled edges of `cv`'s box, or of its part that the clip plane `clip` keeps, on a
    panel of `size` seen with `camera`, for a series of `dims` voxels (nx, ny, nz) at `spacing`
    (dx, dy, dz): one dict per axis not seen end-on, {"axis": "x", "from": [x, y], "to": [x, y]
    (its low and high data ends), "out": [dx, dy] (unit vector in pixels, the side its labels
    go), "ticks": [{"x", "y", "value", "label"}], "name": {"x", "y", "label"} (the middle of
    the edge's part on the panel: the name goes `out` from it beyond the labels)}; positions
    are fractions of the panel (top-left 0, as `probe.project`), ticks off the panel left out.
    [] when the clip plane keeps nothing; None when a corner of the box is behind the camera."""
    extent = world_extent(cv.shape, cv.spacing)
    bounds = visible_bounds(extent, clip)
    if bounds is None:
        return []
    corners = np.array(list(itertools.product(*zip(*bounds, strict=True))))
    at = to_panel(camera, extent, size, corners)
    if at is None:
        return None
    px = np.asarray(size, dtype=np.float64)
    centre = at.mean(axis=0) * px
    facing = _facing(camera, extent, size, bounds)
    plane = None if clip is None else np.array(clip_plane(clip, extent))
    edges = []
    for a in range(3):
        bit = 1 << (2 - a)  # corner k's side along axis a (itertools.product's order)
        pairs = [(k, k | bit) for k in range(8) if not k & bit]
        # On the outline: one of the edge's two faces towards the camera, the other not.
        b, c = (x for x in range(3) if x != a)
        outline = [
            (i, j)
            for i, j in pairs
            if facing[b, (i >> (2 - b)) & 1] != facing[c, (i >> (2 - c)) & 1]
        ]
        candidates = []
        for i, j in outline or pairs:
            kept = _kept(corners[i], corners[j], plane)  # (an oblique plane's AABB: not all)
            if kept is None:
                continue
            p0, p1 = ends = to_panel(camera, extent, size, kept)
            out = _out(ends, px, centre)
            length = float(np.hypot(*((p1 - p0) * px)))
            ticks = _ticks(a, kept, extent, camera, size, dims[a], spacing[a], length)
            candidates.append((p0, p1, out, ticks))
        if not candidates:
            continue
        p0, p1, out, ticks = max(candidates, key=lambda e: _preference(*e, px))
        if _shown_length(p0, p1, px) < LAYOUT.edge_min_px:
            continue
        if _labels_on_panel(ticks, -out, px) > _labels_on_panel(ticks, out, px):
            out = -out  # along the panel's border its labels fall off it: inside the box
        lo, hi = _on_panel(p0, p1)
        edge = {"axis": "xyz"[a], "from": _rounded(p0), "to": _rounded(p1), "out": _rounded(out)}
        # the name off the middle of the part on the panel
        mid = p0 + (p1 - p0) * (lo + hi) / 2
        edge["name"] = dict(zip("xy", _rounded(mid), strict=True), label="xyz"[a])
        edge["ticks"] = ticks
        edges.append(edge)
    return edges


def views_axes(state: ViewState, cvs: list[Chronovolume], series: TimeSeries) -> list | None:
    """With `state`'s box on (its outline), each view's labelled edges (`box_axes`) under its
    own camera, of the part its clip plane keeps, in `series`' spacing units; None with the box
    off. The frames' header, Save PNG, movie frames and `chronocl render --state` take them
    from here."""
    if not state.outline:
        return None
    return [
        box_axes(cv, state.panel_camera(i), state.size, series.dims, series.spacing, state.clip)
        for i, cv in enumerate(cvs)
    ]


def visible_bounds(
    extent: np.ndarray, clip: tuple[float, float, float, float] | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """The world box (low corner, high corner) around the part of the volume's box (`extent`,
    centred at the origin) that the clip plane `clip` keeps, as the bounds of a clipped data
    set in ParaView: the whole box without a plane, the kept half along an axis-aligned one;
    None where it keeps nothing."""
    half = np.asarray(extent, dtype=np.float64) / 2
    if clip is None:
        return -half, half
    *n, d = clip_plane(clip, extent)
    corners = np.array(list(itertools.product(*[(-h, h) for h in half])))
    side = corners @ n + d
    if not (side > 1e-9).any():
        return None  # (offset 1: no more than a face or a corner)
    points = np.concatenate([corners[side >= 0], plane_polygon(clip, extent)])
    return points.min(axis=0), points.max(axis=0)


def _kept(p0: np.ndarray, p1: np.ndarray, plane: np.ndarray | None) -> np.ndarray | None:
    """The part of the world segment p0 -> p1 on the side `plane` (n, d) keeps, as its two ends
    (2, 3) in the same order; None where it keeps none of it."""
    if plane is None:
        return np.array([p0, p1])
    s0, s1 = p0 @ plane[:3] + plane[3], p1 @ plane[:3] + plane[3]
    lo, hi = 0.0, 1.0
    if s0 < -1e-9 and s1 < -1e-9:
        return None
    if s0 < -1e-9:
        lo = s0 / (s0 - s1)
    elif s1 < -1e-9:
        hi = s0 / (s0 - s1)
    if hi - lo < 1e-9:
        return None
    return np.array([p0 + (p1 - p0) * lo, p0 + (p1 - p0) * hi])


def _facing(
    camera: Camera,
    extent: np.ndarray,
    size: tuple[int, int],
    bounds: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """(3, 2) bools: whether the face of the world box `bounds` (low corner, high corner) on
    the low (0) or high (1) side of each axis faces the camera (a face seen edge-on does not)."""
    w, h = size
    view, _ = camera.matrices(extent, w / h)
    eye = -view[:3, :3].T @ view[:3, 3]
    direction = camera.eye_direction()  # an orthographic camera's, the same for every face
    perspective = camera.projection == "perspective"
    out = np.zeros((3, 2), bool)
    for b in range(3):
        for high, sign in ((0, -1.0), (1, 1.0)):
            towards = eye[b] - bounds[high][b] if perspective else direction[b]
            out[b, high] = sign * towards > 1e-9
    return out


def _preference(
    p0: np.ndarray, p1: np.ndarray, out: np.ndarray, ticks: list[dict], px: np.ndarray
) -> tuple[bool, bool, bool, bool, float]:
    """An edge's rank among its axis' candidates: long enough on the panel to hold ticks
    first, then with room on the panel for (two of) its `ticks`' labels outside the box, then
    inside it, then mostly on the panel, then the farther its middle towards the lower left."""
    lo, hi = _on_panel(p0, p1)
    mid = (p0 + p1) / 2
    want = min(2, len(ticks))
    return (
        _shown_length(p0, p1, px) >= LAYOUT.edge_min_px,
        _labels_on_panel(ticks, out, px) >= want,
        _labels_on_panel(ticks, -out, px) >= want,
        hi - lo > 0.5,
        float(mid[1] - mid[0]),
    )


def _labels_on_panel(ticks: list[dict], out: np.ndarray, px: np.ndarray) -> int:
    """How many of `ticks`' labels, set off in direction `out` (pixels) and anchored as the
    page and `draw_axes` anchor them (`_anchor`), would lie on the panel (`px` its size), at
    about `LAYOUT.tick_label_w_px` by `LAYOUT.tick_label_h_px`: an edge along the panel's
    border keeps none on its outer side."""
    anchor = _anchor(out)
    lw, lh = LAYOUT.tick_label_w_px, LAYOUT.tick_label_h_px
    x0 = {"l": 0.0, "m": -0.5, "r": -1.0}[anchor[0]] * lw
    y0 = {"t": 0.0, "m": -0.5, "b": -1.0}[anchor[1]] * lh
    n = 0
    for t in ticks:
        x, y = np.array([t["x"], t["y"]]) * px + out * LAYOUT.tick_label_gap_px + (x0, y0)
        n += 0 <= x and x + lw <= px[0] and 0 <= y and y + lh <= px[1]
    return n


def _shown_length(p0: np.ndarray, p1: np.ndarray, px: np.ndarray) -> float:
    """Pixels of the segment p0 -> p1 (panel fractions) on the panel."""
    lo, hi = _on_panel(p0, p1)
    return max(0.0, hi - lo) * float(np.hypot(*((p1 - p0) * px)))


def _on_panel(p0: np.ndarray, p1: np.ndarray) -> tuple[float, float]:
    """The part of the segment p0 -> p1 (panel fractions) on the panel: (lo, hi) fractions of
    it, lo >= hi where none is."""
    lo, hi = 0.0, 1.0
    d = p1 - p0
    for k in range(2):
        if abs(d[k]) < 1e-12:
            if not 0.0 <= p0[k] <= 1.0:
                return 1.0, 0.0
            continue
        t0, t1 = sorted(((0.0 - p0[k]) / d[k], (1.0 - p0[k]) / d[k]))
        lo, hi = max(lo, t0), min(hi, t1)
    return lo, hi


def _out(ends: np.ndarray, px: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The unit vector (pixels) across the edge from ends[0] to ends[1] (panel fractions; `px`
    the panel's size) away from `centre` (pixels), the box's projected centre."""
    d = (ends[1] - ends[0]) * px
    if not np.hypot(*d) > 1e-9:
        return np.zeros(2)  # seen end-on (and left out)
    along = d / np.hypot(*d)
    out = np.array([-along[1], along[0]])
    return -out if np.dot(out, ends.mean(axis=0) * px - centre) < 0 else out


def _ticks(a, kept, extent, camera, size, n, step_size, length) -> list[dict]:
    """The ticks of the world segment `kept` (its low end first; `length` pixels long on the
    panel) along axis `a`: at 1-2-5 data coordinates of the voxels' centres (`n` of them,
    `step_size` apart) it spans, about `LAYOUT.tick_gap_px` apart at least."""
    # world -> data coordinate along a: the box spans voxel centres -0.5 .. n - 0.5
    ends = [((w / extent[a] + 0.5) * n - 0.5) * step_size for w in kept[:, a]]
    lo, hi = max(0.0, ends[0]), min((n - 1) * step_size, ends[1])
    if hi < lo:
        return []
    most = int(length * (hi - lo) / (ends[1] - ends[0]) // LAYOUT.tick_gap_px) + 1  # and the first
    step = nice_step(lo, hi, most)
    values = multiples(lo, hi, step)
    world = np.repeat(kept[:1], len(values), axis=0)
    world[:, a] = (np.array([(v / step_size + 0.5) / n for v in values]) - 0.5) * extent[a]
    at = to_panel(camera, extent, size, world)
    ticks = []
    for v, (x, y) in zip(values, at if at is not None else [], strict=False):
        if 0.0 <= x <= 1.0 and 0.0 <= y <= 1.0:
            label = tick_text(v, step)
            ticks.append(
                {"x": round(float(x), 5), "y": round(float(y), 5), "value": v, "label": label}
            )
    return ticks


def _rounded(p) -> list[float]:
    return [round(float(v), 5) for v in p]


def draw_axes(panel: np.ndarray, edges: list[dict] | None) -> np.ndarray:
    """`panel` (H, W, 3 uint8, top-down) with `edges` (`box_axes`) drawn on it as the page
    draws them: tick marks and labels in light grey, each axis' name in its triad colour, all
    with a dark rim, so they read on any background; a label that would overlap one drawn
    before it or reach past the panel is left out."""
    if not edges:
        return panel
    from PIL import Image as PILImage
    from PIL import ImageDraw

    from chronocl.render.panels import label_font

    h, w, _ = panel.shape
    out = PILImage.fromarray(np.ascontiguousarray(panel[..., :3]))
    draw = ImageDraw.Draw(out)
    font = label_font(max(11, min(w, h) // 40))
    grey, rim = (225, 225, 225), (0, 0, 0)
    kept: list[tuple[float, float, float, float]] = []

    def text(at, label, fill, anchor) -> tuple[float, float, float, float] | None:
        box = draw.textbbox(tuple(at), label, font=font, anchor=anchor, stroke_width=2)
        if (
            box[0] < 0
            or box[1] < 0
            or box[2] > w
            or box[3] > h
            or any(boxes_overlap(box, k) for k in kept)
        ):
            return None
        kept.append(box)
        draw.text(
            tuple(at), label, fill=fill, font=font, anchor=anchor, stroke_width=2, stroke_fill=rim
        )
        return box

    for edge in edges:
        o = np.array(edge["out"])
        reach = 0.0
        for tick in edge["ticks"]:
            p = np.array([tick["x"] * w, tick["y"] * h])
            box = text(p + o * LAYOUT.tick_label_gap_px, tick["label"], grey, _anchor(o))
            if box is not None:
                draw.line([tuple(p), tuple(p + o * LAYOUT.tick_px)], fill=grey, width=1)
                size = abs(o[0]) * (box[2] - box[0]) + abs(o[1]) * (box[3] - box[1])
                reach = max(reach, size)
        name = edge["name"]
        gap = LAYOUT.axis_name_gap_px
        at = np.array([name["x"] * w, name["y"] * h]) + o * (LAYOUT.tick_label_gap_px + reach + gap)
        at = np.clip(at, gap, [w - gap, h - gap])  # on the picture
        text(at, name["label"], AXIS_COLOURS["xyz".index(edge["axis"])], "mm")
    return np.asarray(out)


def _anchor(out: np.ndarray) -> str:
    """PIL's text anchor for a label set off from its tick in direction `out` (the page's
    text-anchor and dominant-baseline follow the same rule)."""
    horizontal = "l" if out[0] > 0.5 else "r" if out[0] < -0.5 else "m"
    return horizontal + ("t" if out[1] > 0.5 else "b" if out[1] < -0.5 else "m")
