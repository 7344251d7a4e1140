"""The default view: looking from the side where a window's first steps lie.

A front that spreads from one corner hides its own history: the newest shell encloses the
older ones, so from the far side the picture is the newest step alone. Looking from where
the first selected step lies, the older steps sit in front of the newer (the box's faces cut
through every shell). So the default camera turns towards the first step's centre of mass
as seen from the last step's, at elevations of -15° to 60°; where the two nearly coincide (a
feature that grows in place) or the shift runs along the up axis (a plume rising) the given
camera is kept.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from chronocl.core.selection import Selection
from chronocl.integration.fit_range import sample_steps
from chronocl.render.camera import Camera

# Shifts of the centre of mass under this fraction of the box's half diagonal keep the view.
MIN_SHIFT = 0.08
AZIMUTHS = range(0, 360, 15)
# Views from far below the up axis read as upside down; a shift mostly along it (a plume
# rising) is seen from the side, where its steps stand one above the other anyway.
ELEVATIONS = range(-15, 61, 15)
MIN_ALIGN = 0.5  # cosine between the best view and the shift under which the view stays


def early_side(series, selection: Selection, value_range, camera: Camera) -> Camera:
    """`camera` turned (azimuth and elevation) to look from the first selected step's side."""
    steps = list(selection.steps)
    if len(steps) < 2:
        return camera
    first, last = sample_steps(series, [steps[0], steps[-1]], "mean")
    lo = float(value_range[0])
    extent = np.array(series_extent_xyz(series), dtype=np.float64)
    c0, c1 = (_centre(np.clip(v - lo, 0, None), extent) for v in (first, last))
    if c0 is None or c1 is None:
        return camera
    shift = c0 - c1
    if np.linalg.norm(shift) < MIN_SHIFT * 0.5 * np.linalg.norm(extent):
        return camera
    want = shift / np.linalg.norm(shift)

    def align(ae: tuple[int, int]) -> float:
        turned = dataclasses.replace(camera, azimuth=ae[0], elevation=ae[1])
        return float(np.dot(turned.eye_direction(), want))

    best = max(itertools.product(AZIMUTHS, ELEVATIONS), key=align)
    if align(best) < MIN_ALIGN:
        return camera
    return dataclasses.replace(camera, azimuth=float(best[0]), elevation=float(best[1]))


def series_extent_xyz(series) -> tuple[float, float, float]:
    """The series' box in world units, x first (voxels times spacing)."""
    nz, ny, nx = series.volume_shape
    dx, dy, dz = series.spacing
    return nx * dx, ny * dy, nz * dz


def _centre(weights: np.ndarray, extent: np.ndarray) -> np.ndarray | None:
    """The weighted centre of a (z, y, x) sample in world (x, y, z), the box centred at 0."""
    total = float(weights.sum())
    if not total > 0:
        return None
    out = []
    for axis, size in zip((2, 1, 0), extent, strict=True):
        n = weights.shape[axis]
        pos = ((np.arange(n) + 0.5) / n - 0.5) * size
        profile = weights.sum(axis=tuple(a for a in range(3) if a != axis))
        out.append(float(np.dot(profile, pos)) / total)
    return np.array(out)
