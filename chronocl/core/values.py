"""Raw values to normalised u in [0, 1], bit for bit the same in every engine."""

from __future__ import annotations

import numpy as np


def normalization(vmin: float, vmax: float) -> tuple[np.float32, np.float32]:
    """(vmin, scale) in float32 with u = (v - vmin) * scale; a constant field gets scale 0."""
    if not vmax > vmin:
        return np.float32(0.0), np.float32(0.0)
    return np.float32(vmin), np.float32(1.0 / (float(vmax) - float(vmin)))


def normalize(v: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """u = clip((v - vmin) / (vmax - vmin), 0, 1) in float32; a constant field maps to 0.

    Done in float32 with a precomputed reciprocal so every engine gets the same bits.
    """
    lo, scale = normalization(vmin, vmax)
    u = (np.asarray(v, dtype=np.float32) - lo) * scale
    return np.clip(u, np.float32(0.0), np.float32(1.0))


def clip_bounds(vmin: float, vmax: float) -> tuple[np.float32, np.float32]:
    """(lo, hi) in float32 of the normalisation range; a constant field gets hi = lo."""
    lo = np.float32(vmin)
    return lo, (np.float32(vmax) if vmax > vmin else lo)


def clip(v: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """The values clipped to the normalisation range, in float32: u = (clip(v) - vmin) * scale.

    Differences of clipped values are exact where the values are integers, so modes that
    compare changes (``change``) compare them here and scale only the winner.
    """
    lo, hi = clip_bounds(vmin, vmax)
    return np.clip(np.asarray(v, dtype=np.float32), lo, hi)
