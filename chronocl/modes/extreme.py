"""max / min: the step holding the extreme raw value supplies the voxel, coloured by its TF there.

k* = argmax (argmin) of the raw values v_k, ties to the step integrated first; (a c, a) at
u = normalize(v_k*) and that step's time position; t_index = s_k*. Since u is monotone in v the
picture is the extreme of u, and the winner does not depend on the data TF or its range:
t_index answers "when did this voxel peak" (DESIGN.md). Slides by aggregation: the back's winner
replaces the front's only when its raw value is strictly more extreme.
"""

from __future__ import annotations

import numpy as np

from chronocl.core import values as _values
from chronocl.modes.base import Mode, Partial


def winners(best: np.ndarray, best_k: np.ndarray, steps, step_rgba) -> Partial:
    """Each voxel coloured by the step that won it (best_k, -1: none) at its value `best`:
    the data TF at that value, that step's time TF and enhancement, premultiplied."""
    rgba = np.zeros((*best.shape, 4), dtype=np.float64)
    t_index = np.full(best.shape, -1, dtype=np.int32)
    for k in np.unique(best_k[best_k >= 0]):
        sel = best_k == k
        c, a = step_rgba(int(k), best)
        rgba[sel, :3] = a[sel, None] * c[sel]
        rgba[sel, 3] = a[sel]
        t_index[sel] = steps[k]
    return Partial(rgba, t_index, best)


def raw_lanes(dtype, n_steps: int) -> str | None:
    """The narrow step lanes ("uchar" or "ushort") in which the kernel compares integer data in
    its own lanes, where the window's steps fit them; None: compare as float (exact too)."""
    dtype = np.dtype(dtype)
    if dtype not in (np.uint8, np.uint16, np.int16) or n_steps > 2 ** (8 * dtype.itemsize):
        return None
    return "uchar" if dtype == np.uint8 else "ushort"


class Extreme(Mode, abstract=True):
    kernel = "extreme"
    kernel_function = "integrate_extreme"
    rows_kernel = "integrate_extreme_rows"
    rows_state = 8  # the key and the step, each in lanes of at most 4 bytes
    has_t_index = True
    writes_winners = True
    state_bytes = 24
    compares_values = True
    reads_values = True
    lut_by_value = True  # built without QUANT: the LUT is interpolated at the winning u
    is_min = False

    def better(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Where value a beats value b (strictly)."""
        return a < b if self.is_min else a > b

    def accumulate(self, u, steps, order, step_rgba, spec, values):
        raw = np.asarray(values.raw, dtype=np.float32)
        best = np.zeros(raw.shape[1:], dtype=np.float32)
        best_k = np.full(raw.shape[1:], -1, dtype=np.int64)
        for k in order:
            better = (best_k < 0) | self.better(raw[k], best)
            best = np.where(better, raw[k], best)
            best_k = np.where(better, k, best_k)
        partial = winners(_values.normalize(best, *values.value_range), best_k, steps, step_rgba)
        partial.value = best
        return partial

    def leaf_value(self, values):
        return np.asarray(values.raw[-1], dtype=np.float32)

    def leaf_value_kernel(self, value_range):
        return "leaf_raw", []

    def kernel_options(self, spec, positions, raw, given):
        lanes = raw_lanes(given.dtype, given.n_steps)
        defines = {"IS_MIN": self.is_min, "KEY_RAW": lanes is not None}
        if lanes is not None:
            defines["IDX_T"] = lanes
        return defines, {}

    def combine_kernel(self, spec):
        return "extreme", "combine_extreme", {"IS_MIN": self.is_min}

    def combine(self, front, back, spec):
        beats = self.better(back.value, front.value)
        keep = (front.t_index >= 0) & ~(beats & (back.t_index >= 0))
        return Partial(
            np.where(keep[..., None], front.rgba, back.rgba),
            np.where(keep, front.t_index, back.t_index),
            np.where(keep, front.value, back.value),
        )


class Max(Extreme):
    name = "max"
    summary = "maximum intensity through time, coloured by the step that held it"
    pool = "max"


class Min(Extreme):
    name = "min"
    summary = "minimum intensity through time, coloured by the step that held it"
    is_min = True
    pool = "min"


MAX = Max()
MIN = Min()
