"""The brick occupancy grid: the largest opacity a sample can read in each B^3 brick.

The raycaster (kernels/glsl/raycast.frag) jumps a ray across every brick whose grid value is 0,
to the first sample past the brick on the same sample phase, so the picture is the unskipped
one and a sparse chronovolume costs about what its occupied bricks cost.

A brick holds the voxels [b*B, (b+1)*B) of each axis, and its value is the maximum opacity of
the voxels [b*B - 1, (b+1)*B] (grown by one voxel): a trilinear sample at a point inside the
brick reads the two voxels around it, which reach one voxel beyond the brick on either side.
A value of 0 therefore means every sample the shader takes in the brick has opacity 0, which
the shader composites as nothing. Opacities are kept as uint8 (`ceil(a * 255)` of float data,
so any opacity above 0 stays above 0) in a one-channel R8 3D texture.

B = 8: the grid of a 512^3 volume is 64^3 (256 KB, nothing to upload), and a brick is small
enough to follow thin features (the vortex's tubes leave most bricks of their bounding box
empty). Measured with bench/render_skip.py's volumes (vortex, max mode, 930x640, llvmpipe,
draw time without skipping 873 ms at 256^3): 4^3 bricks 312 ms (fewer samples, but twice the
grid reads and hops), 8^3 276 ms, 16^3 328 ms (a third more samples per ray).

`grid(alpha)` takes the alpha channel (uint8 or float, any strides, e.g. `rgba[..., 3]`) and
returns the grid (`from_rgba(rgba)`: the same from a whole RGBA volume, faster for RGBA8); both
work in z-slabs of bricks on chronocl/core/host_threads.py's pool above
`TUNING.brick_grid_serial_voxels` voxels.
`texture(ctx, grid, previous)` makes (or rewrites) the grid's texture.
"""

from __future__ import annotations

import math
import sys
from concurrent.futures import Future, ThreadPoolExecutor
from itertools import pairwise

import numpy as np

from chronocl.core import host_threads
from chronocl.core.errors import InvalidParameterError
from chronocl.core.tuning import TUNING

BRICK = 8
LITTLE_ENDIAN = sys.byteorder == "little"
# not the host pool: a task there waiting on its own slabs could wait for itself
_starter = ThreadPoolExecutor(1, thread_name_prefix="chronocl-bricks")


def grid_shape(shape: tuple[int, int, int], brick: int = BRICK) -> tuple[int, int, int]:
    """(Z, Y, X) bricks covering a volume of `shape` (the last brick of an axis may be short)."""
    return tuple(math.ceil(n / brick) for n in shape)  # type: ignore[return-value]


def grid(alpha: np.ndarray, brick: int = BRICK) -> np.ndarray:
    """The largest opacity of each brick grown by one voxel, uint8 (Z/B, Y/B, X/B) rounded up.

    `alpha` is (Z, Y, X): uint8 (0..255) or float (0..1; clipped), any strides."""
    if alpha.ndim != 3 or 0 in alpha.shape:
        raise InvalidParameterError(f"opacity volume of shape {alpha.shape}; expected (Z, Y, X)")
    return _grid(alpha, brick, _as_uint8)


def from_rgba(rgba: np.ndarray, brick: int = BRICK) -> np.ndarray:
    """`grid` of a premultiplied RGBA volume (Z, Y, X, 4). A C-contiguous RGBA8 volume on a
    little-endian host is read as one uint32 per voxel, whose top byte is the opacity: the
    largest uint32 has the largest opacity, and contiguous uint32 maxima are several times
    faster than maxima over the strided opacity channel (512^3: about 60 vs 230 ms here)."""
    if rgba.ndim != 4 or rgba.shape[3] != 4:
        raise InvalidParameterError(f"RGBA volume of shape {rgba.shape}; expected (Z, Y, X, 4)")
    if rgba.dtype == np.uint8 and rgba.flags.c_contiguous and LITTLE_ENDIAN:
        if 0 in rgba.shape:
            raise InvalidParameterError(f"RGBA volume of shape {rgba.shape} is empty")
        return _grid(rgba.view(np.uint32)[..., 0], brick, _top_byte)
    return grid(rgba[..., 3], brick)


