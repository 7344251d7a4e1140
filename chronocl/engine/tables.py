"""The host tables of an integration: what the kernels look up instead of evaluating TFs.

Transfer-function work is done once on the host: one data LUT shared by all steps and a
(colour, alpha) factor per step, so a kernel does one interpolated lookup per voxel-step
(quantised uint8 data index their LUT directly); when the data colour is constant (the
default: colour by time) it is folded into the per-step factors; when the data TF is a few
straight pieces (`tf_segments`) the kernels evaluate those instead (the modes that compare
opacity with a threshold look it up where the pieces are too close to decide); and the skip
cut is the smallest raw value whose data opacity can matter (`skip_bar`, `raw_cut`), so
steps whose voxels all lie below it are skipped exactly.

Pure numpy, no device: `chronocl.engine.opencl` uploads these tables, and
tests/test_engine_tables.py checks them without one. docs/engine.md has the arithmetic.
"""

from __future__ import annotations

import threading
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from chronocl.core import values
from chronocl.core.tf import lut_lerp32
from chronocl.core.tuning import TUNING
from chronocl.modes.spec import IntegrationSpec

MAX_SEGMENTS = 8  # straight pieces of the data TF evaluated without lookups
SEGMENT_TOLERANCE = 2e-7  # how far a LUT entry may lie from its piece (float32 rounding)
# the most `opacity_error` the threshold modes accept: half the kernels' SEG_MARGIN (1e-5)
OPACITY_ERROR_MAX = 5e-6
# How much a step's opacity may exceed its LUT entries times the time opacity: three float32
# roundings of the interpolation and one of the product (about 4.8e-7), with room to spare.
PASS_SLACK = 1.0 + 1e-5


class Tables(NamedTuple):
    """The device tables of one integration (`host_tables`).

    lut: the data LUT, planar (4, N) float32; tc: per-step (W, 4) = (rgb_t, a_t) float32;
    const_color: whether the data colour is constant (then folded into tc); cut: the skip cut
    (raw values below it look up data opacity 0, or in the threshold modes too little to
    pass: `skip_bar`); segments: the data TF as a few straight pieces (`tf_segments`) or None;
    seg_alpha: what the pieces' opacity is for (SEG_ALPHA: 0 not in the pieces, 1 the
    opacity itself, 2 a threshold test that decides the lanes far from the threshold, the
    others looked up exactly).
    """

    lut: np.ndarray
    tc: np.ndarray
    const_color: bool
    cut: float
    segments: np.ndarray | None
    seg_alpha: int

    def lut_buffer(self) -> np.ndarray:
        """What the kernels' `lut` argument holds: the LUT, then the pieces per step (`timed`)."""
        if self.segments is None:
            return self.lut
        return np.concatenate([self.lut.ravel(), timed(self.segments, self.tc)])


def host_tables(
    spec: IntegrationSpec,
    positions: np.ndarray,
    quant: bool,
    value_range: tuple[float, float],
    pieces: bool = True,
) -> Tables:
    """The device tables of one integration (`Tables`); `pieces`: look for the data TF's
    straight pieces (`data_pieces`), else segments is None."""
    if quant:  # TF(u(v)) for every byte value, with the kernels' float32 arithmetic
        u = values.normalize(np.arange(256, dtype=np.uint8), *value_range)
        lut = lut_lerp32(spec.data_tf.lut, u).astype(np.float64)
    else:
        lut = spec.data_tf.lut.astype(np.float64)
    rgb_t, a_t = spec.time_tf.evaluate(positions)
    const_color = bool(np.all(lut[:, :3] == lut[:1, :3]))
    colour = rgb_t * lut[0, :3] if const_color else rgb_t
    tc = np.concatenate([colour, a_t[:, None]], axis=1).astype(np.float32)
    segments, seg_alpha = data_pieces(lut, const_color, spec, a_t) if pieces else (None, 0)
    bar = skip_bar(spec, a_t)
    if quant:  # byte values below the first entry above the bar
        live = np.flatnonzero(lut[:, 3] > bar)
        cut = float(min(live[0], 255)) if live.size else 255.0
    else:  # LUT positions x < j only mix entries of intervals below the first live one, j
        live = np.flatnonzero(np.maximum(lut[:-1, 3], lut[1:, 3]) > bar)
        first = int(live[0]) if live.size else len(lut) - 1
        cut = raw_cut(float(first), value_range, len(lut))
    planar = np.ascontiguousarray(lut.T, dtype=np.float32)
    return Tables(planar, tc, const_color, cut, segments, seg_alpha)


