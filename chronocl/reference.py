"""The numpy reference integrator: dead simple, every mode, the oracle that tests compare with.

Input is the window's normalised values u (W, Z, Y, X) in [0, 1]; output is
premultiplied RGBA (Z, Y, X, 4) and, for modes that have one, the step that
supplied each voxel (t_index, -1 where none). Each mode's loop over the steps in
integration order lives in its module under `chronocl.modes` (docs/semantics.md);
this module gives every mode the same per-step colour and opacity. Work is split
in two: `accumulate` is per voxel (so it may run on z-slabs with a gradient halo)
and `finalize` is the global step (e.g. additive normalisation).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from chronocl.core import enhance as _enhance
from chronocl.core.tf import lut_lerp32
from chronocl.modes.additive import additive_norm, finalize_sums
from chronocl.modes.alpha import over
from chronocl.modes.base import Partial, Values
from chronocl.modes.spec import IntegrationSpec

__all__ = [
    "accumulate",
    "additive_norm",
    "combine",
    "finalize",
    "finalize_sums",
    "integrate",
    "over",
]


def accumulate(
    u: np.ndarray,
    steps: Sequence[int],
    positions: np.ndarray,
    order: np.ndarray,
    spec: IntegrationSpec,
    values: Values | None = None,
) -> Partial:
    """Integrate u (W, Z, Y, X) over the steps in `order` (indices into the selection).

    `values` are the raw values u came from, for modes that compare them (`reads_values`);
    without them u stands for the values, with the range (0, 1).
    """
    assert len(steps) == u.shape[0] and len(order) == u.shape[0]
    lut = spec.data_tf.lut
    rgb_t, a_t = spec.time_tf.evaluate(positions)

    def step_rgba(k: int, at: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        # Opacity in float32 in the kernels' order, so thresholds decide alike everywhere.
        d = lut_lerp32(lut, u[k] if at is None else at)
        e = (
            np.float32(1.0)
            if spec.enhance.kind == "none"
            else (np.asarray(_enhance.factor(u[k], spec.enhance), dtype=np.float32))
        )
        colour = d[..., :3].astype(np.float64) * rgb_t[k]
        alpha = np.clip(d[..., 3] * np.float32(a_t[k]) * e, np.float32(0.0), np.float32(1.0))
        return colour, alpha.astype(np.float64)

    mode = spec.integration
    if mode.reads_values:
        given = values if values is not None else Values(u)
        return mode.accumulate(u, steps, order, step_rgba, spec, values=given)
    return mode.accumulate(u, steps, order, step_rgba, spec)


def combine(front: Partial, back: Partial, spec: IntegrationSpec) -> Partial:
    """The partial of two consecutive runs of steps, `front` integrated before `back`.

    Associative for every mode that aggregates (`Combines`), which is what sliding a window
    needs (docs/semantics.md).
    """
    return spec.integration.combine(front, back, spec)


def finalize(partial: Partial, positions: np.ndarray, spec: IntegrationSpec) -> np.ndarray:
    """Global last step; returns premultiplied RGBA float32."""
    return spec.integration.finalize(partial, positions, spec)


def integrate(
    u: np.ndarray,
    steps: Sequence[int],
    positions: np.ndarray,
    order: np.ndarray,
    spec: IntegrationSpec,
    values: Values | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Whole-volume integration: (premultiplied RGBA float32 (Z, Y, X, 4), t_index or None)."""
    partial = accumulate(u, steps, positions, order, spec, values)
    return finalize(partial, positions, spec), partial.t_index
