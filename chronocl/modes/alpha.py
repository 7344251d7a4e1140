"""alpha: compositing through time, the first step in the order in front (`over`, premultiplied).

C += (1 - A) a_k c_k, A += (1 - A) a_k. Slides by aggregation: `over` is associative but
cannot take a step back out.
"""

from __future__ import annotations

import numpy as np

from chronocl.modes.base import Mode, Partial


def over(front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """Premultiplied `over`: front composited in front of back."""
    return front + (1.0 - front[..., 3:4]) * back


class Alpha(Mode):
    name = "alpha"
    summary = "alpha compositing through time (front to back in the order)"
    kernel = "alpha"
    kernel_function = "integrate_alpha"
    rows_kernel = "integrate_alpha_rows"
    rows_state = 16
    state_bytes = 16

    def accumulate(self, u, steps, order, step_rgba, spec):
        rgba = np.zeros((*u.shape[1:], 4), dtype=np.float64)
        for k in order:
            c, a = step_rgba(k)
            trans = 1.0 - rgba[..., 3]
            rgba[..., :3] += (trans * a)[..., None] * c
            rgba[..., 3] += trans * a
        return Partial(rgba, None)

    def combine(self, front, back, spec):
        return Partial(over(front.rgba, back.rgba), None)

    def combine_kernel(self, spec):
        return "alpha", "combine_over", {}


MODE = Alpha()
