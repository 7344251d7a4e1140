"""What a mode is: the interface every integration mode implements, and the partial result.

A mode owns everything about one way of integrating a window through time (see
docs/semantics.md): its numpy reference (`accumulate` over the steps in order, `combine` of
two consecutive runs, `finalize`), how a sliding window keeps its state (by aggregation of
partials, or by adding and subtracting steps exactly: ``invert``), the partial volume's size
per voxel, and its OpenCL kernel file ``kernels/opencl/<kernel>.cl`` (integrate and combine
kernels together). The registry in `chronocl.modes` lists the modes; nothing else names one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

if TYPE_CHECKING:
    from chronocl.modes.spec import IntegrationSpec

FIXED_ONE = float(2**40)  # sums of inverting modes in fixed point: exact add and subtract

# One step's colour and opacity: (step k, values (default: u of step k)) -> (colour (..., 3)
# float64, opacity (...) float64), the data TF taken at the values, the time TF at step k.
StepRGBA = Callable[..., tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Values:
    """The raw values of a window (W, Z, Y, X) and the range that normalises them to u.

    Tests may integrate u directly; then the values are u and the range is (0, 1).
    """

    raw: np.ndarray
    value_range: tuple[float, float] = (0.0, 1.0)


@dataclass(frozen=True)
class KernelInput:
    """What a mode's kernel options may depend on beyond the spec: the device data type,
    the number of steps in the brick and the normalisation range."""

    dtype: np.dtype
    n_steps: int
    value_range: tuple[float, float]


@dataclass
class Partial:
    """Per-voxel result before finalisation.

    `rgba` is premultiplied RGBA (a mode that finalises globally keeps its raw sums there),
    `t_index` the selected step that supplied the voxel (-1: none) for modes that have one,
    and `value` what `combine` needs beyond the colour (max/min: the winning value u).
    """

    rgba: np.ndarray
    t_index: np.ndarray | None
    value: np.ndarray | None = None


class Mode:
    """One integration mode. Subclasses set the class attributes and the reference methods."""

    name: ClassVar[str]
    summary: ClassVar[str]  # one line for the CLI help, the viewer and the docs
    kernel: ClassVar[str]  # stem of its file in kernels/opencl/
    kernel_function: ClassVar[str]  # the integrate kernel in that file
    has_t_index: ClassVar[bool] = False
    slides: ClassVar[str] = "aggregate"  # "aggregate" partials, or "invert" (add/subtract)
    state_bytes: ClassVar[int] = 16  # bytes per voxel of one aggregated partial volume
    sum_channels: ClassVar[int] = 0  # "invert": leading RGBA channels kept as fixed-point sums
    leaf_span: ClassVar[int] = 1  # consecutive steps one sliding leaf integrates (ending at it)
    compares_values: ClassVar[bool] = False  # combine needs `leaf_value` in Partial.value
    lut_by_value: ClassVar[bool] = False  # looks the data TF up at a derived value, not v
    # compares a step's opacity with the threshold: the kernels keep the LUT's exact opacity
    opacity_threshold: ClassVar[bool] = False
    legend: ClassVar[str] = "time"  # what colour tells: "time", or "fraction" of the steps
    # what the data TF is looked up at, as its colour bar names it: the "value", or the
    # "change" between steps (δ, in units of the value range; chronocl.render.colorbar)
    data_axis: ClassVar[str] = "value"
    # each step's voxels are coloured by the data TF at their own values, so a step whose
    # values all fall where the TF is transparent cannot show (chronocl.integration.visibility)
    per_step_tf: ClassVar[bool] = True
    reads_values: ClassVar[bool] = False  # `accumulate` also takes `values=` (Values)
    # CPU devices: a kernel in the same file taking a block of rows per work-item, the steps
    # in the outer loop (chronocl/engine/opencl.py `_row_blocks`), and the bytes per voxel of
    # the state it keeps in local memory; None: the per-vector kernel only
    rows_kernel: ClassVar[str | None] = None
    rows_state: ClassVar[int] = 0
    # The coarse levels a mode integrates (docs/levels.md): "mean" for modes that show the
    # whole field; max/min take levels pooled alike, so a thin peak or trough survives.
    pool: ClassVar[str] = "mean"

    # -- the numpy reference -------------------------------------------------------------
    def accumulate(
        self,
        u: np.ndarray,
        steps: Sequence[int],
        order: np.ndarray,
        step_rgba: StepRGBA,
        spec: IntegrationSpec,
    ) -> Partial:
        """Integrate u (W, Z, Y, X) over the steps in `order` (indices into the selection).

        A mode with `reads_values` is also given ``values=`` (`Values`): the raw window.
        """
        raise NotImplementedError

    def combine(self, front: Partial, back: Partial, spec: IntegrationSpec) -> Partial:
        """The partial of two consecutive runs of steps, `front` integrated first."""
        raise NotImplementedError

    def finalize(
        self, partial: Partial, positions: np.ndarray, spec: IntegrationSpec
    ) -> np.ndarray:
        """The finished premultiplied RGBA float32 of a whole window."""
        return partial.rgba.astype(np.float32, copy=False)

    def finalize_is_global(self, spec: IntegrationSpec) -> bool:
        """Whether finishing needs the whole volume (e.g. a normalisation by its maximum).

        Such a mode may depend on the rest of the volume only through the per-channel maxima
        of its raw partial: out-of-core runs record those per slab and finish each chunk
        with them (`chronocl.integration.runstore.FinishTask`).
        """
        return False

    # -- sliding windows --------------------------------------------------------------------
    def leaf_value(self, values: Values) -> np.ndarray | None:
        """What `combine` compares, from the raw values of a leaf's steps (leaf_span, Z, Y, X)."""
        return None

    def finish_sums(
        self,
        sums: np.ndarray,
        alpha: np.ndarray | None,
        positions: np.ndarray,
        spec: IntegrationSpec,
    ) -> np.ndarray:
        """ "invert" modes: the finished RGBA float32 from the window's sums (Z, Y, X, C)."""
        raise NotImplementedError

    # -- the OpenCL kernel ------------------------------------------------------------------
    def kernel_options(
        self, spec: IntegrationSpec, positions: np.ndarray, raw: bool, given: KernelInput
    ) -> tuple[dict, list]:
        """Build defines and the extra scalar arguments of this mode's integrate kernel."""
        return {}, []

    def combine_kernel(self, spec: IntegrationSpec) -> tuple[str, str, dict]:
        """(kernel file stem, kernel, defines) of the kernel doing `combine` (built SLIDING)."""
        raise NotImplementedError

    def finish_kernel(
        self, acc: np.ndarray, positions: np.ndarray, spec: IntegrationSpec
    ) -> tuple[str, dict, list]:
        """ "invert" modes: the kernel doing `finish_sums`, its defines and scalar arguments.

        Its arguments: acc (C longs per voxel), the aggregated opacity if the mode has one,
        the output RGBA, then the scalars.
        """
        raise NotImplementedError
