"""What a mode is: the interface every integration mode implements, and the partial result.

A mode owns everything about one way of integrating a window through time (see
docs/semantics.md): its numpy reference (`accumulate` over the steps in order, `combine` of
two consecutive runs, `finalize`), how a sliding window keeps its state (by aggregation of
partials, or by adding and subtracting steps exactly: ``invert``), the partial volume's size
per voxel, and its OpenCL kernel file ``kernels/opencl/<kernel>.cl`` (integrate and combine
kernels together). The registry in `chronocl.modes` lists the modes; nothing else names one.

What a mode's flags promise is checked when its class is defined (`check_mode`): sliding by
aggregation needs `combine` and `combine_kernel` (`Combines`), by inversion `finish_sums` and
`finish_kernel` (`FinishesSums`), comparing values `leaf_value` (`ComparesValues`). A mode that
lacks a hook so fails at import, not mid-run.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Protocol, runtime_checkable

import numpy as np

from chronocl.core.errors import ChronoclError, ModeDefinitionError

if TYPE_CHECKING:
    from chronocl.core.tf import DataTF, TimeTF

FIXED_ONE = float(2**40)  # sums of inverting modes in fixed point: exact add and subtract


class FaintSums(ChronoclError):
    """A window's fixed-point sums too faint to finish as precisely as integrating it: a mode
    whose picture is relative to its largest sum (additive, normalised by "max") reads each
    sum to within 2^-40 a step (truncated), which is coarse beside a largest sum under
    `faint_below`. Not an error of the user's: a session that slides catches it and
    integrates such a window from its steps."""


def faint_below(steps: int) -> float:
    """The largest sum below which `steps` steps' truncation in fixed point (under 1/FIXED_ONE
    each) may be more than 2^-21 of it: finished from the sums, such a window could differ from
    its integration by more than a few float32 roundings."""
    return steps * 2.0**-19


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
    and `value` what `combine` needs beyond the colour (max/min: the winning raw value).
    """

    rgba: np.ndarray
    t_index: np.ndarray | None
    value: np.ndarray | None = None


class SpecView(Protocol):
    """What a mode's hooks read of the `IntegrationSpec` they are given.

    The spec itself (`chronocl.modes.spec`) looks modes up in the registry, which imports this
    module; naming it here would make the contract and the spec import each other.
    """

    mode: str
    order: str | Sequence[int]
    data_tf: DataTF
    time_tf: TimeTF
    threshold: float
    normalize: str


# -- capabilities: the hooks a mode's flags promise ----------------------------------------------
@runtime_checkable
class Combines(Protocol):
    """Sliding by aggregation of partials (``slides = "aggregate"``), or an inverting mode that
    also aggregates a partial of its own (``state_bytes > 0``: additive's opacity)."""

    def combine(self, front: Partial, back: Partial, spec: SpecView) -> Partial:
        """The partial of two consecutive runs of steps, `front` integrated first."""
        ...

    def combine_kernel(self, spec: SpecView) -> tuple[str, str, dict]:
        """(kernel file stem, kernel, defines) of the kernel doing `combine` (built SLIDING)."""
        ...


@runtime_checkable
class FinishesSums(Protocol):
    """Sliding by inversion (``slides = "invert"``): the window is kept as exact fixed-point
    sums of `sum_channels` channels, steps added and subtracted, and finished from them."""

    def finish_sums(
        self,
        sums: np.ndarray,
        alpha: np.ndarray | None,
        positions: np.ndarray,
        spec: SpecView,
    ) -> np.ndarray:
        """The finished RGBA float32 from the window's sums (Z, Y, X, C)."""
        ...

    def finish_kernel(
        self, acc: np.ndarray, positions: np.ndarray, spec: SpecView
    ) -> tuple[str, dict, list, list]:
        """The kernel doing `finish_sums`: (kernel, defines, extra buffers, scalars).

        Its arguments: acc (C longs per voxel), the aggregated opacity if the mode has one,
        the extra buffers (count's LUT), the output RGBA, then the scalars.
        """
        ...


@runtime_checkable
class ComparesValues(Protocol):
    """``compares_values``: `combine` compares a value per voxel (max/min: the winning raw value;
    change: the largest change), kept in `Partial.value`."""

    def leaf_value(self, values: Values) -> np.ndarray:
        """What `combine` compares, from the raw values of a leaf's steps (leaf_span, Z, Y, X)."""
        ...

    def leaf_value_kernel(self, value_range: tuple[float, float]) -> tuple[str, list]:
        """The kernel doing `leaf_value` on the device (kernels/opencl/leaves.cl, built
        SLIDING) and its float32 scalars: (kernel, scalars)."""
        ...


def _hooks(protocol: type) -> tuple[str, ...]:
    return tuple(k for k, v in vars(protocol).items() if callable(v) and not k.startswith("_"))


# (capability, the flags that promise it as the message names them, whether a class does)
CAPABILITIES: tuple[tuple[type, str, Callable[[type[Mode]], bool]], ...] = (
    (Combines, 'slides = "aggregate" or state_bytes > 0', lambda m: m.combines()),
    (FinishesSums, 'slides = "invert"', lambda m: m.slides == "invert"),
    (ComparesValues, "compares_values = True", lambda m: m.compares_values),
)
# The flags' allowed values, checked when a mode class is defined.
CHOICES = {
    "slides": ("aggregate", "invert"),
    "legend": ("time", "fraction"),
    "data_axis": ("value", "change"),
    "pool": ("mean", "max", "min"),  # chronocl.data.pyramid.POOLS
}