def submit(rgba: np.ndarray) -> Future:
    """`from_rgba(rgba)` started on a thread of its own (its slabs still go to the pool), so the
    caller can write the volume's texture meanwhile; `.result()` is the grid."""
    return _starter.submit(from_rgba, rgba)


def occupied_bounds(grid: np.ndarray, rgba: np.ndarray, brick: int = BRICK) -> np.ndarray:
    """The first and last voxel of `rgba` (Z, Y, X, 4) with opacity > 0 along x, y and z, as
    `chronocl.render.upload.Occupancy.bounds` gives them (none: [0, 0, 0, -1, -1, -1]), from
    its `grid` and a few planes of it. A brick's value covers its voxels grown by one, so where
    the bricks of layers below b are all 0 and layer b's are not, the first occupied plane lies
    in [b*B, (b+1)*B]; where the layers above b are all 0, the last in [b*B - 1, (b+1)*B - 2]
    (or up to the volume's last plane where b is the grid's last layer).
    Only those planes are read (within the box found so far): at 512^3 a few ms, where a pass
    over the volume took 40-50 ms before the texture's write. For RGBA8 (or NaN-free float):
    the grid's maxima carry a NaN through, and a brick holding one reads as empty."""
    if grid.shape != grid_shape(rgba.shape[:3], brick):
        raise InvalidParameterError(
            f"a brick grid of shape {grid.shape} for a volume of {rgba.shape[:3]} in bricks of "
            f"{brick}: build it with `grid_shape`'s bricks"
        )
    live = grid > 0
    if not live.any():
        return np.array([0, 0, 0, -1, -1, -1])
    alpha = rgba[..., 3]
    box = [slice(None)] * 3  # (z, y, x): narrowed to the bounds found, axis by axis
    lo, hi = {}, {}
    for axis in (0, 1, 2):  # z first: the planes read along y and x are then fewer
        n = alpha.shape[axis]
        layers = np.flatnonzero(live.any(axis=tuple(a for a in range(3) if a != axis)))
        first, last = int(layers[0]), int(layers[-1])
        a0, a1 = first * brick, min((first + 1) * brick + 1, n)
        # (the last layer of the grid has none above it: its last plane may be the volume's)
        b1 = min((last + 1) * brick - 1, n) if last < live.shape[axis] - 1 else n
        b0 = max(last * brick - 1, 0)
        lo[axis] = a0 + _first_filled(alpha, box, axis, a0, a1)
        hi[axis] = b1 - 1 - _first_filled(alpha, box, axis, b0, b1, reverse=True)
        box[axis] = slice(lo[axis], hi[axis] + 1)
    return np.array([lo[2], lo[1], lo[0], hi[2], hi[1], hi[0]])


def _first_filled(alpha, box: list, axis: int, p0: int, p1: int, reverse: bool = False) -> int:
    """The index, from p0 (from p1 - 1 where `reverse`), of the first plane p0..p1 along `axis`
    holding an opacity > 0 within `box`."""
    part = list(box)
    part[axis] = slice(p0, p1)
    filled = np.moveaxis(alpha[tuple(part)] > 0, axis, 0).reshape(p1 - p0, -1).any(axis=1)
    idx = np.flatnonzero(filled[::-1] if reverse else filled)
    if idx.size == 0:  # cannot be, the grid says otherwise: a grid not of this volume
        raise InvalidParameterError("the brick grid is not this volume's: rebuild it")
    return int(idx[0])


