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
    # With no TF given: a voxel is present where its opacity exceeds 0.25, i.e. its value lies
    # above about 17 % of the window's fitted range, and f shows through an occupancy ramp
    # (purple once, teal about a quarter of the time, yellow always), translucent enough
    # (0.15 to 0.5) that the always-present core shows through the rest.
    default_data_points = (
        (0.0, 0.55, 0.25, 0.85, 0.0),
        (0.02, 0.55, 0.25, 0.85, 0.15),
        (0.25, 0.1, 0.75, 0.7, 0.3),
        (1.0, 1.0, 0.9, 0.1, 0.5),
    )
    default_threshold = 0.25

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
        return {}, {"threshold": np.float32(spec.threshold)}

    def finish_kernel(self, acc, positions, spec):
        lut = np.ascontiguousarray(spec.data_tf.lut.T, dtype=np.float32)
        return "finish_count", {"LUT_N": lut.shape[1]}, [lut], [np.float32(max(1, len(positions)))]


MODE = Count()
