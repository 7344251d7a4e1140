"""The contract every integration engine keeps (the numpy reference and OpenCL alike).

An engine integrates one xytz brick (rows, W, Y, X) into that slab's part of a chronovolume,
combines the partials of adjacent runs of steps (for windows that slide by aggregation), and
keeps the fixed-point sums of windows that slide by inversion (docs/semantics.md). The OpenCL
engine's combine, fixed_add and finish_sums also take device arrays (a sliding state kept on a
GPU: `chronocl.engine.elementwise`). It also gathers each voxel's winner of an integrated
window from its steps, for a TF edit that only recolours (`chronocl.engine.gather`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from chronocl.modes.base import FIXED_ONE, Partial
from chronocl.modes.spec import IntegrationSpec

__all__ = ["FIXED_ONE", "Engine"]


class Engine(Protocol):
    """What an engine does and declares. Its capabilities are attributes every engine sets (no
    caller guesses them with `getattr`: tests/test_layers.py): where it reads a window's host
    steps, whether its steps travel to a device, what its kernels write, and the format its
    bricks travel in; an engine of one's own sets them too."""

    name: str
    # reads a window's host slots where they lie (a `SlotBrick` unstacked): a CPU device's
    # host pointers; else the brick is stacked (numpy) or copied (a GPU)
    reads_in_place: bool
    # its steps travel to a device (a GPU, or a CPU device without host pointers): they may be
    # kept there (`chronocl.engine.device_steps.DeviceWindow`)
    copies_to_device: bool
    # a uint8 `out` of `accumulate` gets the display format, RGBA8 (kernels/opencl/common.h)
    writes_display: bool
    # `accumulate` takes winners' outputs (u, k) for a mode that `writes_winners`
    writes_winners: bool
    device_format: str  # what bricks travel in (`chronocl.engine.device_formats`)

    @property
    def max_brick_bytes(self) -> int:
        """Largest brick one call may be given."""
        ...

    def accumulate(
        self,
        brick: np.ndarray,
        crop: slice,
        steps: Sequence[int],
        positions: np.ndarray,
        order: np.ndarray,
        spec: IntegrationSpec,
        value_range: tuple[float, float],
        out: tuple[np.ndarray, np.ndarray | None] | None = None,
        raw: bool = False,
    ) -> tuple[Partial, bool]:
        """Integrate brick rows `crop`; returns the partial and whether it is finished.

        `raw` asks for the mode's raw partial (what is summed or combined before finishing).
        """
        ...

    def combine(
        self, front: Partial, back: Partial, spec: IntegrationSpec, rgba8: bool = False
    ) -> Partial:
        """The partial of `front` then `back` (new arrays; the inputs are kept); with `rgba8`
        (an engine that `writes_display`, a final value) its colour as display RGBA8."""
        ...

    def fixed_add(self, acc: np.ndarray, rgba: np.ndarray, sign: int) -> None:
        """acc (Z, Y, X, C) int64 += sign * fixed(first C channels of a raw partial)."""
        ...

    def finish_sums(
        self,
        acc: np.ndarray,
        alpha: np.ndarray | None,
        positions: np.ndarray,
        spec: IntegrationSpec,
    ) -> np.ndarray:
        """The finished RGBA float32 of a window kept as fixed-point sums (and, for modes
        that aggregate their opacity, that opacity)."""
        ...

    def gather(
        self,
        t_index: np.ndarray,
        arrays: dict[int, np.ndarray],
        steps: tuple[int, ...],
        value_range: tuple[float, float],
        change: bool,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each voxel's winner of an integrated window (max, min, first_hit, change) from its
        t_index and the window's raw resident values (step -> (Z, Y, X)): the value it won
        with normalised to `value_range` (float32 u; `change`: the change) and its step's
        place in `steps` (k; the dtype's largest: none), as `chronocl.engine.gather` says."""
        ...
