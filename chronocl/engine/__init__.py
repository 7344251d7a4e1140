"""Integration engines: ``numpy`` (the reference) and ``opencl`` (PoCL on CPUs, any GPU driver).

An engine integrates one xytz brick (rows, W, Y, X) into that slab's part of
the chronovolume; `chronocl.integrate` streams the bricks.
"""

from __future__ import annotations

import numpy as np

from chronocl import reference
from chronocl.core import values
from chronocl.core.errors import UnknownNameError
from chronocl.modes.spec import IntegrationSpec
from chronocl.reference import Partial

ENGINES = ("opencl", "numpy")


class NumpyEngine:
    """The reference integrator behind the engine interface."""

    name = "numpy"
    max_brick_bytes = 64 * 2**20

    def accumulate(
        self,
        brick: np.ndarray,
        crop: slice,
        steps,
        positions: np.ndarray,
        order: np.ndarray,
        spec: IntegrationSpec,
        value_range: tuple[float, float],
        out: tuple[np.ndarray, np.ndarray | None] | None = None,
    ) -> tuple[Partial, bool]:
        u = values.normalize(np.moveaxis(brick, 1, 0), *value_range)
        partial = reference.accumulate(u, steps, positions, order, spec)
        rgba = partial.rgba[crop]
        t_index = None if partial.t_index is None else partial.t_index[crop]
        if out is not None:
            out[0][...] = rgba
            if t_index is not None:
                out[1][...] = t_index
            rgba, t_index = out[0], (out[1] if t_index is not None else None)
        return Partial(rgba, t_index), False

    def combine(self, front: Partial, back: Partial, spec: IntegrationSpec) -> Partial:
        """The partial of `front` then `back` (reference.combine)."""
        return reference.combine(front, back, spec)

    def fixed_add(self, acc: np.ndarray, rgba: np.ndarray, sign: int) -> None:
        """acc (Z, Y, X, 3) int64 += sign * fixed-point colour sums of one additive partial."""
        fixed = np.trunc(np.asarray(rgba[..., :3], np.float64) * FIXED_ONE).astype(np.int64)
        acc += fixed if sign > 0 else -fixed

    def fixed_finalize(self, acc: np.ndarray, alpha: np.ndarray, norm: np.ndarray) -> np.ndarray:
        """The finished additive RGBA from fixed-point sums, window opacity and norm (3,)."""
        rgba = np.empty((*alpha.shape, 4), np.float64)
        rgba[..., :3] = acc / FIXED_ONE
        rgba[..., 3] = alpha
        return reference.finalize_sums(rgba, norm)


FIXED_ONE = float(2**40)  # additive colour sums in fixed point: exact add / subtract

_engines: dict[tuple[str, str | None], object] = {}


def get_engine(name: str = "opencl", device: str | None = None):
    """A cached engine by name (the OpenCL one per device)."""
    if name not in ENGINES:
        raise UnknownNameError(f"unknown engine {name!r}; choose one of {', '.join(ENGINES)}")
    key = (name, device)
    if key not in _engines:
        if name == "numpy":
            _engines[key] = NumpyEngine()
        else:
            from chronocl.engine.opencl import OpenCLEngine

            _engines[key] = OpenCLEngine(device)
    return _engines[key]
