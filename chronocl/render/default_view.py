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
from chronocl.core.tuning import TUNING
from chronocl.integration.window_centres import window_centres
from chronocl.render.camera import Camera

AZIMUTHS = range(0, 360, 15)
# Views from far below the up axis read as upside down; a shift mostly along it (a plume
# rising) is seen from the side, where its steps stand one above the other anyway.
ELEVATIONS = range(-15, 61, 15)


def early_side(camera: Camera, centres: dict | None) -> Camera:
    """`camera` turned (azimuth and elevation) to look from the side of the window's first
    steps, given where they and its last steps lie (`window_centres`; None: kept)."""
    if not centres:
        return camera
    c0, c1 = np.asarray(centres["first"], float), np.asarray(centres["last"], float)
    extent = np.asarray(centres["extent"], dtype=np.float64)
    shift = c0 - c1
    if np.linalg.norm(shift) < TUNING.default_view_min_shift * 0.5 * np.linalg.norm(extent):
        return camera
    want = shift / np.linalg.norm(shift)

    def align(ae: tuple[int, int]) -> float:
        turned = dataclasses.replace(camera, azimuth=ae[0], elevation=ae[1])
        return float(np.dot(turned.eye_direction(), want))

    best = max(itertools.product(AZIMUTHS, ELEVATIONS), key=align)
    if align(best) < TUNING.default_view_min_align:
        return camera
    return dataclasses.replace(camera, azimuth=float(best[0]), elevation=float(best[1]))


def series_early_side(series, selection: Selection, value_range, camera: Camera) -> Camera:
    """`early_side` of a window of `series` (the command line's, before it integrates)."""
    return early_side(camera, window_centres(series, selection, value_range))


def default_camera(chronovolume) -> Camera:
    """The view `render` takes without a camera: `Camera()` turned by the centres the
    chronovolume keeps (`chronocl.integrate` records them), as the command line turns it."""
    return early_side(Camera(), chronovolume.metadata.get("centres"))
