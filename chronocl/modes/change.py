"""change: where and when a place changed most between consecutive selected steps.

δ_k = |u(s_k) - u(s_{k-1})| for consecutive selected steps (k >= 1, in time order); the
largest δ supplies the voxel, coloured by the data TF at δ and the time TF of s_k (the step
where it happened), t_index = s_k; ties go to the step integrated first. One step: nothing
changed (transparent, t_index -1). Slides by aggregation over pairs of steps: a pair is a
leaf, combined like max.

The changes are compared as differences of the values clipped to the normalisation range,
d_k = |clip(v_k) - clip(v_{k-1})|, and only the winner is scaled, δ = min(d * scale, 1): the
same δ in exact arithmetic, but equal changes of integer data tie exactly (rounding in u
would break such ties arbitrarily), and byte data is compared in byte lanes.
"""

from __future__ import annotations

import numpy as np

from chronocl.core import values as _values
from chronocl.modes.base import Mode
from chronocl.modes.extreme import MAX, winners


class Change(Mode):
    name = "change"
    summary = "largest change between consecutive steps, coloured by when it happened"
    kernel = "change"
    kernel_function = "integrate_change"
    rows_kernel = "integrate_change_rows"
    rows_state = 12  # the previous clipped value, the largest change and its step
    has_t_index = True
    writes_winners = True
    state_bytes = 24
    leaf_span = 2
    compares_values = True
    lut_by_value = True  # the data TF is looked up at δ
    data_axis = "change"
    per_step_tf = False
    reads_values = True

    def accumulate(self, u, steps, order, step_rgba, spec, values):
        c = _values.clip(values.raw, *values.value_range)
        best = np.zeros(u.shape[1:], dtype=np.float32)
        best_k = np.full(u.shape[1:], -1, dtype=np.int64)
        for k in order:
            if k == 0:
                continue
            d = np.abs(c[k] - c[k - 1])
            better = (best_k < 0) | (d > best)
            best = np.where(better, d, best)
            best_k = np.where(better, k, best_k)
        partial = winners(self.delta(best, values.value_range), best_k, steps, step_rgba)
        partial.value = best
        return partial

    @staticmethod
    def delta(d: np.ndarray, value_range: tuple[float, float]) -> np.ndarray:
        """δ of clipped differences d: in u units, at most 1."""
        _, scale = _values.normalization(*value_range)
        return np.minimum(d * scale, np.float32(1.0))

    def leaf_value(self, values):
        c = _values.clip(values.raw[-2:], *values.value_range)
        return np.abs(c[1] - c[0])

    def leaf_value_kernel(self, value_range):
        return "leaf_change", list(_values.clip_bounds(*value_range))

    def combine(self, front, back, spec):
        return MAX.combine(front, back, spec)

    def kernel_options(self, spec, positions, raw, given):
        order = {"forward": 1, "backward": 2}.get(spec.order, 0)
        lo, hi = _values.clip_bounds(*given.value_range)
        # Bytes clipped to whole-number bounds stay whole: compare them in byte lanes.
        whole = all(b == np.floor(b) for b in (np.clip(lo, 0, 255), np.clip(hi, 0, 255)))
        as_bytes = given.dtype == np.uint8 and whole and given.n_steps <= 255
        defines = {"TIME_ORDER": order, "CHANGE_BYTES": bool(order and as_bytes)}
        return defines, {"lo": lo, "hi": hi}

    def combine_kernel(self, spec):
        return "extreme", "combine_extreme", {}


MODE = Change()