def _grid(values: np.ndarray, brick: int, finish) -> np.ndarray:
    if brick < 1:
        raise InvalidParameterError(f"brick size {brick}; use a positive number of voxels")
    out = np.empty(grid_shape(values.shape, brick), dtype=np.uint8)
    gz = out.shape[0]
    if values.size <= TUNING.brick_grid_serial_voxels or gz == 1:
        _slab(values, out, brick, 0, gz, finish)
        return out
    cuts = np.linspace(0, gz, min(gz, 2 * host_threads.workers()) + 1).astype(int)
    jobs = [
        host_threads.pool().submit(_slab, values, out, brick, a, b, finish)
        for a, b in pairwise(cuts.tolist())
        if b > a
    ]
    for job in jobs:
        job.result()
    return out


def _slab(values: np.ndarray, out: np.ndarray, brick: int, g0: int, g1: int, finish) -> None:
    """out[g0:g1] from the voxels its bricks reach: z from g0*B - 1 to g1*B (clamped)."""
    nz = values.shape[0]
    z0, z1 = max(g0 * brick - 1, 0), min(g1 * brick + 1, nz)
    # grown brick maxima along z, y, x in turn, in the data's type; each pass shrinks its
    # axis by B, so the first (over the whole slab) costs nearly all the time
    reduced = _axis_max(values[z0:z1], 0, brick, first=g0 * brick - z0, count=g1 - g0)
    reduced = _axis_max(reduced, 1, brick, first=0, count=out.shape[1])
    reduced = _axis_max(reduced, 2, brick, first=0, count=out.shape[2])
    out[g0:g1] = finish(reduced)


def _top_byte(peak: np.ndarray) -> np.ndarray:
    return (peak >> 24).astype(np.uint8)


def _as_uint8(peak: np.ndarray) -> np.ndarray:
    """uint8 opacities as they are; float ones as ceil(a * 255) in 0..255 (above 0 stays so)."""
    if peak.dtype == np.uint8:
        return peak
    scaled = np.ceil(np.multiply(peak, 255, dtype=np.float64))
    return np.clip(np.nan_to_num(scaled), 0, 255).astype(np.uint8)


def _axis_max(a: np.ndarray, axis: int, brick: int, first: int, count: int) -> np.ndarray:
    """Along `axis`, the maximum over [first + k*B - 1, first + (k+1)*B] (clamped to the array)
    for k in 0..count-1: the brick's own B voxels by a reshaped reduction (the last brick may
    be short), then the one voxel either side of it."""
    a = np.moveaxis(a, axis, 0)
    n = a.shape[0]
    full = min(count, (n - first) // brick)
    out = np.empty((count, *a.shape[1:]), dtype=a.dtype)
    if full:
        core = a[first : first + full * brick]
        np.max(core.reshape(full, brick, *a.shape[1:]), axis=1, out=out[:full])
    if full < count:  # the short last brick
        out[full] = a[first + full * brick :].max(axis=0)
    # the voxel before brick k is first + k*B - 1, the one after it first + (k+1)*B: strided
    # views (no gathered copies), maxima in place
    k0 = 0 if first >= 1 else 1  # brick 0 of the volume has no voxel before it
    before = a[first - 1 + k0 * brick : first + count * brick - 1 : brick]
    np.maximum(out[k0 : k0 + len(before)], before, out=out[k0 : k0 + len(before)])
    after = a[first + brick : first + (count + 1) * brick : brick]
    np.maximum(out[: len(after)], after, out=out[: len(after)])
    return np.moveaxis(out, 0, axis)


def texture(ctx, bricks: np.ndarray, previous=None):
    """A grid (from `grid` or `from_rgba`) as an R8 3D texture (read with texelFetch), written
    into `previous` when it has the grid's size, else a new one (and `previous` released)."""
    size = bricks.shape[::-1]
    if previous is not None and tuple(previous.size) == size:
        previous.write(bricks)
        return previous
    if previous is not None:
        previous.release()
    return ctx.texture3d(size, 1, bricks, dtype="f1")
