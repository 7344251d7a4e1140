"""first_hit: the first step in the order whose opacity exceeds the threshold supplies the voxel.

(a_k c_k, a_k) and t_index = s_k; none: (0, 0, 0, 0) and -1. Slides by aggregation: the
front's hit wins where it has one.
"""

from __future__ import annotations

import numpy as np

from chronocl.modes.base import Mode, Partial


class FirstHit(Mode):
    name = "first_hit"
    summary = "first temporal hit above the opacity threshold, with the step that made it"
    opacity_threshold = True
    kernel = "first_hit"
    kernel_function = "integrate_first_hit"
    rows_kernel = "integrate_first_hit_rows"
    rows_state = 8
    has_t_index = True
    state_bytes = 20

    def accumulate(self, u, steps, order, step_rgba, spec):
        shape = u.shape[1:]
        rgba = np.zeros((*shape, 4), dtype=np.float64)
        t_index = np.full(shape, -1, dtype=np.int32)
        for k in order:
            c, a = step_rgba(k)
            hit = (t_index < 0) & (a > spec.threshold)
            rgba[hit, :3] = a[hit, None] * c[hit]
            rgba[hit, 3] = a[hit]
            t_index[hit] = steps[k]
        return Partial(rgba, t_index)

    def combine_kernel(self, spec):
        return "first_hit", "combine_first", {}

    def kernel_options(self, spec, positions, raw, given):
        return {}, {"threshold": np.float32(spec.threshold)}

    def combine(self, front, back, spec):
        keep = front.t_index >= 0
        return Partial(
            np.where(keep[..., None], front.rgba, back.rgba),
            np.where(keep, front.t_index, back.t_index),
        )


MODE = FirstHit()
