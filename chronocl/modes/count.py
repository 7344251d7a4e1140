"""count (occupancy): the fraction of selected steps whose opacity exceeds the threshold.

f = n / W with n = #{k : a_k > threshold}; the voxel shows the data TF at f (its colour ramp
and opacity, premultiplied), so "present all the time" and "present once" read apart.
Slides by inversion: n is summed exactly.
"""

from __future__ import annotations

import numpy as np

from chronocl.core.tf import lut_lerp32
from chronocl.modes.base import Mode, Partial


class Count(Mode):
    name = "count"
    summary = "occupancy: fraction of steps above the opacity threshold, via the data TF"
    opacity_threshold = True
    kernel = "count"
    kernel_function = "integrate_count"
    rows_kernel = "integrate_count_rows"
    rows_state = 4
    slides = "invert"
    state_bytes = 0
    sum_channels = 1
    lut_by_value = True  # the data TF is looked up at the fraction f
    per_step_tf = False
    legend = "fraction"

    def accumulate(self, u, steps, order, step_rgba, spec):
        rgba = np.zeros((*u.shape[1:], 4), dtype=np.float64)
        for k in order:
            _, a = step_rgba(k)
            rgba[..., 0] += a > spec.threshold
        return Partial(rgba, None)

    def finalize(self, partial, positions, spec):
        return self.finish_sums(partial.rgba[..., :1], None, positions, spec)

    def finish_sums(self, sums, alpha, positions, spec):
        w = np.float32(max(1, len(positions)))
        f = np.asarray(sums[..., 0], np.float32) / w
        d = lut_lerp32(spec.data_tf.lut, f).astype(np.float32)
        return np.concatenate([d[..., :3] * d[..., 3:4], d[..., 3:4]], axis=-1)

    def kernel_options(self, spec, positions, raw, given):
        return {}, [np.float32(spec.threshold)]

    def finish_kernel(self, acc, positions, spec):
        lut = np.ascontiguousarray(spec.data_tf.lut.T, dtype=np.float32)
        return "finish_count", {"LUT_N": lut.shape[1]}, [lut], [np.float32(max(1, len(positions)))]


MODE = Count()
