"""The numpy reference integrator: dead simple, every mode, the oracle that tests compare with.

Input is the window's normalised values u (W, Z, Y, X) in [0, 1]; output is
premultiplied RGBA (Z, Y, X, 4) and, for first_hit / max / min, the step that
supplied each voxel (t_index, -1 where none). Each mode is one loop over the
steps in integration order, written as in DESIGN.md section 2. Work is split in
two: `accumulate` is per voxel (so it may run on z-slabs with a gradient halo)
and `finalize` is the global step (additive normalisation).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from chronocl.core import enhance as _enhance
from chronocl.core.tf import lut_lerp32
from chronocl.modes.spec import IntegrationSpec


@dataclass
class Partial:
    """Per-voxel result before finalisation. For additive, rgb holds the raw sums Σ α·c.

    `value` is max/min's winning normalised value u, which combining two partials needs.
    """

    rgba: np.ndarray
    t_index: np.ndarray | None
    value: np.ndarray | None = None


def over(front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """Premultiplied `over`: front composited in front of back."""
    return front + (1.0 - front[..., 3:4]) * back


def additive_norm(spec: IntegrationSpec, positions: np.ndarray) -> np.ndarray:
    """N = Σ_k a_t(p_k)·rgb_t(p_k), per channel (3,)."""
    rgb_t, a_t = spec.time_tf.evaluate(positions)
    return (a_t[:, None] * rgb_t).sum(axis=0)


def accumulate(
    u: np.ndarray,
    steps: Sequence[int],
    positions: np.ndarray,
    order: np.ndarray,
    spec: IntegrationSpec,
) -> Partial:
    """Integrate u (W, Z, Y, X) over the steps in `order` (indices into the selection)."""
    w = u.shape[0]
    shape = u.shape[1:]
    lut = spec.data_tf.lut
    rgb_t, a_t = spec.time_tf.evaluate(positions)

    def step_rgba(k: int) -> tuple[np.ndarray, np.ndarray]:
        # Opacity in float32 in the kernels' order, so thresholds decide alike everywhere.
        d = lut_lerp32(lut, u[k])
        e = (
            np.float32(1.0)
            if spec.enhance.kind == "none"
            else (np.asarray(_enhance.factor(u[k], spec.enhance), dtype=np.float32))
        )
        colour = d[..., :3].astype(np.float64) * rgb_t[k]
        alpha = np.clip(d[..., 3] * np.float32(a_t[k]) * e, np.float32(0.0), np.float32(1.0))
        return colour, alpha.astype(np.float64)

    rgba = np.zeros((*shape, 4), dtype=np.float64)
    t_index = np.full(shape, -1, dtype=np.int32) if spec.has_t_index else None
    assert len(steps) == w and len(order) == w

    if spec.mode == "alpha":
        for k in order:
            c, a = step_rgba(k)
            trans = 1.0 - rgba[..., 3]
            rgba[..., :3] += (trans * a)[..., None] * c
            rgba[..., 3] += trans * a
    elif spec.mode == "first_hit":
        for k in order:
            c, a = step_rgba(k)
            hit = (t_index < 0) & (a > spec.threshold)
            rgba[hit, :3] = a[hit, None] * c[hit]
            rgba[hit, 3] = a[hit]
            t_index[hit] = steps[k]
    elif spec.mode == "additive":
        for k in order:
            c, a = step_rgba(k)
            rgba[..., :3] += a[..., None] * c
            rgba[..., 3] = np.maximum(rgba[..., 3], a)
    elif spec.mode in ("max", "min"):
        best = np.zeros(shape, dtype=np.float32)
        best_k = np.full(shape, -1, dtype=np.int64)
        for k in order:
            better = best_k < 0
            better |= u[k] > best if spec.mode == "max" else u[k] < best
            best = np.where(better, u[k], best)
            best_k = np.where(better, k, best_k)
        for k in range(w):
            sel = best_k == k
            if sel.any():
                c, a = step_rgba(k)
                rgba[sel, :3] = a[sel, None] * c[sel]
                rgba[sel, 3] = a[sel]
                t_index[sel] = steps[k]
        return Partial(rgba, t_index, best)
    else:  # pragma: no cover - IntegrationSpec validates the mode
        raise AssertionError(spec.mode)
    return Partial(rgba, t_index)


def combine(front: Partial, back: Partial, spec: IntegrationSpec) -> Partial:
    """The partial of two consecutive runs of steps, `front` integrated before `back`.

    Associative for every mode, which is what sliding a window needs (DESIGN.md 3):
    alpha is `over`; first_hit keeps the front's hit where it has one; max/min keep the
    front's winner unless the back's value is strictly more extreme (ties go to the step
    integrated first, as in `accumulate`). Additive partials hold opacity alone (the colour
    sums are kept apart, exactly, in fixed point): the larger opacity.
    """
    if spec.mode == "alpha":
        return Partial(over(front.rgba, back.rgba), None)
    if spec.mode == "additive":
        return Partial(np.maximum(front.rgba, back.rgba), None)
    if spec.mode == "first_hit":
        keep = front.t_index >= 0
    else:
        beats = back.value > front.value if spec.mode == "max" else back.value < front.value
        keep = (front.t_index >= 0) & ~(beats & (back.t_index >= 0))
    value = None if front.value is None else np.where(keep, front.value, back.value)
    return Partial(
        np.where(keep[..., None], front.rgba, back.rgba),
        np.where(keep, front.t_index, back.t_index),
        value,
    )


def finalize(partial: Partial, positions: np.ndarray, spec: IntegrationSpec) -> np.ndarray:
    """Global last step; returns premultiplied RGBA float32. Only additive does work here."""
    rgba = partial.rgba
    if spec.mode == "additive":
        if spec.normalize == "time":
            norm = additive_norm(spec, positions)
        else:
            norm = np.full(3, rgba[..., :3].max() if rgba.size else 0.0)
        return finalize_sums(rgba, norm)
    return rgba.astype(np.float32, copy=False)


def finalize_sums(sums: np.ndarray, norm: np.ndarray) -> np.ndarray:
    """Additive: colour sums / norm per channel (0 where norm is 0), clamped to the opacity.

    Arithmetic stays in the dtypes given (float32 sums over a float32 norm divide in float32),
    so every path that finalises the same sums gets the same bits.
    """
    rgba = np.array(sums, copy=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled = np.where(norm > 0, rgba[..., :3] / np.where(norm > 0, norm, 1.0), 0.0)
    rgba[..., :3] = np.minimum(scaled, rgba[..., 3:4])
    return rgba.astype(np.float32, copy=False)


def integrate(
    u: np.ndarray,
    steps: Sequence[int],
    positions: np.ndarray,
    order: np.ndarray,
    spec: IntegrationSpec,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Whole-volume integration: (premultiplied RGBA float32 (Z, Y, X, 4), t_index or None)."""
    partial = accumulate(u, steps, positions, order, spec)
    return finalize(partial, positions, spec), partial.t_index
