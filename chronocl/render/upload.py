"""Display textures: a chronovolume's premultiplied RGBA made ready for a 3D texture, fast.

Formats: "f4" float32 (no conversion), "f2" half float, "f1" RGBA8 unorm (round(v * 255),
clipped to 0..255). `convert` works in z-slab tasks on a small thread pool (numpy's casts and
ufuncs release the GIL), one cache-sized block at a time, straight into a staging buffer: for
the viewer's frames one from the pool of reused host buffers (`chronocl.core.memory`), let go
once written, whose memory the next frame takes again, already faulted in. The same pass
finds the slices, rows and columns with opacity > 0, from which the raycaster's occupied box
comes, so the volume is read once. Which format the viewer sends at which size, and why:
docs/display.md.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from chronocl.core import host_threads
from chronocl.core.errors import InvalidParameterError
from chronocl.core.memory import recycled_empty
from chronocl.core.tuning import TUNING
from chronocl.integration import inmemory

FORMATS: dict[str, type] = {"f4": np.float32, "f2": np.float16, "f1": np.uint8}
LITTLE_ENDIAN = sys.byteorder == "little"
_scratch = threading.local()


def display_format(voxels: int) -> str:
    """The viewer's texture format for a volume of `voxels`: RGBA8 above `DISPLAY_VOXELS`
    (`chronocl.integration.inmemory`'s: the display integration writes the same format),
    float32 (exact, nothing to convert) below, where every format costs about a millisecond.

    Measured with bench/upload.py (docs/display.md; 2 cores, llvmpipe, 512^2): llvmpipe
    draws RGBA8 faster than float32 at every size tried (64^3: 77 vs 84 ms, 128^3: 120-141
    vs 126-186 ms, 256^3: 268-289 vs 365-422 ms), its conversion costs a few ms more than
    float32's occupancy-only pass and its write a quarter; half floats lose on both
    (numpy's float16 cast is 8x slower than the RGBA8 rounding). The image stays within
    3/255 on 99.9 % of pixels (PSNR >= 56 dB)."""
    return "f4" if voxels <= inmemory.DISPLAY_VOXELS else "f1"


@dataclass
class Occupancy:
    """Which slices (z), rows (y) and columns (x) hold a voxel with opacity > 0."""

    z: np.ndarray
    y: np.ndarray
    x: np.ndarray

    def bounds(self) -> np.ndarray:
        """The first and last occupied index along x, y, z (`occupied_corners`' bounds)."""
        if not self.z.any():
            return np.array([0, 0, 0, -1, -1, -1])
        idx = [np.flatnonzero(filled) for filled in (self.x, self.y, self.z)]
        return np.array([i[0] for i in idx] + [i[-1] for i in idx])


def occupied_corners(bounds, size, extent: np.ndarray, voxel: np.ndarray):
    """World corners of the voxels from index `bounds` (the first occupied x, y, z, then the
    last; a last x below 0: none) grown by one voxel (trilinear reach) and kept inside the box
    of `size` (x, y, z) voxels of `voxel` (world_geometry's extent and voxel); none gives an
    empty box (min > max: every ray misses)."""
    half = extent / 2
    lo, hi = np.asarray(bounds[:3]), np.asarray(bounds[3:])
    if hi[0] < 0:
        return half.copy(), -half.copy()
    lo = np.maximum(lo - 1, 0)
    hi = np.minimum(hi + 2, np.array(size))
    return -half + lo * voxel, -half + hi * voxel


def occupancy(alpha: np.ndarray) -> Occupancy:
    """The occupancy of an opacity volume (Z, Y, X), serially (small volumes, tests)."""
    filled = alpha > 0
    return Occupancy(filled.any(axis=(1, 2)), filled.any(axis=(0, 2)), filled.any(axis=(0, 1)))


def staging_for(
    shape: tuple[int, ...], fmt: str, staging: np.ndarray | None, pooled: bool = False
) -> np.ndarray:
    """`staging` when it has this shape and format's type, else a new C-contiguous buffer:
    where `pooled`, from the pool (`recycled_empty`: the memory of the last one of its size
    that died). Not by default: a render's half floats would be a size of their own in the
    pool, pushing out the spares of the chronovolumes integrated between renders."""
    dtype = np.dtype(FORMATS[fmt])
    if (
        staging is not None
        and staging.shape == tuple(shape)
        and staging.dtype == dtype
        and staging.flags.c_contiguous
    ):
        return staging
    return recycled_empty(tuple(shape), dtype) if pooled else np.empty(shape, dtype=dtype)


def convert(
    rgba: np.ndarray,
    fmt: str,
    staging: np.ndarray | None = None,
    pooled: bool = False,
    occupancy: bool = True,
) -> tuple[np.ndarray, Occupancy | None]:
    """Premultiplied RGBA (Z, Y, X, 4) as texture data of format `fmt`, and its occupancy.

    The data is written into `staging` when it fits, else into a new buffer, from the pool
    where `pooled` (`staging_for`: let it go once written, the next call takes its memory
    again). A C-contiguous float32 input for "f4", or uint8 (RGBA8, a display chronovolume)
    for "f1", is returned as it is, with its occupancy, or None where not `occupancy` (a
    pass over the volume of its own: `brick_grid.occupied_bounds` finds its bounds from the
    brick grid instead). A conversion finds the occupancy in the same pass, whatever is asked.
    """
    if fmt not in FORMATS:
        raise InvalidParameterError(f"texture format {fmt!r}; use one of {', '.join(FORMATS)}")
    if rgba.ndim != 4 or rgba.shape[3] != 4:
        raise InvalidParameterError(f"RGBA volume of shape {rgba.shape}; expected (Z, Y, X, 4)")
    nz, ny, nx, _ = rgba.shape
    # RGBA8 in (a display chronovolume: the kernels wrote it) goes out as it is, as f1.
    if rgba.dtype == np.uint8 and fmt != "f1":
        raise InvalidParameterError(f"RGBA8 volume for texture format {fmt!r}; use 'f1'")
    as_is = rgba.flags.c_contiguous and (
        (fmt == "f4" and rgba.dtype == np.float32) or (fmt == "f1" and rgba.dtype == np.uint8)
    )
    out = rgba if as_is else staging_for(rgba.shape, fmt, staging, pooled)
    if as_is and not occupancy:
        return out, None
    z = np.zeros(nz, dtype=bool)
    y = np.zeros(ny, dtype=bool)
    x = np.zeros(nx, dtype=bool)
    if nz * ny * nx <= TUNING.upload_serial_voxels or nz == 1:
        parts = [_convert_slab(rgba, out, fmt, 0, nz, as_is)]
    else:
        workers = host_threads.workers()
        cuts = np.linspace(0, nz, min(nz, 2 * workers) + 1).astype(int)
        jobs = [
            host_threads.pool().submit(_convert_slab, rgba, out, fmt, a, b, as_is)
            for a, b in pairwise(cuts.tolist())
            if b > a
        ]
        parts = [job.result() for job in jobs]
    for z0, part_z, part_y, part_x in parts:
        z[z0 : z0 + part_z.size] = part_z
        y |= part_y
        x |= part_x
    return out, Occupancy(z, y, x)


def _convert_slab(rgba, out, fmt: str, z0: int, z1: int, as_is: bool):
    """Convert slices z0..z1 block by block; returns (z0, their z, y, x occupancy)."""
    if as_is and rgba.dtype == np.uint8 and LITTLE_ENDIAN:
        return _rgba8_occupancy(rgba, z0, z1)
    _, ny, nx, _ = rgba.shape
    rows = max(1, TUNING.upload_block_values // (4 * nx))
    occ_z = np.zeros(z1 - z0, dtype=bool)
    occ_y = np.zeros(ny, dtype=bool)
    occ_x = np.zeros(nx, dtype=bool)
    scratch = None
    if fmt == "f1" and not as_is:
        scratch = getattr(_scratch, "block", None)
        if scratch is None or scratch.size < rows * nx * 4:
            scratch = _scratch.block = np.empty(rows * nx * 4, dtype=np.float32)
    for k in range(z0, z1):
        for r0 in range(0, ny, rows):
            src = rgba[k, r0 : r0 + rows]
            dst = out[k, r0 : r0 + rows]
            if scratch is not None:
                block = scratch[: src.size].reshape(src.shape)
                np.multiply(src, 255, out=block)
                np.rint(block, out=block)
                np.clip(block, 0, 255, out=block)
                np.copyto(dst, block, casting="unsafe")
                if LITTLE_ENDIAN:  # RGBA8 as one uint32: opacity > 0 when it is > 2^24 - 1
                    filled = dst.view(np.uint32)[..., 0] > 0xFFFFFF
                else:
                    filled = dst[..., 3] > 0
            else:  # f4 or f2, or the data as it is (RGBA8 here: a big-endian host)
                if not as_is:
                    np.copyto(dst, src, casting="same_kind")
                filled = src[..., 3] > 0
            in_rows = filled.any(axis=1)
            if in_rows.any():
                occ_z[k - z0] = True
                occ_y[r0 : r0 + rows] |= in_rows
                occ_x |= filled.any(axis=0)
    return z0, occ_z, occ_y, occ_x


def _rgba8_occupancy(rgba: np.ndarray, z0: int, z1: int):
    """`_convert_slab`'s occupancy of RGBA8 sent as it is: each voxel read as one uint32 whose
    top byte is the opacity, so the largest value of a row or column says whether it holds an
    opaque voxel; maxima of whole slices, without the boolean volume the comparison makes
    (512^3: 82 ms on one thread against 130-146 ms on two)."""
    u = rgba.view(np.uint32)[..., 0]
    ny, nx = u.shape[1:]
    occ_z = np.zeros(z1 - z0, dtype=bool)
    y_peak = np.zeros(ny, dtype=np.uint32)
    x_peak = np.zeros(nx, dtype=np.uint32)
    for k in range(z0, z1):
        rows = u[k].max(axis=1)
        if rows.max() > 0xFFFFFF:
            occ_z[k - z0] = True
            np.maximum(y_peak, rows, out=y_peak)
            np.maximum(x_peak, u[k].max(axis=0), out=x_peak)
    return z0, occ_z, y_peak > 0xFFFFFF, x_peak > 0xFFFFFF
