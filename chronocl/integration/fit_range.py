"""The value range a data TF uses when none is given: fitted to the selected window, per mode.

A series' global range (recorded at ingest) hides what a window holds: a plume whose first
steps peak at a tenth of the run's maximum normalises them to u < 0.1, under any TF's
threshold, and the per-voxel minima of `min` all sit near the bottom. So by default the range
is the window's own, taken from the values the mode shows:

- modes that colour every step by its values (alpha, first_hit, additive, mean, count): the
  values of the selected steps; `max` / `min`: each voxel's maximum / minimum over them;
  `change`: the window's minimum and maximum (its differences are taken within that range).
- low end: the median of those values, or the window's minimum where the median is the
  minimum (a background at the bottom stays transparent, the faint rest shows);
  high end: their 99.9th percentile, so one hot voxel does not darken the rest.

The values come from a sample of at most `TUNING.fit_sample_values` voxels (a stored coarse level
where the series has one, else every n-th voxel along each axis) of at most
`TUNING.fit_sample_steps` evenly spaced selected steps. Results are kept per series, selection and
mode.
"""

from __future__ import annotations

import math
import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable

import numpy as np

from chronocl.core.selection import Selection
from chronocl.core.tuning import TUNING

TOP_PERCENTILE = 99.9


class SeriesCache:
    """The last `size` results computed from a series, least recently used dropped first.
    Thread-safe (the viewer fits from several clients' threads); keeps no series alive."""

    def __init__(self, size: int = 64) -> None:
        self.size = size
        self._results: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def get(self, series, key: tuple, compute: Callable[[], object]):
        """The result kept for `series` and `key`, else `compute()` (called outside the lock:
        it reads data) kept."""
        key = (id(series), series.path, *key)
        with self._lock:
            hit = self._results.get(key)
            if hit is not None and hit[0]() is series:
                self._results.move_to_end(key)
                return hit[1]
        result = compute()
        with self._lock:
            self._results[key] = (weakref.ref(series), result)
            while len(self._results) > self.size:
                self._results.popitem(last=False)
        return result


_FITTED = SeriesCache()


def window_range(series, selection: Selection, mode) -> tuple[float, float]:
    """(lo, hi) for normalising the values of `selection` of `series` integrated by `mode`
    (a registered Mode), lo < hi; the window's own (min, max) where the sample is flat."""
    key = (tuple(selection.steps), mode.name)
    return _FITTED.get(series, key, lambda: _fit(series, selection, mode))


def _fit(series, selection: Selection, mode) -> tuple[float, float]:
    stats = series.stats
    steps = list(selection.steps)
    w_min = min(stats.step_min[s] for s in steps)
    w_max = max(stats.step_max[s] for s in steps)
    if not w_max > w_min or mode.name == "change":
        return _distinct(w_min, w_max)
    if len(steps) > TUNING.fit_sample_steps:
        picks = np.linspace(0, len(steps) - 1, TUNING.fit_sample_steps).round().astype(int)
        steps = [steps[i] for i in sorted(set(picks.tolist()))]
    sample = sample_steps(series, steps, mode.pool)
    if mode.name == "max":
        shown = sample.max(axis=0)
    elif mode.name == "min":
        shown = sample.min(axis=0)
    else:
        shown = sample
    shown = shown[np.isfinite(shown)]
    if shown.size == 0:
        return _distinct(w_min, w_max)
    median, top = (float(v) for v in np.percentile(shown, [50.0, TOP_PERCENTILE]))
    lo = max(float(w_min), median)
    hi = min(float(w_max), top)
    if not hi > lo:  # most values equal: the range of what rises above them
        above = shown[shown > lo]
        hi = float(np.percentile(above, TOP_PERCENTILE)) if above.size else float(w_max)
    if not hi > lo:
        return _distinct(w_min, w_max)
    return _distinct(lo, hi)


def sample_steps(series, steps: list[int], pool: str = "mean") -> np.ndarray:
    """(n, z, y, x) float32 values of `steps`, about TUNING.fit_sample_values voxels in all: a
    stored coarse level (pooled by `pool`) when there is a small enough one, else every n-th voxel
    of the coarsest stored level (of level 0 where none is stored)."""
    budget = TUNING.fit_sample_values / len(steps)
    source = series
    stored = series.path is not None or getattr(series.level_source, "stored", False)
    if stored:  # stored levels (local or remote) read cheaply; in memory they would pool it all
        # The first level small enough, else the coarsest: a stride through level 0 would
        # still decode every chunk of every sampled step (1.5 s for ten 512^3 float32 steps).
        for n in range(1, series.n_levels):
            source = series.level(n, pool)
            if math.prod(source.volume_shape) <= budget:
                break
    nz, ny, nx = source.volume_shape
    stride = max(1, math.ceil((nz * ny * nx / budget) ** (1 / 3)))
    every = slice(None, None, stride)
    return np.concatenate(
        [source.read_region(slice(s, s + 1), every, every, every) for s in steps]
    ).astype(np.float32, copy=False)


def _distinct(lo: float, hi: float) -> tuple[float, float]:
    """(lo, hi) distinct in float32 (the engines' precision): a flat range is widened by one."""
    lo, hi = float(lo), float(hi)
    if not np.float32(lo) < np.float32(hi):
        hi = lo + max(1.0, abs(lo) * 1e-6)
    return lo, hi
