"""The building blocks of the synthetic data sets (`chronocl.data.synthetic`): normalised box
axes, Gaussian profiles cut to exactly 0, features fused where they overlap, and frames that
turn smoothly over time.

Equal inputs give bit-identical outputs on any machine: numpy's float32 exp, sin, arctan2 ...
take different SIMD code paths on different CPUs (AVX2, AVX-512) and differ there in the last
bit, so every transcendental function of the data sets is evaluated in float64 and rounded once
to float32 (`f64`), which makes a last-bit difference in float64 vanish in the rounding.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

_F = np.float32
# Gaussian features are cut off at this many standard deviations; the profile is
# shifted and rescaled so that it reaches exactly 0 there (continuous, no seams).
CUT = 3.5
_CUT_FLOOR = float(np.exp(-0.5 * CUT**2))


# Elements per chunk of `f64`: its float64 temporaries stay small at 512^3 and above.
_CHUNK = 1 << 22


def f64(fn: Callable[..., np.ndarray], *args: np.ndarray) -> np.ndarray:
    """fn(*args) evaluated in float64 and rounded to float32 (see the module docstring)."""
    args = np.broadcast_arrays(*args)
    out = np.empty(args[0].shape, dtype=_F)
    flat_out = out.reshape(-1)
    flat = [np.ascontiguousarray(a).reshape(-1) for a in args]
    for i in range(0, flat_out.size, _CHUNK):
        part = [a[i : i + _CHUNK].astype(np.float64) for a in flat]
        flat_out[i : i + _CHUNK] = fn(*part)
    return out


def box_axis(n: int) -> np.ndarray:
    """Voxel-centre coordinates of an axis of n voxels, normalised to [-1, 1]."""
    return ((np.arange(n, dtype=np.float64) * 2.0 + 1.0) / n - 1.0).astype(_F)


def index_range(lo: float, hi: float, n: int) -> slice:
    """Voxels of an axis of n voxels whose centres may lie in [lo, hi]."""
    i0 = max(int(np.floor((lo + 1.0) * n / 2.0 - 0.5)), 0)
    i1 = min(int(np.ceil((hi + 1.0) * n / 2.0 - 0.5)) + 1, n)
    return slice(i0, max(i0, i1))


def gauss(d2: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian of squared distance d2 with width sigma, 1 at 0, exactly 0 beyond CUT sigma."""
    g = f64(np.exp, d2 * _F(-0.5 / sigma**2))
    g -= _F(_CUT_FLOOR)
    g *= _F(1.0 / (1.0 - _CUT_FLOOR))
    return np.maximum(g, 0, out=g)


def union(out: np.ndarray, sl: tuple[slice, ...], f: np.ndarray) -> None:
    """out = 1 - (1 - out)(1 - f) on the sub-box sl: overlapping features fuse smoothly."""
    o = out[sl]
    o += f * (1 - o)


def unit(v: np.ndarray) -> np.ndarray:
    """v scaled to length 1."""
    return v / np.linalg.norm(v)


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotate v by `angle` about the unit vector `axis` (Rodrigues' formula)."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1 - c)


def frame(n0: np.ndarray, n1: np.ndarray, s: float) -> tuple[np.ndarray, ...]:
    """Orthonormal (e1, e2, normal) turning from normal n0 (s = 0) to n1 (s = 1).

    The in-plane vectors are carried along with the normal, so the frame turns
    smoothly over time and a pattern fixed in it does not jump between steps.
    """
    n0, n1 = unit(n0), unit(n1)
    helper = np.array([0.0, 0.0, 1.0]) if abs(n0[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = unit(np.cross(n0, helper))
    axis = np.cross(n0, n1)
    if np.linalg.norm(axis) > 1e-9:
        axis = unit(axis)
        angle = s * float(np.arccos(np.clip(np.dot(n0, n1), -1.0, 1.0)))
        n0, e1 = _rotate(n0, axis, angle), _rotate(e1, axis, angle)
    return e1, np.cross(n0, e1), n0
