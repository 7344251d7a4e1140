"""max / min: the step holding the extreme value u supplies the voxel, coloured by its TF there.

(a c, a) at that value and that step's time position; t_index = s_k*. Ties go to the step
integrated first. Slides by aggregation: the back's winner replaces the front's only when
strictly more extreme.
"""

from __future__ import annotations

import functools

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


@functools.lru_cache(maxsize=64)
def _integer_zones(dtype: str, value_range: tuple[float, float]) -> tuple[float, float] | None:
    info = np.iinfo(dtype)
    v = np.arange(info.min, info.max + 1)
    u = _values.normalize(v, *value_range)
    zero, one = u <= 0, u >= 1
    zlo = float(v[zero].max()) if zero.any() else float(info.min) - 1
    zhi = float(v[one].min()) if one.any() else float(info.max) + 1
    middle = u[(v > zlo) & (v < zhi)]
    return (zlo, zhi) if bool(np.all(np.diff(middle) > 0)) else None


def raw_key_zones(dtype, value_range, n_steps: int) -> tuple[float, float] | None:
    """(zlo, zhi) when max/min may compare the raw values of integer data: u = 0 at or below
    zlo, u = 1 at or above zhi and u strictly increasing on the values between (so raw order is
    u's order there, ties included), and the steps fit the data's lanes (uchar: 256, 16-bit:
    65536). None otherwise: float data, or a range whose rounding merges integer values."""
    dtype = np.dtype(dtype)
    if dtype not in (np.uint8, np.uint16, np.int16) or n_steps > 2 ** (8 * dtype.itemsize):
        return None
    return _integer_zones(dtype.name, (float(value_range[0]), float(value_range[1])))


class Extreme(Mode, abstract=True):
    kernel = "extreme"
    kernel_function = "integrate_extreme"
    rows_kernel = "integrate_extreme_rows"
    rows_state = 8  # the key and the step, each in lanes of at most 4 bytes
    has_t_index = True
    state_bytes = 24
    compares_values = True
    lut_by_value = True  # built without QUANT: the LUT is interpolated at the winning u
    is_min = False

    def better(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Where value a beats value b (strictly)."""
        return a < b if self.is_min else a > b

    def accumulate(self, u, steps, order, step_rgba, spec):
        best = np.zeros(u.shape[1:], dtype=np.float32)
        best_k = np.full(u.shape[1:], -1, dtype=np.int64)
        for k in order:
            better = (best_k < 0) | self.better(u[k], best)
            best = np.where(better, u[k], best)
            best_k = np.where(better, k, best_k)
        return winners(best, best_k, steps, step_rgba)

    def leaf_value(self, values):
        return _values.normalize(values.raw[-1], *values.value_range)

    def leaf_value_kernel(self, value_range):
        return "leaf_u", list(_values.normalization(*value_range))

    def kernel_options(self, spec, positions, raw, given):
        # The kernel compares raw values where u orders them as it does (see raw_key_zones),
        # else t = (v - vmin) * scale unclamped; the zones beyond zlo and zhi tie in u.
        zones = raw_key_zones(given.dtype, given.value_range, given.n_steps)
        defines = {"IS_MIN": self.is_min, "KEY_RAW": zones is not None}
        if zones is not None:
            defines["IDX_T"] = "uchar" if given.dtype == np.uint8 else "ushort"
        zlo, zhi = zones if zones is not None else (0.0, 1.0)
        return defines, {"zlo": np.float32(zlo), "zhi": np.float32(zhi)}

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
