"""Markers in a rendered panel: a ring and a label at points of the volume, e.g. the events of
a window (`chronocl.events`: merges, splits, births, deaths at their features' centroids), so
that a picture says where in the chronovolume something happened.

A marker is (x, y, z as fractions of the volume's box, voxel centres at (i + 0.5) / n;
label): the same at every level of the series. It is projected with the panel's camera as the
raycaster lays the volume out (`camera.world_extent`, `camera.to_panel`); markers behind the
camera or off the panel are left out, and so is a label with no room beside its ring (labels
never overlap, nor stray to another ring). Rings and labels have a dark rim, so they read on black
and on white. `draw_path` draws a line through points of the box instead, a dot at each and a
label at its start: a feature's track through a window (the viewer's events panel highlights the
track chosen).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise

import numpy as np

from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import Camera, to_panel, world_extent
from chronocl.render.layout import LAYOUT

Marker = tuple[Sequence[float], str]  # (x, y, z) fractions of the box, label
MARKER_RGB = (255, 230, 90)
PATH_RGB = (90, 220, 255)  # a track's path: apart from the markers' yellow
RIM = (0, 0, 0)


def draw_markers(
    panel: np.ndarray, camera: Camera, cv: Chronovolume, markers: Sequence[Marker]
) -> np.ndarray:
    """`panel` (H, W, 3 uint8, top-down) with `markers` drawn where `camera` sees them."""
    from PIL import Image as PILImage
    from PIL import ImageDraw

    from chronocl.render.panels import label_font

    if not markers:
        return panel
    h, w, _ = panel.shape
    extent = world_extent(cv.shape, cv.spacing)
    fractions = np.asarray([m[0] for m in markers], dtype=np.float64).reshape(-1, 3)
    world = (fractions - 0.5) * extent
    at = [to_panel(camera, extent, (w, h), p[None]) for p in world]  # None: behind the camera
    image = PILImage.fromarray(panel)
    draw = ImageDraw.Draw(image)
    radius = max(LAYOUT.ring_min_px, round(LAYOUT.ring_fraction * min(w, h)))
    font = label_font(max(10, radius * 2))
    placed: list[tuple[float, float, float, float]] = []  # labels drawn: none overlaps
    for point, (_, label) in zip(at, markers, strict=True):
        if point is None:
            continue
        x, y = point[0]
        if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
            continue
        px, py = x * w, y * h
        ring = (px - radius, py - radius, px + radius, py + radius)
        draw.ellipse(ring, outline=RIM, width=4)
        draw.ellipse(ring, outline=MARKER_RGB, width=2)
        bounds = draw.textbbox((0, 0), label, font=font, stroke_width=2)
        spot = _label_spot(bounds, px, py, radius, placed, (w, h))
        if spot is None:  # no room beside its ring: the ring alone (the events' list names it)
            continue
        placed.append(spot[1])
        draw.text(spot[0], label, fill=MARKER_RGB, font=font, stroke_width=2, stroke_fill=RIM)
    return np.asarray(image)


def _label_spot(bounds, px: float, py: float, radius: float, placed: list, size: tuple):
    """Where a label of text box `bounds` (at the origin) goes beside the ring at (px, py):
    right of it, then left, each in place, a line lower or higher, two lines; the first spot
    on the panel that overlaps no label placed, as ((x, y), box); None: none. Farther away a
    label would name another marker's ring."""
    left, top, right, bottom = bounds
    w, h = size
    for shift in _shifts(bottom - top + 2, most=2):
        for at_x in (px + radius + 2, px - radius - 2 - (right - left)):
            at_y = py - radius + shift
            box = (at_x + left, at_y + top, at_x + right, at_y + bottom)
            inside = box[0] >= 0 and box[1] >= 0 and box[2] <= w and box[3] <= h
            if inside and not any(boxes_overlap(box, other) for other in placed):
                return (at_x, at_y), box
    return None


def draw_path(
    panel: np.ndarray,
    camera: Camera,
    cv: Chronovolume,
    points: Sequence[Sequence[float]],
    label: str,
    rgb: tuple[int, int, int] = PATH_RGB,
) -> np.ndarray:
    """`panel` with a line through `points` ((x, y, z) fractions of the box, in order), a dot
    at each and `label` beside the first, where `camera` sees them; a stretch with an end
    behind the camera is left out."""
    from PIL import Image as PILImage
    from PIL import ImageDraw

    from chronocl.render.panels import label_font

    if not len(points):
        return panel
    h, w, _ = panel.shape
    extent = world_extent(cv.shape, cv.spacing)
    world = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - 0.5) * extent
    at = [to_panel(camera, extent, (w, h), p[None]) for p in world]
    xy = [None if a is None else (a[0][0] * w, a[0][1] * h) for a in at]
    image = PILImage.fromarray(panel)
    draw = ImageDraw.Draw(image)
    dot = max(3, round(LAYOUT.ring_fraction * min(w, h) / 2))
    for colour, width in ((RIM, 6), (rgb, 3)):
        for a, b in pairwise(xy):
            if a is not None and b is not None:
                draw.line((a, b), fill=colour, width=width)
    for p in xy:
        if p is not None:
            draw.ellipse((p[0] - dot, p[1] - dot, p[0] + dot, p[1] + dot), fill=rgb, outline=RIM)
    start = next((p for p in xy if p is not None), None)  # (an event's label marks the end)
    if start is not None:
        font = label_font(max(10, dot * 4))
        at_x, at_y = start[0] + 2 * dot + 2, start[1] + dot
        draw.text((at_x, at_y), label, fill=rgb, font=font, stroke_width=2, stroke_fill=RIM)
    return np.asarray(image)


def _shifts(line: float, most: int = 8):
    """Vertical offsets to try for a label: in place, then a line lower, higher, two..."""
    yield 0.0
    for k in range(1, most + 1):
        yield k * line
        yield -k * line


def boxes_overlap(a, b) -> bool:
    """Whether boxes (x0, y0, x1, y1) `a` and `b` overlap (touching edges do not)."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]
