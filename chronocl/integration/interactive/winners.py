"""Recolouring without re-integration: when a TF edit may only recolour, and what it recolours.

In the modes whose voxel is one step's colour at one value (max, min, first_hit, change:
docs/semantics.md) a voxel's RGBA is TF(u*, p_k*) premultiplied, where k* is the step that won
it and u* the value it won with (change: the change δ). Keep (u*, k*) per voxel and an edit of
the transfer functions only looks them up again (`chronocl.render.recolour`), as long as the
edit cannot change who won:

- max, min: the winner is the raw extreme (ties: the order), so every edit of the transfer
  functions recolours, the value range included: u* of every winner is then gathered again at
  the new range (the steps that won stay).
- change: the winner depends on the values clipped to the value range (and ties on the
  order), so any edit of the data TF's colours and opacities, and of the time TF, recolours,
  as long as the range stays the same (clipping to another range makes new ties).
- first_hit: the winner is the first step whose opacity a_d(u)·a_t(p_k) exceeds the threshold,
  so the edit must keep, at every step, which values pass (`same_hits`).
- Enhancement (edge: gradients of u; silhouette: also the view) multiplies each step's opacity
  by a factor that is not kept here: a spec with enhancement integrates. So does any change of
  mode, order, threshold or normalisation, and every other mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chronocl.core.tf import lut_lerp32
from chronocl.engine.base import Engine
from chronocl.engine.gather import on_host
from chronocl.modes.spec import IntegrationSpec

RECOLOURED = ("max", "min", "first_hit", "change")


@dataclass(frozen=True)
class Winners:
    """Per voxel the value that won (float32 u, or δ for change) and the index of the winning
    step in the window (`steps`; `none` where no step won), for the spec integrated."""

    u: np.ndarray  # (Z, Y, X) float32
    k: np.ndarray  # (Z, Y, X) uint8 or uint16
    steps: tuple[int, ...]
    n_steps: int
    value_range: tuple[float, float]
    spec: IntegrationSpec

    @property
    def none(self) -> int:
        return int(np.iinfo(self.k.dtype).max)


def why_not(
    old: IntegrationSpec,
    new: IntegrationSpec,
    old_range: tuple[float, float],
    new_range: tuple[float, float],
    steps: tuple[int, ...],
    n_steps: int,
) -> str | None:
    """None when `new` shows the window integrated under `old` by recolouring it; else why it
    must integrate (one line)."""
    if old.mode not in RECOLOURED:
        return f"{old.mode} mixes every step's colour"
    if new.mode != old.mode:
        return "the mode changed"
    if old.enhance.kind != "none" or new.enhance.kind != "none":
        return "enhancement depends on gradients (silhouettes on the view)"
    if new.order != old.order or new.threshold != old.threshold:
        return "the order or threshold changed"
    if old.mode not in ("max", "min") and tuple(map(float, old_range)) != tuple(
        map(float, new_range)
    ):  # max/min keep their winners, the raw extremes: their u is gathered again
        return "the value range changed: other values may win"
    if old.mode == "first_hit" and not same_hits(old, new, steps, n_steps):
        return "the edit changes which values pass the opacity threshold"
    return None


def _passes(spec: IntegrationSpec, steps: tuple[int, ...], n_steps: int) -> np.ndarray:
    """(W, size) bool: at each step, whether each LUT entry's opacity passes the threshold, in
    float32 as the kernels compute it (enhancement excluded: `why_not` refuses it)."""
    lut = spec.data_tf.lut
    _, a_t = spec.time_tf.evaluate(spec.time_tf.positions_of(steps, n_steps))
    a = lut[None, :, 3] * a_t.astype(np.float32)[:, None]
    return np.clip(a, np.float32(0), np.float32(1)) > np.float32(spec.threshold)


# The least product of a crossing's non-zero LUT end and a step's time opacity for which a
# threshold of 0 is passed wherever the other end is 0 (see `same_hits`): the opacity is then at
# least this times 2^-24, far above float32's smallest normal (2^-126), so nothing underflows.
ZERO_CROSSING_LEAST = 2.0**-70
# How far a segment's opacity must clear the threshold, relatively, for every value in it to
# pass (or fail) whatever the rounding: lo * (1 - f) + hi * f and the time opacity's product
# round four times in float32 (2^-24 each); and, at a threshold of 0, how far above 0.
CLEAR_BY, CLEAR_OF_ZERO = 2.0**-20, 2.0**-100


def same_hits(
    old: IntegrationSpec, new: IntegrationSpec, steps: tuple[int, ...], n_steps: int
) -> bool:
    """Whether every value passes first_hit's threshold at every step under `new` exactly
    where it does under `old`. The opacity is linear between LUT entries, times the step's time
    opacity. A segment (a step's two neighbouring LUT entries) unchanged by the edit gives the
    same opacities. A changed one whose ends both pass (or both fail) does so throughout only
    where both ends clear the threshold by more than the rounding (`CLEAR_BY`) under both TFs.
    Where the ends differ the crossing is where it was if the segment is unchanged, or, at a
    threshold of 0, if the end that fails is 0 in both: the kernels' lo * (1 - f) + hi * f
    (`tf.lut_lerp32`) is then hi * f or lo * (1 - f), above 0 exactly where f is above 0 (below
    1) whatever the other end's value, as long as f's least step is not smaller than 2^-24:
    not so for a rise from the first entry, where f is u * (size - 1) itself. Sufficient, not
    necessary (data not looked at)."""
    if old.data_tf.size != new.data_tf.size:
        return False
    p_old, p_new = _passes(old, steps, n_steps), _passes(new, steps, n_steps)
    if not np.array_equal(p_old, p_new):
        return False
    lut_o, lut_n = old.data_tf.lut[:, 3], new.data_tf.lut[:, 3]
    _, at_o = old.time_tf.evaluate(old.time_tf.positions_of(steps, n_steps))
    _, at_n = new.time_tf.evaluate(new.time_tf.positions_of(steps, n_steps))
    at_o, at_n = np.float32(at_o), np.float32(at_n)
    crossing = p_old[:, 1:] != p_old[:, :-1]  # (W, size - 1) segments the threshold cuts
    changed = ((lut_o[:-1] != lut_n[:-1]) | (lut_o[1:] != lut_n[1:]))[None, :] | (at_o != at_n)[
        :, None
    ]
    a_o = lut_o.astype(np.float64)[None, :] * at_o.astype(np.float64)[:, None]  # (W, size)
    a_n = lut_n.astype(np.float64)[None, :] * at_n.astype(np.float64)[:, None]
    ends = (a_o[:, :-1], a_o[:, 1:], a_n[:, :-1], a_n[:, 1:])
    low, high = np.minimum.reduce(ends), np.maximum.reduce(ends)
    t = float(np.float32(old.threshold))
    clear = (high == 0) | (high * (1 + CLEAR_BY) < t)  # fails throughout
    if t < 1:  # (an opacity is clamped to 1: a threshold of 1 is never passed)
        clear |= low > t * (1 + CLEAR_BY) + CLEAR_OF_ZERO  # passes throughout
    if (changed & ~crossing & ~clear).any():
        return False
    if not crossing.any():
        return True
    seg = np.flatnonzero(crossing.any(axis=0))
    lo_o, hi_o, lo_n, hi_n = lut_o[seg], lut_o[seg + 1], lut_n[seg], lut_n[seg + 1]
    ends_same = (lo_o == lo_n) & (hi_o == hi_n)
    crossed = crossing.any(axis=1)
    if not (at_o == at_n)[crossed].all():
        return False
    if old.threshold == 0.0 and new.threshold == 0.0:
        rising = (lo_o == 0) & (lo_n == 0) & (seg >= 1)
        falling = (hi_o == 0) & (hi_n == 0)
        end = np.where(rising, np.minimum(hi_o, hi_n), np.minimum(lo_o, lo_n)).astype(np.float64)
        least_time = float(at_o[crossed].min())
        ends_same |= (rising | falling) & (end * least_time >= ZERO_CROSSING_LEAST)
    return bool(ends_same.all())


def winners(
    t_index: np.ndarray,
    arrays: dict[int, np.ndarray],
    steps: tuple[int, ...],
    n_steps: int,
    value_range: tuple[float, float],
    spec: IntegrationSpec,
    engine: Engine | None = None,
) -> Winners:
    """The winners of an integrated window: its t_index (the selected step of each voxel, -1:
    none) and the window's raw resident values (step -> (Z, Y, X)), gathered by `engine`
    (`Engine.gather`: OpenCL's on its device; default numpy's, on the host threads, the
    oracle the tests hold the others to). A session's: `LevelSession.winners`."""
    gather = on_host if engine is None else engine.gather
    u, k = gather(t_index, arrays, steps, value_range, spec.mode == "change")
    return Winners(u, k, tuple(steps), n_steps, tuple(value_range), spec)


def step_table(spec: IntegrationSpec, steps: tuple[int, ...], n_steps: int) -> np.ndarray:
    """(W, 4) float32: each window step's time colour and opacity (rgb_t, a_t)."""
    rgb_t, a_t = spec.time_tf.evaluate(spec.time_tf.positions_of(steps, n_steps))
    return np.concatenate([rgb_t, a_t[:, None]], axis=1).astype(np.float32)


def recoloured(w: Winners, spec: IntegrationSpec) -> np.ndarray:
    """The premultiplied RGBA float32 (Z, Y, X, 4) the winners take under `spec`, on the host
    (the oracle of the GPU's recolouring; the viewer never calls it)."""
    d = lut_lerp32(spec.data_tf.lut, w.u)
    table = step_table(spec, w.steps, w.n_steps)
    won = w.k != w.none
    t = table[np.where(won, w.k, 0)]
    a = np.clip(d[..., 3] * t[..., 3], np.float32(0), np.float32(1))
    rgba = np.zeros((*w.u.shape, 4), np.float32)
    rgba[..., :3] = a[..., None].astype(np.float64) * (d[..., :3] * t[..., :3].astype(np.float64))
    rgba[..., 3] = a
    rgba[~won] = 0
    return rgba
