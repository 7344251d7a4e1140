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

`show` then puts what changed into the display `Volume` (the bricks of host RGBA8 that may
differ, and either's box and grid). Winners the kernels did not write are gathered by the
session's engine (`chronocl.engine.gather`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from chronocl.integration.interactive.winners import Winners
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.volume import Volume


@dataclass
class Changed:
    """What one `apply` changed, for `show` to put into `volume`."""

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


def show(changed: Changed, spacing, held: np.ndarray | None = None) -> None:
    """Put `changed` into its `Volume` (on the GL thread): the host RGBA8's bricks that may
    differ from what the texture holds (`held`: the bricks that may be coloured there, the
    `coloured` of the result it holds; None: unknown, the whole texture), then its place in
    the world, occupied box and brick grid. A 512^3 texture is 512 MB; a TF edit of the vortex
    changes a fifth of its bricks."""
    vol = changed.volume
    if changed.rgba is not None:
        redo = np.ones_like(changed.coloured) if held is None else changed.coloured | held
        vol.write_bricks(changed.rgba, redo)
    vol.place(spacing, changed.bounds, changed.bricks)


def empty_bounds() -> np.ndarray:
    """The bounds of no voxel, which the kernels narrow (atomics, or a min and max here)."""
    return np.array([1 << 30] * 3 + [-1] * 3, dtype=np.int32)
