"""What a recolouring changed, put into its display texture (`show`, on the GL thread).

Both recolourers give their occupied box and brick grid, which become the `Volume`'s; the
brick-wise one's RGBA8 lies on the host, and only the bricks that may differ from what the
texture holds go up: per z-slab of bricks, the box of those bricks, read in place from the
array (GL's unpack row length and image height; moderngl writes only contiguous boxes, so
glTexSubImage3D and glPixelStorei are called through eglGetProcAddress). A 512^3 texture is
512 MB; a TF edit of the vortex changes a fifth of its bricks.
"""

from __future__ import annotations

import ctypes
from functools import cache

import numpy as np

from chronocl.render import brick_grid
from chronocl.render.recolour import Changed, occupied_corners, volume_geometry

B = brick_grid.BRICK


def upload_boxes(changed: np.ndarray, dims: tuple[int, int, int]) -> list[tuple[int, ...]]:
    """Voxel boxes (x0, y0, z0, x1, y1, z1) covering the bricks of `changed` ((Z, Y, X)/B
    bool): per z-slab of bricks, the box of its changed bricks."""
    nx, ny, nz = dims
    boxes = []
    for bz in np.flatnonzero(changed.any(axis=(1, 2))):
        ys = np.flatnonzero(changed[bz].any(axis=1))
        xs = np.flatnonzero(changed[bz].any(axis=0))
        boxes.append(
            (
                int(xs[0]) * B, int(ys[0]) * B, int(bz) * B,
                min((int(xs[-1]) + 1) * B, nx), min((int(ys[-1]) + 1) * B, ny),
                min((int(bz) + 1) * B, nz),
            )
        )  # fmt: skip
    return boxes


@cache
def _gl_functions():
    """glPixelStorei, glTexSubImage3D and glBindBuffer of the current EGL context (moderngl
    writes only whole boxes of contiguous data)."""
    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]

    def fn(name: str, *args):
        address = egl.eglGetProcAddress(name.encode())
        if not address:
            raise OSError(f"no {name} in this OpenGL")
        return ctypes.CFUNCTYPE(None, *args)(address)

    i, u = ctypes.c_int, ctypes.c_uint
    store = fn("glPixelStorei", u, i)
    sub = fn("glTexSubImage3D", u, i, i, i, i, i, i, i, u, u, ctypes.c_void_p)
    bind = fn("glBindBuffer", u, u)
    return store, sub, bind


GL_TEXTURE_3D, GL_RGBA, GL_UNSIGNED_BYTE = 0x806F, 0x1908, 0x1401
GL_UNPACK_ROW_LENGTH, GL_UNPACK_IMAGE_HEIGHT, GL_UNPACK_ALIGNMENT = 0x0CF2, 0x806E, 0x0CF5
GL_PIXEL_UNPACK_BUFFER = 0x88EC


def write_boxes(ctx, texture, rgba: np.ndarray, boxes) -> None:
    """Write the `boxes` (voxel boxes of `upload_boxes`) of the C-contiguous RGBA8 `rgba`
    (Z, Y, X, 4) into the RGBA8 3D `texture` of the same size, reading `rgba` in place."""
    _, ny, nx, _ = rgba.shape
    store, sub, bind = _gl_functions()
    texture.use(location=ctx.default_texture_unit)
    bind(GL_PIXEL_UNPACK_BUFFER, 0)  # the pointer is host memory, not a buffer's offset
    base = rgba.ctypes.data
    store(GL_UNPACK_ROW_LENGTH, nx)
    store(GL_UNPACK_IMAGE_HEIGHT, ny)
    store(GL_UNPACK_ALIGNMENT, 4)
    try:
        for x0, y0, z0, x1, y1, z1 in boxes:
            at = base + 4 * ((z0 * ny + y0) * nx + x0)
            size = (x1 - x0, y1 - y0, z1 - z0)
            sub(GL_TEXTURE_3D, 0, x0, y0, z0, *size, GL_RGBA, GL_UNSIGNED_BYTE, at)
    finally:
        store(GL_UNPACK_ROW_LENGTH, 0)
        store(GL_UNPACK_IMAGE_HEIGHT, 0)


def show(ctx, changed: Changed, spacing, held: np.ndarray | None = None) -> None:
    """Put `changed` into its `Volume`: the host RGBA8's bricks that may differ from what the
    texture holds (`held`: the bricks that may be coloured there, the `coloured` of the result
    it holds; None: unknown, the whole texture), its world box, occupied box and brick grid."""
    vol = changed.volume
    dims = tuple(vol.texture.size)  # x, y, z
    if changed.rgba is not None:
        redo = np.ones_like(changed.coloured) if held is None else changed.coloured | held
        write_boxes(ctx, vol.texture, changed.rgba, upload_boxes(redo, dims))
    extent, voxel = volume_geometry(dims, spacing)
    vol.extent, vol.unit = extent, float(np.min(voxel))
    vol.occupied = occupied_corners(changed.bounds, dims, extent, voxel)
    vol.bricks = brick_grid.texture(ctx, changed.bricks, vol.bricks)
