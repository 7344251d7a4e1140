"""Framing: the part of a chronovolume that is not transparent, as a world box for the camera.

A chronovolume often fills a small part of its box (a plume rising in a tall domain); framing
the box then draws it as a speck. `visible_box` finds the voxels whose opacity exceeds
`TUNING.visible_alpha` (or a tenth of the largest opacity, for faint volumes) by per-axis `any`
over a strided sample of at most `TUNING.framing_sample_voxels`, grown by the stride so that nothing
sampled past is cut off. `framed` gives a camera with `frame="visible"` that box as its focus;
an all-transparent volume keeps the whole box.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import Camera, world_extent


def visible_box(cv: Chronovolume) -> np.ndarray | None:
    """World box (x0, y0, z0, x1, y1, z1) of the voxels more opaque than `TUNING.visible_alpha`
    (or a tenth of the largest opacity, if that is less); None when every voxel is transparent."""
    alpha = cv.rgba[..., 3]
    stride = max(1, math.ceil((alpha.size / TUNING.framing_sample_voxels) ** (1 / 3)))
    sample = alpha[::stride, ::stride, ::stride]
    if sample.dtype == np.uint8:  # a display chronovolume's RGBA8
        sample = sample / np.float32(255)
    top = float(sample.max()) if sample.size else 0.0
    if not top > 0:
        return None
    seen = sample > min(TUNING.visible_alpha, top / 10)
    lo, hi = [], []
    for axis, n in ((2, alpha.shape[2]), (1, alpha.shape[1]), (0, alpha.shape[0])):
        others = tuple(a for a in range(3) if a != axis)
        idx = np.flatnonzero(seen.any(axis=others))
        lo.append(max(int(idx[0]) * stride - (stride - 1), 0))
        hi.append(min(int(idx[-1]) * stride + stride, n))
    extent = world_extent(alpha.shape, cv.spacing)
    voxel = extent / np.array(alpha.shape[::-1], dtype=np.float64)
    return np.concatenate([-extent / 2 + np.array(lo) * voxel, -extent / 2 + np.array(hi) * voxel])


def union_box(chronovolumes: Sequence[Chronovolume]) -> np.ndarray | None:
    """The smallest world box holding every chronovolume's visible box (None: none visible)."""
    boxes = [b for b in (visible_box(cv) for cv in chronovolumes) if b is not None]
    if not boxes:
        return None
    stacked = np.stack(boxes)
    return np.concatenate([stacked[:, :3].min(axis=0), stacked[:, 3:].max(axis=0)])


def framed(camera: Camera, chronovolumes: Sequence[Chronovolume]) -> Camera:
    """`camera` framing what is visible in `chronovolumes` (drawn under one camera): its focus
    set to their visible region. A camera framing the box, one with a focus already, and
    volumes that are all transparent or visible to their edges are returned as they are."""
    if camera.frame != "visible" or camera.focus is not None or not chronovolumes:
        return camera
    box = union_box(chronovolumes)
    if box is None:
        return camera
    half = world_extent(chronovolumes[0].shape, chronovolumes[0].spacing) / 2
    if np.allclose(box[:3], -half) and np.allclose(box[3:], half):
        return camera  # the whole box: exactly the box's framing
    return replace(camera, focus=tuple(float(v) for v in box))
