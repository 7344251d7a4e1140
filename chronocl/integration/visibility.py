"""Saying when a picture cannot show what was selected: steps whose values all fall where the
transfer functions are transparent, and chronovolumes with nothing opaque in them.

Both are found from what is known without reading the data again: a step's minimum and
maximum (the series' statistics) against the data TF's opacity over that range times the time
TF's opacity at the step, and the chronovolume's own opacity. Each comes as one
`ChronoclWarning` naming the steps and the option that fixes it (the CLI prints one line).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from chronocl.core.errors import ChronoclWarning

# Under this opacity a step's voxels, or a chronovolume, do not show.
VISIBLE = 0.005


def invisible_steps(job) -> dict[int, str]:
    """The selected steps of `job` (a prepared integration) that cannot show, each with why:
    "time" where the time TF gives the step no opacity, "data" where every value of the step
    lies where the data TF's opacity (times the step's time opacity) is under VISIBLE."""
    spec = job.spec
    if not spec.integration.per_step_tf:
        return {}
    enhanced = spec.enhance.kind != "none"  # edges may be raised well above the TF's opacity
    stats = job.series.stats
    lo, hi = job.value_range
    alpha = spec.data_tf.lut[:, 3]
    n = len(alpha)
    _, time_alpha = spec.time_tf.evaluate(np.asarray(job.positions, np.float64))
    out = {}
    for k, step in enumerate(job.selection.steps):
        u0, u1 = (_u(v, lo, hi) for v in (stats.step_min[step], stats.step_max[step]))
        i0, i1 = math.floor(u0 * (n - 1)), math.ceil(u1 * (n - 1))
        if float(time_alpha[k]) < VISIBLE:
            out[int(step)] = "time"
        elif not enhanced and float(alpha[i0 : i1 + 1].max()) * float(time_alpha[k]) < VISIBLE:
            out[int(step)] = "data"
    return out


def warn_invisible(job, cv=None) -> None:
    """Warn about the steps of `job` that cannot show and about its chronovolume `cv` when
    nothing in it is opaque (without `cv`, before the work: the steps alone)."""
    empty = cv is not None and _empty(cv)
    stats, (lo, hi) = job.series.stats, job.value_range
    hidden = {} if empty else invisible_steps(job)  # an empty picture says it all
    w = job.selection.width
    by_data = [s for s, why in hidden.items() if why == "data"]
    by_time = [s for s, why in hidden.items() if why == "time"]
    if by_data:
        low = min(_u(stats.step_min[s], lo, hi) for s in by_data)
        top = max(_u(stats.step_max[s], lo, hi) for s in by_data)
        warnings.warn(
            f"{_steps_text(by_data, w)} invisible: their values ({low:.2f} .. {top:.2f} of the "
            f"value range) lie where the data TF's opacity is under {VISIBLE:g}; give a data "
            "TF that is opaque over their values (--tf FILE with a data_tf, or data_tf=)",
            ChronoclWarning,
            stacklevel=3,
        )
    if by_time:
        warnings.warn(
            f"{_steps_text(by_time, w)} invisible: the time TF gives them no opacity; "
            "choose another time opacity (--tf FILE with a time_tf, or time_tf=)",
            ChronoclWarning,
            stacklevel=3,
        )
    if empty:
        warnings.warn(
            f"the {job.spec.mode} chronovolume shows nothing: no voxel is more opaque than "
            f"{VISIBLE:g}; give a data TF that is opaque where the {job.spec.mode} values lie "
            "(--tf FILE with a data_tf, or data_tf=)",
            ChronoclWarning,
            stacklevel=3,
        )


def _empty(cv) -> bool:
    alpha = cv.rgba[..., 3]
    # A first look at every 8th row finds a visible picture at an eighth of the reads.
    if alpha.size and float(alpha[::8].max()) >= VISIBLE:
        return False
    return float(alpha.max(initial=0.0)) < VISIBLE


def _u(value: float, lo: float, hi: float) -> float:
    return min(1.0, max(0.0, (float(value) - lo) / (hi - lo))) if hi > lo else 0.0


def _steps_text(steps: list[int], width: int) -> str:
    """'step 3 (1 of the 10 selected) is' or 'steps 0, 1, 2 (3 of the 10 selected) are'."""
    shown = ", ".join(map(str, steps[:6])) + (", …" if len(steps) > 6 else "")
    noun, verb = ("step", "is") if len(steps) == 1 else ("steps", "are")
    return f"{noun} {shown} ({len(steps)} of the {width} selected) {verb}"
