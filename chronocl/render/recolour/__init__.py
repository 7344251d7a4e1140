"""Recolouring: a TF edit of max, min, first_hit or change shown without integrating.

A window's winners (`chronocl.integration.interactive.winners.Winners`: per voxel the value
that won and the winning step) are prepared once per window, then every edit applies a spec to
them: its premultiplied RGBA, the occupied box and the brick grid of empty-space skipping, in
the arithmetic of the integrate kernels (the data TF's LUT lerped as `lut_lerp32`, times the
time TF of the winning step). One protocol, `Recolourer`, two implementations:

- `gl.GLRecolourer`: a compute pass writes the display texture on the GPU (any format).
- `bricks.BrickRecolourer`: the OpenCL device of the host writes RGBA8 brick by brick, only
  the bricks the new or the last TFs may colour (llvmpipe: its compute shaders run far slower
  than PoCL's kernels, and its textures are host memory anyway), in z-spans of rows of bricks
  where the winners are over the device's largest buffer.

`texture.show` then puts what changed into the display `Volume` (the bricks' boxes of host
RGBA8, and either's box and grid); `gather.gather` gathers winners on the OpenCL device.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from chronocl.integration.interactive.winners import Winners
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.camera import world_extent
from chronocl.render.raycaster import Volume


@dataclass
class Changed:
    """What one `apply` changed, for `texture.show` to put into `volume`."""

    volume: Volume  # the display texture it is shown in
    bounds: np.ndarray  # int32 (lo x, y, z, hi x, y, z) of voxels with opacity > 0; hi -1: none
    bricks: np.ndarray  # uint8 brick grid (Z, Y, X)/B, as brick_grid.from_rgba gives it
    rgba: np.ndarray | None = None  # RGBA8 (Z, Y, X, 4) on the host; None: in the texture
    coloured: np.ndarray | None = None  # (Z, Y, X)/B bool: the bricks `rgba` may colour
    rewritten: int = 0  # bricks recoloured (all of them on the GPU)


class Recolourer(Protocol):
    """Prepares a window's winners once, then recolours them for each TF edit."""

    gl_thread: bool  # whether it runs on the thread owning the GL context (writing the texture)

    def prepare(self, winners: Winners):
        """The winners where this recolourer reads them (release it when the window goes)."""

    def apply(self, prepared, spec: IntegrationSpec, into: Volume) -> Changed:
        """The winners under `spec` (its TFs; the rest as they were integrated), to be shown in
        `into` (the viewer's texture of the window)."""


def volume_geometry(dims, spacing) -> tuple[np.ndarray, np.ndarray]:
    """World extent (longest side 1) and voxel size, as `Raycaster.upload` lays them out."""
    extent = world_extent(tuple(dims)[::-1], spacing)
    return extent, extent / np.array(dims, dtype=np.float64)


def occupied_corners(bounds: np.ndarray, dims, extent, voxel) -> tuple[np.ndarray, np.ndarray]:
    """`chronocl.render.upload.Occupancy.corners` from the first and last occupied index per
    axis (x, y, z): grown by one voxel, kept inside the box; none: an empty box."""
    half = extent / 2
    lo, hi = bounds[:3], bounds[3:]
    if hi[0] < 0:
        return half.copy(), -half.copy()
    lo = np.maximum(lo - 1, 0)
    hi = np.minimum(hi + 2, np.array(dims))
    return -half + lo * voxel, -half + hi * voxel


def empty_bounds() -> np.ndarray:
    """The bounds of no voxel, which the kernels narrow (atomics, or a min and max here)."""
    return np.array([1 << 30] * 3 + [-1] * 3, dtype=np.int32)