class TableCache:
    """The host tables of the `size` (None: `TUNING.lut_cache`) integrations most recently
    used, read-only.

    A series integrated slab by slab, or again with the same transfer functions, builds its
    tables once (about a third of a millisecond each time, where max over 30x128^3 takes 9).
    Safe to share between threads and engines (the key holds `pieces`).
    """

    def __init__(self, size: int | None = None) -> None:
        self.size = TUNING.lut_cache if size is None else size
        self._tables: dict[tuple, Tables] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._tables)

    def get(
        self,
        spec: IntegrationSpec,
        positions: np.ndarray,
        quant: bool,
        value_range: tuple[float, float],
        pieces: bool = True,
    ) -> Tables:
        """`host_tables` of these arguments, built once while they stay among the recent."""
        pos = np.asarray(positions)
        key = (spec, pos.dtype.str, pos.tobytes(), quant, *map(float, value_range), pieces)
        with self._lock:  # specs are frozen and hold tuples: hashable
            tables = self._tables.pop(key, None)
            if tables is not None:  # the most recently used go last, the oldest first
                self._tables[key] = tables
        if tables is None:
            tables = host_tables(spec, positions, quant, value_range, pieces)
            for a in tables:
                if isinstance(a, np.ndarray):
                    a.setflags(write=False)
            with self._lock:
                while len(self._tables) >= self.size:
                    del self._tables[next(iter(self._tables))]
                self._tables[key] = tables
        return tables


def data_pieces(lut: np.ndarray, const_color: bool, spec: IntegrationSpec, a_t: np.ndarray):
    """The pieces of the data TF (LUT `lut` (N, 4)) the kernels evaluate, and their SEG_ALPHA
    (see `Tables`).

    Opacity joins the pieces where it is straight in as few pieces; a mode comparing it
    with a threshold keeps the LUT's exact opacity and lets its pieces decide only lanes
    farther from the threshold than their error (`opacity_error`, at most
    OPACITY_ERROR_MAX, times a time opacity of at most 1; no gradient enhancement) could
    reach."""
    lut32 = lut.astype(np.float32)
    channels = [] if const_color else [0, 1, 2]
    exact = spec.integration.opacity_threshold
    # a threshold test trusts the pieces only where they bound the exact opacity
    if not (exact and (float(a_t.max(initial=0.0)) > 1.0 or spec.enhance.needs_gradient)):
        table = tf_segments(lut32, [*channels, 3])
        if table is not None and (not exact or opacity_error(table, len(lut)) <= OPACITY_ERROR_MAX):
            return table, 2 if exact else 1
    return (tf_segments(lut32, channels) if channels else None), 0


def tf_segments(lut: np.ndarray, channels: list[int]) -> np.ndarray | None:
    """`channels` of LUT `lut` (N, 4) as at most MAX_SEGMENTS straight pieces, or None.

    Returns (9, S) float32: each piece's first LUT position x0, then the four channels there
    and their slopes per position (channels not asked for are 0); a piece runs to the next
    one's x0. Every entry of the channels asked for lies within SEGMENT_TOLERANCE of its
    piece, so the kernels' sum over the pieces (the value at 0 plus each slope times x's
    run through its piece, kernels/opencl/common.h) equals the LUT's interpolation to float32
    rounding (docs/engine.md). A piece breaks where the second difference of a channel is
    not zero.
    """
    n = len(lut)
    v64 = lut[:, channels].astype(np.float64)
    bend = np.abs(v64[:-2] - 2 * v64[1:-1] + v64[2:]).max(axis=1) > SEGMENT_TOLERANCE
    starts = np.concatenate([[0], np.flatnonzero(bend) + 1])
    if len(starts) > MAX_SEGMENTS:
        return None
    ends = np.concatenate([starts[1:], [n - 1]])
    table = np.zeros((9, len(starts)), dtype=np.float64)
    rows = np.asarray(channels, dtype=int)
    for j, (a, b) in enumerate(zip(starts, ends, strict=True)):
        slope = (v64[b] - v64[a]) / (b - a)
        line = v64[a] + slope * np.arange(b - a + 1)[:, None]
        if np.abs(line - v64[a : b + 1]).max() > SEGMENT_TOLERANCE:
            return None
        table[0, j] = a
        table[1 + rows, j], table[5 + rows, j] = v64[a], slope
    return table.astype(np.float32)


