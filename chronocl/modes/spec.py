"""What a chronovolume is made of: mode, order, transfer functions, enhancement.

`IntegrationSpec` is the frozen, validated description shared by every engine
and stored in a chronovolume's metadata; `resolve_order` turns an order into
the sequence of selection indices k in which steps are integrated.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from chronocl import modes
from chronocl.core.enhance import Enhance
from chronocl.core.errors import InvalidParameterError, InvalidSelectionError, UnknownNameError
from chronocl.core.selection import Selection
from chronocl.core.tf import FITTED, DataTF, TimeTF
from chronocl.modes import Mode

ORDERS = ("forward", "backward")
NORMALIZE = ("time", "max")


def default_data_tf(mode: str) -> DataTF:
    """The data TF a spec of `mode` gets when none is given: the mode's own
    (`Mode.default_data_points`, count's occupancy ramp) over the fitted window range, else
    the white default."""
    points = modes.get(mode).default_data_points
    return DataTF(points=points, value_range=FITTED) if points else DataTF()


@dataclass(frozen=True)
class IntegrationSpec:
    """How to integrate a selection through time (docs/semantics.md).

    `order` is ``forward``, ``backward`` or an importance permutation given as the
    selected step numbers, most important first. `threshold` is the opacity a step must
    exceed for first_hit (to be hit) and count (to count as present); `normalize` is
    additive's normalisation (``time``: divide by N = Σ a_t·rgb_t; ``max``: by the volume's
    largest channel value). No `data_tf`: the mode's default (`Mode.default_data_points`:
    white, count its occupancy ramp); no `threshold`: 0, or with the mode's own TF its
    `Mode.default_threshold` (count: 0.25). No `time_tf`: the one that follows the data TF
    (`TimeTF.for_data`: rgb, or lightness under a colour map).
    """

    mode: str = modes.DEFAULT
    order: str | tuple[int, ...] = "forward"
    data_tf: DataTF = None  # type: ignore[assignment]  # None: the mode's default (below)
    time_tf: TimeTF = None  # type: ignore[assignment]  # None: TimeTF.for_data(data_tf.points)
    enhance: Enhance = field(default_factory=Enhance)
    threshold: float = None  # type: ignore[assignment]  # None: the mode's default
    normalize: str = "time"

    def __post_init__(self) -> None:
        mode = modes.get(self.mode)  # an unknown name raises, naming the choices
        own_tf = self.data_tf is None
        if own_tf:
            object.__setattr__(self, "data_tf", default_data_tf(self.mode))
        if self.threshold is None:  # the mode's default threshold goes with its own TF
            object.__setattr__(self, "threshold", mode.default_threshold if own_tf else 0.0)
        if self.time_tf is None:
            object.__setattr__(self, "time_tf", TimeTF.for_data(self.data_tf.points))
        if isinstance(self.order, str):
            if self.order not in ORDERS:
                raise UnknownNameError(
                    f"unknown order {self.order!r}; choose forward, backward or a list of steps"
                )
        elif isinstance(self.order, Sequence | np.ndarray):
            try:
                object.__setattr__(self, "order", tuple(int(s) for s in self.order))
            except (TypeError, ValueError):
                raise InvalidSelectionError(
                    f"importance order {self.order!r} must be a list of step numbers"
                ) from None
        else:
            raise UnknownNameError(
                f"unknown order {self.order!r}; choose forward, backward or a list of steps"
            )
        if self.normalize not in NORMALIZE:
            raise UnknownNameError(
                f"unknown additive normalisation {self.normalize!r}; choose time or max"
            )
        t = float(self.threshold)
        if not (math.isfinite(t) and 0.0 <= t < 1.0):
            raise InvalidParameterError(
                f"opacity threshold is {self.threshold}; it must lie in [0, 1)"
            )
        # Opacities are float32 in every engine: compare against the float32 threshold.
        object.__setattr__(self, "threshold", float(np.float32(t)))

    @property
    def integration(self) -> Mode:
        """The registered mode that integrates this spec."""
        return modes.get(self.mode)

    @property
    def has_t_index(self) -> bool:
        return self.integration.has_t_index

    @property
    def finalize_is_global(self) -> bool:
        """Whether finishing needs the whole volume (additive normalised by its maximum)."""
        return self.integration.finalize_is_global(self)

    def with_value_range(self, value_range) -> IntegrationSpec:
        """This spec with its data TF normalising over `value_range` (a fixed pair)."""
        return replace(self, data_tf=replace(self.data_tf, value_range=tuple(value_range)))

    def to_dict(self) -> dict:
        return {
            "mode": self.mode,
            "order": self.order if isinstance(self.order, str) else list(self.order),
            "data_tf": self.data_tf.to_dict(),
            "time_tf": self.time_tf.to_dict(),
            "enhance": self.enhance.to_dict(),
            "threshold": self.threshold,
            "normalize": self.normalize,
        }

    @classmethod
    def from_dict(cls, d: dict) -> IntegrationSpec:
        order = d.get("order", "forward")
        return cls(
            mode=d["mode"],
            order=order if isinstance(order, str) else tuple(order),
            data_tf=DataTF.from_dict(d.get("data_tf", {})),
            time_tf=TimeTF.from_dict(d.get("time_tf", {})),
            enhance=Enhance(**{**d.get("enhance", {}), "view": tuple(d["enhance"]["view"])})
            if "enhance" in d
            else Enhance(),
            threshold=d.get("threshold", 0.0),
            normalize=d.get("normalize", "time"),
        )


def resolve_order(order: str | Sequence[int], selection: Selection) -> np.ndarray:
    """Indices k into the selection, in integration order (first = in front)."""
    w = selection.width
    if isinstance(order, str):
        if order == "forward":
            return np.arange(w)
        if order == "backward":
            return np.arange(w)[::-1].copy()
        raise UnknownNameError(
            f"unknown order {order!r}; choose forward, backward or a list of steps"
        )
    steps = [int(s) for s in order]
    if sorted(steps) != list(selection.steps):
        raise InvalidSelectionError(
            f"importance order {steps} must be a permutation of the selected steps "
            f"{list(selection.steps)}"
        )
    where = {s: k for k, s in enumerate(selection.steps)}
    return np.array([where[s] for s in steps], dtype=np.int64)
