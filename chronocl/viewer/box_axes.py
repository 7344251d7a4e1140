"""The box's axes on a panel, as ParaView's cube axes: with the box outline on, three of its
edges (one along x, one along y, one along z) carry ticks at 1-2-5 values of the data's
coordinates and the axis' name, projected with the panel's camera so the page draws them over
the picture (views.js `showAxes`) and the saved PNG carries them (`draw_axes`).

Coordinates: voxel i's centre lies at i times the series' (level 0's) spacing along its axis,
so an axis' ticks run over 0 .. (n - 1) * spacing, where the probe puts the voxels
(`probe.box_fractions`); a coarse level keeps level 0's box, so its ticks are the same.

Which edges: of the four edges along an axis, those on the projected box's outline (one of the
edge's two faces towards the camera, the other not; usually two), so that the labels, set off
from the edge away from the box's projected centre (`out`), lie outside the volume's box; of
those, one long enough on the panel (`MIN_EDGE_PX`, counting only its part on the panel: the
camera frames the visible region, so the box may reach past the panel), then one mostly on the
panel, then the one whose projected middle lies farthest towards the panel's lower left
(largest y - x in panel fractions, y downwards), as ParaView's cube axes sit; that also keeps
them off the triad in the bottom-right corner of a saved picture. An axis seen nearly end-on
gets no ticks nor name. The name sits off the middle of the edge's part on the panel, beyond
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
from chronocl.render.camera import Camera, to_panel
from chronocl.render.markers import boxes_overlap
from chronocl.render.triad import AXIS_COLOURS
from chronocl.viewer.slots import geometry
from chronocl.viewer.view_state import ViewState

MIN_EDGE_PX = 40  # an edge shorter than this on the panel is seen end-on: no ticks
TICK_GAP_PX = 50  # ticks along an edge at least about this far apart
# As views.js draws them: a tick mark's length outwards from its edge, a label's gap from the
# edge, and an axis name's gap beyond its tick labels.
TICK_PX = 5
LABEL_PX = 8
NAME_GAP_PX = 8


def box_axes(
    cv: Chronovolume,
    camera: Camera,
    size: tuple[int, int],
    dims: tuple[int, int, int],
    spacing: tuple[float, float, float],
) -> list[dict] | None:
    """The labelled edges of `cv`'s box on a panel of `size` seen with `camera`, for a series
    of `dims` voxels (nx, ny, nz) at `spacing` (dx, dy, dz): one dict per axis not seen end-on,
    {"axis": "x", "from": [x, y], "to": [x, y] (its low and high data ends), "out": [dx, dy]
    (unit vector in pixels, away from the box), "ticks": [{"x", "y", "value", "label"}],
    "name": {"x", "y", "label"} (the middle of the edge's part on the panel: the name goes
    `out` from it beyond the labels)}; positions are fractions of the panel (top-left 0, as
    `probe.project`), ticks off the panel left out. None when a corner of the box is behind
    the camera."""
    extent, _ = geometry(cv)
    half = extent / 2
    corners = np.array(list(itertools.product(*[(-h, h) for h in half])))
    at = to_panel(camera, extent, size, corners)
    if at is None:
        return None
    px = np.asarray(size, dtype=np.float64)
    centre = at.mean(axis=0) * px
    facing = _facing(camera, extent, size)
    edges = []
    for a in range(3):
        bit = 1 << (2 - a)  # corner k's side along axis a (itertools.product's order)
        pairs = [(k, k | bit) for k in range(8) if not k & bit]
        # On the outline: one of the edge's two faces towards the camera, the other not.
        b, c = (x for x in range(3) if x != a)
        side = [(int(corners[i][b] > 0), int(corners[i][c] > 0)) for i, _ in pairs]
        outline = [
            e for e, (sb, sc) in zip(pairs, side, strict=True) if facing[b, sb] != facing[c, sc]
        ]
        i, j = max(outline or pairs, key=lambda e: _preference(at[e[0]], at[e[1]], px))
        lo, hi = _on_panel(at[i], at[j])
        if _shown_length(at[i], at[j], px) < MIN_EDGE_PX:
            continue
        edge = _edge(a, at[i], at[j], px, centre)
        # the name off the middle of the part on the panel
        mid = at[i] + (at[j] - at[i]) * (lo + hi) / 2
        edge["name"] = dict(zip("xy", _rounded(mid), strict=True), label="xyz"[a])
        length = float(np.hypot(*((at[j] - at[i]) * px)))
        edge["ticks"] = _ticks(a, corners[i], extent, camera, size, dims[a], spacing[a], length)
        edges.append(edge)
    return edges


def views_axes(state: ViewState, cvs: list[Chronovolume], series: TimeSeries) -> list | None:
    """With `state`'s box on (its outline), each view's labelled edges (`box_axes`) under its
    own camera, in `series`' spacing units; None with the box off. The frames' header, Save
    PNG, movie frames and `chronocl render --state` take them from here."""
    if not state.outline:
        return None
    return [
        box_axes(cv, state.panel_camera(i), state.size, series.dims, series.spacing)
        for i, cv in enumerate(cvs)
    ]


def _facing(camera: Camera, extent: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(3, 2) bools: whether the box's face on the low (0) or high (1) side of each axis
    faces the camera (a face seen edge-on does not)."""
    w, h = size
    view, _ = camera.matrices(extent, w / h)
    eye = -view[:3, :3].T @ view[:3, 3]
    direction = camera.eye_direction()  # an orthographic camera's, the same for every face
    perspective = camera.projection == "perspective"
    out = np.zeros((3, 2), bool)
    for b in range(3):
        for high, sign in ((0, -1.0), (1, 1.0)):
            towards = eye[b] - sign * extent[b] / 2 if perspective else direction[b]
            out[b, high] = sign * towards > 1e-9
    return out


