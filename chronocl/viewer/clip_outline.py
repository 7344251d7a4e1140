"""The clip plane's outline on a panel: where the plane meets the volume's box, projected with
the panel's camera, so the page can draw the cut it is looking through."""

from __future__ import annotations

import itertools

import numpy as np

from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import Camera, to_panel, world_extent
from chronocl.render.raycaster import clip_plane


def plane_polygon(clip: tuple[float, float, float, float], extent: np.ndarray) -> np.ndarray:
    """The polygon (k, 3), k in 3..6 or 0, where the plane `clip` cuts the box of `extent`
    centred at the origin, its corners in order around it (world space, as the raycaster)."""
    *n, d = clip_plane(clip, extent)
    n = np.asarray(n)
    half = np.asarray(extent, dtype=np.float64) / 2
    corners = np.array(list(itertools.product(*[(-h, h) for h in half])))
    side = corners @ n + d
    points = []
    for i, j in itertools.combinations(range(8), 2):
        if np.count_nonzero(corners[i] != corners[j]) != 1:
            continue  # not an edge of the box
        a, b = side[i], side[j]
        if a == b or a * b > 0:
            continue
        points.append(corners[i] + (a / (a - b)) * (corners[j] - corners[i]))
    if len(points) < 3:
        return np.zeros((0, 3))
    p = np.unique(np.round(np.array(points), 12), axis=0)
    centre = p.mean(axis=0)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    angle = np.arctan2((p - centre) @ v, (p - centre) @ u)
    return p[np.argsort(angle)]


def clip_outline(
    cv: Chronovolume,
    camera: Camera,
    size: tuple[int, int],
    clip: tuple[float, float, float, float] | None,
) -> list[list[float]] | None:
    """The plane's polygon on a panel of `size`: [x, y] fractions of the panel (top-left 0,
    beyond 0..1 where it leaves the panel), or None without a clip plane, a miss, or a corner
    behind the camera."""
    if clip is None:
        return None
    extent = world_extent(cv.shape, cv.spacing)
    polygon = plane_polygon(clip, extent)
    if not len(polygon):
        return None
    at = to_panel(camera, extent, size, polygon)
    return None if at is None else [[round(float(x), 5), round(float(y), 5)] for x, y in at]
