"""Which selected steps a picture shows: each step taken out in turn, the picture compared.

A step shows in a picture when taking it out changes the picture. "Taking it out" keeps
everything else as it was (the other steps' time positions and colours, the value range,
additive's normalisation): the step's values are replaced by ones that contribute nothing,
the bottom of the value range (transparent under a TF that is transparent there, never a
maximum) or for `min` the top (never a minimum). A step counts as shown when at least
`TUNING.shown_step_pixels` pixels (and 0.05 % of the picture) change by more than
`TUNING.shown_step_level` in some channel.

This is what the demo gallery prints per picture and what the tests of the default transfer
functions check ("every selected step shows"). It integrates and renders W + 1 times: meant
for data of demo and test sizes.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from chronocl.core.errors import ChronoclWarning
from chronocl.core.tuning import TUNING
from chronocl.data.series import TimeSeries
from chronocl.integration.inmemory import integrate, prepare


@dataclass(frozen=True)
class StepsShown:
    """The selected steps a picture shows and those it hides."""

    shown: tuple[int, ...]
    hidden: tuple[int, ...]

    @property
    def fraction(self) -> float:
        return len(self.shown) / max(1, len(self.shown) + len(self.hidden))


def steps_shown(series: TimeSeries, window, mode: str, picture, **args) -> StepsShown:
    """The steps of `window` that the picture of `mode` shows.

    `picture(cv)` renders a chronovolume to an (H, W, 3 or 4) array in [0, 1] or 0..255 (the
    same camera, size and settings every call); `args` are those of `integrate` (spec=,
    data_tf=, engine=, ...)."""
    spec_args = {k: v for k, v in args.items() if k != "engine"}
    job = prepare(series, window, mode, spec_args.pop("spec", None), spec_args or None)
    spec = job.spec.with_value_range(job.value_range)
    engine = args.get("engine", "numpy")
    steps = list(job.selection.steps)
    data = series.read(steps)

    def pixels(values: np.ndarray) -> np.ndarray:
        with warnings.catch_warnings():  # a step taken out is meant to be invisible
            warnings.simplefilter("ignore", ChronoclWarning)
            cv = integrate(_copy(series, steps, values), steps, spec=spec, engine=engine)
        return _pixels(picture(cv))

    base = pixels(data)
    gone = job.value_range[1] if mode == "min" else job.value_range[0]
    shown, hidden = [], []
    for k, step in enumerate(steps):
        ablated = data.copy()
        ablated[k] = gone
        changed = (np.abs(pixels(ablated) - base) > TUNING.shown_step_level).any(axis=-1).sum()
        need = max(TUNING.shown_step_pixels, 5e-4 * base.shape[0] * base.shape[1])
        (shown if changed >= need else hidden).append(step)
    return StepsShown(tuple(shown), tuple(hidden))


def _copy(series: TimeSeries, steps: list[int], data: np.ndarray) -> TimeSeries:
    """A series as long as `series` holding `data` at `steps` (the other steps zero and never
    read), so absolute time positions and labels stay those of the original."""
    full = np.zeros((series.n_steps, *series.volume_shape), dtype=series.dtype)
    full[steps] = data
    return TimeSeries.from_array(full, spacing=series.spacing, times=list(series.times))


def _pixels(image) -> np.ndarray:
    a = np.asarray(getattr(image, "array", image), dtype=np.float64)
    if a.max(initial=0) > 1.0:
        a = a / 255.0
    return a[..., :3]