def opacity_error(table: np.ndarray, n: int) -> float:
    """A bound on how far the opacity of pieces `table` (`tf_segments`, LUT of `n` entries)
    evaluated as the kernels do lies from the LUT's interpolation: float32 rounding of each
    product and sum (no partial sum exceeds the value at 0 plus the pieces' changes) and the
    entries' distance from their pieces. The threshold modes trust the pieces beyond 1e-5
    (SEG_MARGIN in kernels/opencl/common.h), so this must stay below OPACITY_ERROR_MAX."""
    x0 = table[0].astype(np.float64)
    length = np.diff(np.append(x0, n - 1))
    swing = abs(float(table[4, 0])) + float(np.sum(np.abs(table[8].astype(np.float64)) * length))
    return 2.0**-24 * (table.shape[1] + 2) * swing + 2 * SEGMENT_TOLERANCE


def skip_bar(spec: IntegrationSpec, a_t: np.ndarray) -> float:
    """The data opacity a LUT entry must exceed for a step to matter: 0 (a step whose voxels
    all look up entries of opacity 0 adds nothing), or, in the modes that compare opacity with
    a threshold, the entry below which no step's opacity can exceed the threshold. Opacity is
    the LUT's interpolation, at most its larger entry (to float32 rounding), times the step's
    time opacity; gradient enhancement may raise it, so it keeps the bar at 0."""
    mode = spec.integration
    if not mode.opacity_threshold or spec.enhance.needs_gradient or spec.threshold <= 0:
        return 0.0
    a_max = float(np.max(a_t, initial=0.0))
    return float("inf") if a_max <= 0 else spec.threshold / (a_max * PASS_SLACK)


def timed(segments: np.ndarray, tc: np.ndarray) -> np.ndarray:
    """The kernels' table of `segments` (9, S) for steps of time factors `tc` (W, 4): the
    pieces' x0 (S), then per step and channel the value at 0 and the S slopes, times the
    step's time colour (r, g, b) or opacity (a): (S + W * 4 * (S + 1),) float32."""
    x0, c0, slopes = segments[0], segments[1:5, 0], segments[5:9]
    rows = np.concatenate([c0[:, None], slopes], axis=1).astype(np.float64)  # (4, S + 1)
    per_step = tc.astype(np.float64)[:, :, None] * rows[None]
    return np.concatenate([x0, per_step.ravel()]).astype(np.float32)


@lru_cache(maxsize=256)  # a bisection of ~34 numpy steps (0.6 ms), asked again on every brick
def raw_cut(position: float, value_range: tuple[float, float], lut_size: int) -> float:
    """The smallest float32 raw value v whose LUT position u(v) * (N - 1) is >= `position`.

    The kernels compute u(v) = clip((v - vmin) * scale, 0, 1) in float32; every step of it
    is monotone, so a binary search over the ordered float32 values finds the exact bound.
    """
    vmin, scale = values.normalization(*value_range)
    n1, target = np.float32(lut_size - 1), np.float32(position)

    def reaches(key: int) -> bool:
        v = _float_of_key(key)
        with np.errstate(over="ignore"):  # near the float32 limits: inf, clipped as on the device
            u = np.clip((v - vmin) * scale, np.float32(0.0), np.float32(1.0))
        return bool(u * n1 >= target)

    if scale == 0:  # a constant field: u = 0 everywhere
        return float("-inf") if np.float32(0.0) >= target else float("inf")
    big = np.finfo(np.float32).max  # data are finite
    low, high = _key_of_float(-big), _key_of_float(big)
    if reaches(low):
        return float("-inf")
    if not reaches(high):
        return float("inf")
    while high - low > 1:  # invariant: not reaches(low), reaches(high)
        mid = (low + high) // 2
        if reaches(mid):
            high = mid
        else:
            low = mid
    return float(_float_of_key(high))


def _key_of_float(v: np.float32) -> int:
    """An integer key that orders float32 values as the numbers they are."""
    bits = int(np.array(v, dtype=np.float32).view(np.int32))
    return bits if bits >= 0 else -(bits & 0x7FFFFFFF)


def _float_of_key(key: int) -> np.float32:
    bits = key if key >= 0 else (-key) | -0x80000000
    return np.array(bits, dtype=np.int32).view(np.float32)[()]
