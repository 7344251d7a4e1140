"""A reader's time steps before they are written (`Steps`): what a format's reader hands the
store writer, and what a series gives back (`TimeSeries.steps`) to be written again."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Steps:
    """A reader's time steps before they are written: `read()` yields each (Z, Y, X) step in
    turn (one in memory at a time) and the rest is what `write_series` records of them."""

    read: Callable[[], Iterator[np.ndarray]]
    n_steps: int
    volume_shape: tuple[int, ...]
    dtype: np.dtype
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)  # (dx, dy, dz), x first
    source: str = ""
    times: Sequence | None = None
    labels: Sequence[str] | None = None
    attrs: Mapping[str, object] = field(default_factory=dict)

    def written(self) -> dict:
        """`write_series` keywords for these steps (all but the steps themselves)."""
        return dict(
            n_steps=self.n_steps,
            volume_shape=self.volume_shape,
            dtype=self.dtype,
            spacing=self.spacing,
            times=self.times,
            source=self.source,
            labels=self.labels,
            attrs=dict(self.attrs),
        )