def _preference(p0: np.ndarray, p1: np.ndarray, px: np.ndarray) -> tuple[bool, bool, float]:
    """An edge's rank among its axis' candidates: long enough on the panel to hold ticks
    first, then mostly on the panel, then the farther its middle towards the lower left."""
    lo, hi = _on_panel(p0, p1)
    mid = (p0 + p1) / 2
    return _shown_length(p0, p1, px) >= MIN_EDGE_PX, hi - lo > 0.5, float(mid[1] - mid[0])


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


def _edge(a: int, p0: np.ndarray, p1: np.ndarray, px: np.ndarray, centre: np.ndarray) -> dict:
    """The edge along axis `a` from p0 to p1 on the panel (fractions; `px` its size, `centre`
    the box's projected centre in pixels) with its directions."""
    d = (p1 - p0) * px
    along = d / np.hypot(*d)
    out = np.array([-along[1], along[0]])
    if np.dot(out, (p0 + p1) / 2 * px - centre) < 0:
        out = -out
    return {
        "axis": "xyz"[a],
        "from": _rounded(p0),
        "to": _rounded(p1),
        "out": _rounded(out),
    }


def _ticks(a, start, extent, camera, size, n, step_size, length) -> list[dict]:
    """The ticks of the edge along axis `a` from world point `start` (its low end; `length`
    pixels long on the panel): at 1-2-5 data coordinates over its `n` voxels' centres
    (`step_size` apart), about `TICK_GAP_PX` apart at least."""
    hi = (n - 1) * step_size
    most = int(length * (n - 1) / n // TICK_GAP_PX) + 1  # intervals, and the tick at 0
    step = nice_step(0.0, hi, most)
    values = multiples(0.0, hi, step)
    world = np.repeat(start[None], len(values), axis=0)
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
            box = text(p + o * LABEL_PX, tick["label"], grey, _anchor(o))
            if box is not None:
                draw.line([tuple(p), tuple(p + o * TICK_PX)], fill=grey, width=1)
                size = abs(o[0]) * (box[2] - box[0]) + abs(o[1]) * (box[3] - box[1])
                reach = max(reach, size)
        name = edge["name"]
        at = np.array([name["x"] * w, name["y"] * h]) + o * (LABEL_PX + reach + NAME_GAP_PX)
        at = np.clip(at, NAME_GAP_PX, [w - NAME_GAP_PX, h - NAME_GAP_PX])  # on the picture
        text(at, name["label"], AXIS_COLOURS["xyz".index(edge["axis"])], "mm")
    return np.asarray(out)


def _anchor(out: np.ndarray) -> str:
    """PIL's text anchor for a label set off from its tick in direction `out` (the page's
    text-anchor and dominant-baseline follow the same rule)."""
    horizontal = "l" if out[0] > 0.5 else "r" if out[0] < -0.5 else "m"
    return horizontal + ("t" if out[1] > 0.5 else "b" if out[1] < -0.5 else "m")
