"""The numpy engine: the reference integrator (chronocl.reference) behind the engine contract."""

from __future__ import annotations

import numpy as np

from chronocl import reference
from chronocl.core import values
from chronocl.core.errors import InvalidParameterError
from chronocl.engine.base import FIXED_ONE
from chronocl.engine.gather import on_host
from chronocl.modes.base import Partial, Values
from chronocl.modes.spec import IntegrationSpec


class NumpyEngine:
    """Slow and plain: the oracle every fast path is tested against."""

    name = "numpy"
    max_brick_bytes = 64 * 2**20
    reads_in_place = False  # a SlotBrick is stacked
    copies_to_device = False
    writes_display = False
    writes_winners = False  # the viewer gathers them (chronocl.integration.interactive.winners)
    device_format = "auto"

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
        raw: bool = False,
    ) -> tuple[Partial, bool]:
        window = np.moveaxis(np.asarray(brick), 1, 0)  # a SlotBrick stacked
        u = values.normalize(window, *value_range)
        raw_values = Values(window, value_range)
        partial = reference.accumulate(u, steps, positions, order, spec, raw_values)
        rgba = partial.rgba[crop]
        t_index = None if partial.t_index is None else partial.t_index[crop]
        if out is not None:
            out[0][...] = rgba
            if t_index is not None:
                out[1][...] = t_index
            rgba, t_index = out[0], (out[1] if t_index is not None else None)
        return Partial(rgba, t_index), False

    def combine(
        self, front: Partial, back: Partial, spec: IntegrationSpec, rgba8: bool = False
    ) -> Partial:
        if rgba8:  # (it does not write the display format: no session asks it to)
            raise InvalidParameterError("the numpy engine combines in float32 only")
        return reference.combine(front, back, spec)

    def fixed_add(self, acc: np.ndarray, rgba: np.ndarray, sign: int) -> None:
        c = acc.shape[-1]
        fixed = np.trunc(np.asarray(rgba[..., :c], np.float64) * FIXED_ONE).astype(np.int64)
        acc += fixed if sign > 0 else -fixed

    def finish_sums(
        self,
        acc: np.ndarray,
        alpha: np.ndarray | None,
        positions: np.ndarray,
        spec: IntegrationSpec,
    ) -> np.ndarray:
        return spec.integration.finish_sums(acc / FIXED_ONE, alpha, positions, spec)

    def gather(self, t_index, arrays, steps, value_range, change: bool):
        return on_host(t_index, arrays, steps, value_range, change)
