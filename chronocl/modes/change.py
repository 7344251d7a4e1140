"""change: where and when a place changed most between consecutive selected steps.

δ_k = |u(s_k) - u(s_{k-1})| for consecutive selected steps (k >= 1, in time order); the
largest δ supplies the voxel, coloured by the data TF at δ and the time TF of s_k (the step
where it happened), t_index = s_k; ties go to the step integrated first. One step: nothing
changed (transparent, t_index -1). Slides by aggregation over pairs of steps: a pair is a
leaf, combined like max.
"""

from __future__ import annotations

import numpy as np

from chronocl.modes.base import Mode
from chronocl.modes.extreme import MAX, winners


class Change(Mode):
    name = "change"
    summary = "largest change between consecutive steps, coloured by when it happened"
    kernel = "change"
    kernel_function = "integrate_change"
    has_t_index = True
    state_bytes = 24
    leaf_span = 2
    compares_values = True
    lut_by_value = True  # the data TF is looked up at δ

    def accumulate(self, u, steps, order, step_rgba, spec):
        best = np.zeros(u.shape[1:], dtype=np.float32)
        best_k = np.full(u.shape[1:], -1, dtype=np.int64)
        for k in order:
            if k == 0:
                continue
            d = np.abs(u[k] - u[k - 1])
            better = (best_k < 0) | (d > best)
            best = np.where(better, d, best)
            best_k = np.where(better, k, best_k)
        return winners(best, best_k, steps, step_rgba)

    def leaf_value(self, u):
        return np.abs(u[-1] - u[-2])

    def combine(self, front, back, spec):
        return MAX.combine(front, back, spec)

    def kernel_options(self, spec, positions, raw):
        return {"TIME_ORDER": {"forward": 1, "backward": 2}.get(spec.order, 0)}, []

    def combine_kernel(self, spec):
        return "extreme", "combine_extreme", {}


MODE = Change()