class Mode:
    """One integration mode. Subclasses set the class attributes and the reference methods.

    Every mode has `accumulate`; the flags below promise further hooks (`CAPABILITIES`: the
    protocols `Combines`, `FinishesSums`, `ComparesValues`), and a class that promises one
    without defining its hooks, or sets a flag out of its choices, is refused where it is
    defined (ModeDefinitionError at import). A base class that is not a mode itself says so:
    ``class Extreme(Mode, abstract=True)``.
    """

    name: ClassVar[str]
    summary: ClassVar[str]  # one line for the CLI help, the viewer and the docs
    kernel: ClassVar[str]  # stem of its file in kernels/opencl/
    kernel_function: ClassVar[str]  # the integrate kernel in that file
    has_t_index: ClassVar[bool] = False
    # its kernels also write each voxel's winner (u and step index, where the host asks:
    # WINNERS, common.h), which the viewer recolours a TF edit from without gathering them
    writes_winners: ClassVar[bool] = False
    # how a sliding window keeps its state: "aggregate" partials (`Combines`), or "invert"
    # (add and subtract steps as fixed-point sums of `sum_channels` channels: `FinishesSums`)
    slides: ClassVar[str] = "aggregate"
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
    # What a spec naming no data TF or no threshold gets in this mode (IntegrationSpec): the
    # data TF's points (None: the default DataTF(), white) over the fitted window range, and
    # the opacity threshold.
    default_data_points: ClassVar[tuple[tuple[float, ...], ...] | None] = None
    default_threshold: ClassVar[float] = 0.0

    def __init_subclass__(cls, abstract: bool = False, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        if not abstract:
            check_mode(cls)

    @classmethod
    def combines(cls) -> bool:
        """Whether the mode aggregates partials when it slides (`Combines`)."""
        return cls.slides == "aggregate" or cls.state_bytes > 0

    # -- the numpy reference (every mode) -------------------------------------------------
    def accumulate(
        self,
        u: np.ndarray,
        steps: Sequence[int],
        order: np.ndarray,
        step_rgba: StepRGBA,
        spec: SpecView,
    ) -> Partial:
        """Integrate u (W, Z, Y, X) over the steps in `order` (indices into the selection).

        A mode with `reads_values` is also given ``values=`` (`Values`): the raw window.
        """
        raise NotImplementedError  # check_mode refuses a mode class without its own

    def finalize(self, partial: Partial, positions: np.ndarray, spec: SpecView) -> np.ndarray:
        """The finished premultiplied RGBA float32 of a whole window."""
        return partial.rgba.astype(np.float32, copy=False)

    def finalize_is_global(self, spec: SpecView) -> bool:
        """Whether finishing needs the whole volume (e.g. a normalisation by its maximum).

        Such a mode may depend on the rest of the volume only through the per-channel maxima
        of its raw partial: out-of-core runs record those per slab and finish each chunk
        with them (`chronocl.integration.runs.runstore.FinishTask`).
        """
        return False

    # -- the OpenCL kernel ------------------------------------------------------------------
    def kernel_options(
        self, spec: SpecView, positions: np.ndarray, raw: bool, given: KernelInput
    ) -> tuple[dict, dict]:
        """Build defines and the extra scalar arguments of this mode's integrate kernel, by
        name in the kernel's order (they follow KERNEL_ARGS: chronocl/engine/kernel_args.py)."""
        return {}, {}


def check_mode(cls: type[Mode]) -> None:
    """Refuse a mode class whose flags promise hooks it lacks, or take values out of their
    choices: one line naming the class, the flag and the missing hook."""
    where = f"mode class {cls.__qualname__}"

    def refuse(problem: str) -> None:
        raise ModeDefinitionError(f"{where} {problem} (docs/architecture.md, How to add a mode)")

    for attr in ("name", "summary", "kernel", "kernel_function"):
        if not isinstance(getattr(cls, attr, None), str) or not getattr(cls, attr):
            refuse(f"has no {attr}; set it as a class attribute (a non-empty string)")
    for attr, choices in CHOICES.items():
        if getattr(cls, attr) not in choices:
            refuse(f"sets {attr} = {getattr(cls, attr)!r}; choose one of {', '.join(choices)}")
    if cls.accumulate is Mode.accumulate:
        refuse("does not define accumulate, the numpy reference every mode has")
    takes_values = "values" in inspect.signature(cls.accumulate).parameters
    if takes_values != cls.reads_values:
        refuse(
            f"sets reads_values = {cls.reads_values} but its accumulate "
            f"{'takes' if takes_values else 'does not take'} values=; make them agree"
        )
    for protocol, promise, promised in CAPABILITIES:
        missing = [h for h in _hooks(protocol) if not callable(getattr(cls, h, None))]
        if promised(cls) and missing:
            refuse(
                f"sets {promise} ({protocol.__name__}) but does not define {' and '.join(missing)}"
            )
    if (cls.slides == "invert") != (cls.sum_channels > 0):
        refuse(
            f"sets slides = {cls.slides!r} with sum_channels = {cls.sum_channels}; an "
            '"invert" mode keeps some channels as sums (sum_channels > 0), an aggregating one none'
        )
    if bool(cls.rows_kernel) != (cls.rows_state > 0):
        refuse(
            f"sets rows_kernel = {cls.rows_kernel!r} with rows_state = {cls.rows_state}; "
            "a rows kernel needs its state's bytes per voxel, and only it has one"
        )
    if cls.leaf_span < 1:
        refuse(f"sets leaf_span = {cls.leaf_span}; a leaf integrates 1 or more steps")
    if cls.writes_winners and not cls.has_t_index:
        refuse("sets writes_winners without has_t_index; a winner is one step per voxel")
