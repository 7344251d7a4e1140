"""Where a window's first and last selected steps lie: their centres of mass (values above the
range's low end, on a sample of each step) in world units, the box centred at 0, x first.

A chronovolume made by `chronocl.integrate` keeps them in its metadata (``centres``), so
`chronocl.render.default_view` turns the camera towards the first steps from a chronovolume
alone, as the command line does from the series: one default view for both.
"""

from __future__ import annotations

import numpy as np

from chronocl.core.selection import Selection
from chronocl.integration.fit_range import SeriesCache, sample_steps

_CENTRES = SeriesCache()  # render integrates mode by mode, turntables frame by frame


def window_centres(series, selection: Selection, value_range) -> dict | None:
    """{"first": [x, y, z], "last": [x, y, z], "extent": [x, y, z]} in world units; None for
    a window of one step or a step with nothing above the range's low end. Kept per series,
    window and range (two sampled steps read once)."""
    key = (selection.steps[0], selection.steps[-1], float(value_range[0]))
    return _CENTRES.get(series, key, lambda: _centres(series, selection, value_range))


def _centres(series, selection: Selection, value_range) -> dict | None:
    steps = list(selection.steps)
    if len(steps) < 2:
        return None
    first, last = sample_steps(series, [steps[0], steps[-1]], "mean")
    lo = float(value_range[0])
    nz, ny, nx = series.volume_shape
    dx, dy, dz = series.spacing
    extent = np.array([nx * dx, ny * dy, nz * dz], dtype=np.float64)
    c0, c1 = (_centre(np.clip(v - lo, 0, None), extent) for v in (first, last))
    if c0 is None or c1 is None:
        return None
    return {"first": c0, "last": c1, "extent": [float(e) for e in extent]}


def _centre(weights: np.ndarray, extent: np.ndarray) -> list[float] | None:
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
    return out
