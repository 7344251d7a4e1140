"""Feature enhancement factors e_k: edge (gradient magnitude) and view-dependent silhouette.

Gradients g = ∇u by central differences in voxel units, one-sided at the
borders (`numpy.gradient`, edge_order=1); an axis of length 1 has zero
gradient. Edge: e = k0 + k1·|g|^k2. Silhouette: e = k0 + k1·(1 - |ĝ·view|)^k2
with ĝ = g/|g|, and e = k0 where |g| = 0. Computed on a z-slab with a one-voxel
halo, the interior equals the whole-volume result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError

ENHANCE_KINDS = ("none", "edge", "silhouette")
_DEFAULTS = {"none": (1.0, 0.0, 1.0), "edge": (0.2, 6.0, 1.0), "silhouette": (0.15, 1.0, 1.0)}


@dataclass(frozen=True)
class Enhance:
    """Enhancement kind and parameters; `view` is the viewing direction (x, y, z)."""

    kind: str = "none"
    k0: float | None = None
    k1: float | None = None
    k2: float | None = None
    view: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        if self.kind not in ENHANCE_KINDS:
            raise UnknownNameError(
                f"unknown enhancement {self.kind!r}; choose one of {', '.join(ENHANCE_KINDS)}"
            )
        for name, default in zip(("k0", "k1", "k2"), _DEFAULTS[self.kind], strict=True):
            value = getattr(self, name)
            value = default if value is None else float(value)
            if not math.isfinite(value) or value < 0:
                raise InvalidParameterError(
                    f"enhancement {name} is {value}; it must be a finite number >= 0"
                )
            object.__setattr__(self, name, value)
        v = np.asarray(self.view, dtype=np.float64)
        norm = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
        if not (math.isfinite(norm) and norm > 0):
            raise InvalidParameterError(
                f"enhancement view {self.view!r} must be three finite numbers, not all zero"
            )
        object.__setattr__(self, "view", tuple(float(c) for c in v / norm))

    @property
    def needs_gradient(self) -> bool:
        return self.kind != "none"

    def to_dict(self) -> dict:
        return {"kind": self.kind, "k0": self.k0, "k1": self.k1, "k2": self.k2, "view": self.view}


def gradient(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(gx, gy, gz) of a (Z, Y, X) volume in voxel units."""
    parts = []
    for axis in (2, 1, 0):
        if u.shape[axis] < 2:
            parts.append(np.zeros(u.shape, dtype=np.float64))
        else:
            parts.append(np.gradient(u.astype(np.float64), axis=axis))
    return parts[0], parts[1], parts[2]


def factor(u: np.ndarray, enhance: Enhance) -> np.ndarray | float:
    """The enhancement factor e for one step's normalised volume u (Z, Y, X)."""
    if enhance.kind == "none":
        return 1.0
    gx, gy, gz = gradient(u)
    mag = np.sqrt(gx * gx + gy * gy + gz * gz)
    if enhance.kind == "edge":
        return enhance.k0 + enhance.k1 * mag**enhance.k2
    vx, vy, vz = enhance.view
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(gx * vx + gy * vy + gz * vz) / mag
    sil = enhance.k0 + enhance.k1 * np.clip(1.0 - cos, 0.0, 1.0) ** enhance.k2
    return np.where(mag > 0, sil, enhance.k0)
