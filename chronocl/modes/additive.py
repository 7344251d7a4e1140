"""additive: colours summed through time and normalised; opacity is the largest one.

C = Σ a_k c_k divided per channel by N (``time``: N = Σ a_t(p_k) rgb_t(p_k); ``max``: the
volume's largest channel value) and clamped to A = max a_k. Slides by inversion: the colour
sums are kept in fixed point, so a step that leaves subtracts exactly what it added; the
opacity (a maximum) slides by aggregation. Normalised by "max", a window whose largest sum is
too faint for the fixed point's precision (`FaintSums`: an all but black or transparent window)
is not finished from its sums: a session integrates it instead.
"""

from __future__ import annotations

import numpy as np

from chronocl.modes.base import FIXED_ONE, FaintSums, Mode, Partial, faint_below


def additive_norm(spec, positions: np.ndarray) -> np.ndarray:
    """N = Σ_k a_t(p_k)·rgb_t(p_k), per channel (3,)."""
    rgb_t, a_t = spec.time_tf.evaluate(positions)
    return (a_t[:, None] * rgb_t).sum(axis=0)


def finalize_sums(sums: np.ndarray, norm: np.ndarray) -> np.ndarray:
    """Colour sums / norm per channel (0 where norm is 0), clamped to the opacity.

    Arithmetic stays in the dtypes given (float32 sums over a float32 norm divide in float32),
    so every path that finalises the same sums gets the same bits.
    """
    rgba = np.array(sums, copy=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled = np.where(norm > 0, rgba[..., :3] / np.where(norm > 0, norm, 1.0), 0.0)
    rgba[..., :3] = np.minimum(scaled, rgba[..., 3:4])
    return rgba.astype(np.float32, copy=False)


class Additive(Mode):
    name = "additive"
    summary = "additive colours through time, normalised (white where all steps overlap)"
    kernel = "additive"
    kernel_function = "integrate_additive"
    rows_kernel = "integrate_additive_rows"
    rows_state = 16
    slides = "invert"
    state_bytes = 4  # the opacity slides by aggregation (a maximum)
    sum_channels = 3  # the colour sums, in fixed point

    def accumulate(self, u, steps, order, step_rgba, spec):
        rgba = np.zeros((*u.shape[1:], 4), dtype=np.float64)
        for k in order:
            c, a = step_rgba(k)
            rgba[..., :3] += a[..., None] * c
            rgba[..., 3] = np.maximum(rgba[..., 3], a)
        return Partial(rgba, None)

    def combine(self, front, back, spec):
        # Sliding partials hold the opacity alone (colour sums are kept apart, exactly).
        return Partial(np.maximum(front.rgba, back.rgba), None)

    def finalize(self, partial, positions, spec):
        rgba = partial.rgba
        if spec.normalize == "time":
            norm = additive_norm(spec, positions)
        else:
            norm = np.full(3, rgba[..., :3].max() if rgba.size else 0.0)
        return finalize_sums(rgba, norm)

    def finalize_is_global(self, spec):
        return spec.normalize == "max"

    def norm(self, spec, positions: np.ndarray, sums: np.ndarray) -> np.ndarray:
        """The per-channel divisor: the time TF's N, or the largest colour sum in `sums`."""
        if spec.normalize == "time":
            return additive_norm(spec, positions)
        return np.full(3, float(sums.max()) if sums.size else 0.0)

    def _finish_norm(self, spec, positions: np.ndarray, sums: np.ndarray) -> np.ndarray:
        """`norm` for a window finished from its fixed-point sums; `FaintSums` where its largest
        sum (normalised by "max") is too faint for their precision."""
        norm = self.norm(spec, positions, sums)
        if spec.normalize == "max" and norm[0] < faint_below(len(positions)):
            raise FaintSums(f"the largest colour sum {norm[0]:.3g} is too faint to slide")
        return norm

    def finish_sums(self, sums, alpha, positions, spec):
        norm = self._finish_norm(spec, positions, sums)
        rgba = np.empty((*alpha.shape, 4), np.float64)
        rgba[..., :3] = sums
        rgba[..., 3] = alpha
        return finalize_sums(rgba, norm)

    def combine_kernel(self, spec):
        return "additive", "combine_fmax", {}

    def finish_kernel(self, acc, positions, spec):
        # the largest sum, read from the device, only where it is the divisor
        largest = float(acc.max()) / FIXED_ONE if acc.size and spec.normalize == "max" else 0.0
        norm = self._finish_norm(spec, positions, np.array([largest]))
        return "finish_additive", {}, [], [np.array([*norm, 0.0], dtype=np.float32)]

    def kernel_options(self, spec, positions, raw, given):
        norm = additive_norm(spec, positions)
        final = spec.normalize == "time" and not raw
        return {"NORM_TIME": final}, {"norm": np.array([*norm, 0.0], dtype=np.float32)}


MODE = Additive()
