"""mean: the time average of the premultiplied colour and opacity over the window.

RGBA = (1/W) Σ_k (a_k c_k, a_k). Slides by inversion: the four sums are kept in fixed point,
so a step that leaves subtracts exactly what it added; the window divides by W once.
"""

from __future__ import annotations

import numpy as np

from chronocl.modes.base import Mode, Partial


class Mean(Mode):
    name = "mean"
    summary = "time average of the premultiplied colour and opacity over the window"
    kernel = "mean"
    kernel_function = "integrate_mean"
    rows_kernel = "integrate_mean_rows"
    rows_state = 16
    slides = "invert"
    state_bytes = 0
    sum_channels = 4

    def accumulate(self, u, steps, order, step_rgba, spec):
        rgba = np.zeros((*u.shape[1:], 4), dtype=np.float64)
        for k in order:
            c, a = step_rgba(k)
            rgba[..., :3] += a[..., None] * c
            rgba[..., 3] += a
        return Partial(rgba, None)

    def finalize(self, partial, positions, spec):
        return self.finish_sums(partial.rgba, None, positions, spec)

    def finish_sums(self, sums, alpha, positions, spec):
        w = max(1, len(positions))
        return (np.asarray(sums, np.float64) / w).astype(np.float32)

    def finish_kernel(self, acc, positions, spec):
        return "finish_mean", {}, [], [np.float32(1.0 / max(1, len(positions)))]


MODE = Mean()
