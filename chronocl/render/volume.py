"""The display volume: a chronovolume's 3D texture and its place in the raycaster's world.

A `Volume` owns what the raycaster samples: the RGBA texture (float32, half float or RGBA8;
trilinear, or nearest), the world box its voxels fill (`world_geometry`), the box of its
occupied voxels and the brick grid across whose empty bricks rays jump
(chronocl/render/brick_grid.py). It is allocated once (`allocate`; the viewer keeps one per
panel and level and rewrites it in place), written in one of three ways, then placed (`place`):

- `write`: the whole texture, in z-slabs where the write may be given up (a refine's frame);
- `write_slab`: one z-slab (a refine's slabs, as they integrate: chronocl/viewer/slab_upload.py);
- `write_bricks`: the bricks a recolouring may have changed (chronocl/render/recolour/), read
  in place from a host RGBA8 array. moderngl writes only contiguous boxes, so these go through
  glTexSubImage3D and the unpack row length and image height (glPixelStorei), called through
  eglGetProcAddress: the only raw GL calls of the display.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field
from functools import cache
from itertools import pairwise

import numpy as np

from chronocl.core.errors import SupersededError
from chronocl.core.tuning import TUNING
from chronocl.render import brick_grid
from chronocl.render.camera import world_geometry
from chronocl.render.upload import occupied_corners

B = brick_grid.BRICK


@dataclass(eq=False)
class Volume:
    """A chronovolume on the GPU: its texture, world-space box, occupied box and brick grid."""

    texture: object
    extent: np.ndarray = field(default_factory=lambda: np.zeros(3))  # world size (x, y, z)
    voxel: np.ndarray = field(default_factory=lambda: np.zeros(3))  # world size of a voxel
    # world corners of the voxels with opacity > 0
    occupied: tuple[np.ndarray, np.ndarray] = field(default_factory=lambda: (np.zeros(3),) * 2)
    # the brick grid's R8 texture (brick_grid.texture), read to skip empty space; None: no skipping
    bricks: object | None = None

    @classmethod
    def allocate(cls, ctx, size, fmt: str, data=None, nearest: bool = False) -> Volume:
        """A new RGBA 3D texture of `size` (x, y, z) and format `fmt` (f4, f2, f1), holding
        `data` if given, sampled trilinearly (or `nearest`), clamped at its faces; placed by
        `place`."""
        import moderngl

        tex = ctx.texture3d(tuple(size), 4, data, dtype=fmt)
        tex.filter = (moderngl.NEAREST,) * 2 if nearest else (moderngl.LINEAR,) * 2
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        return cls(tex)

    @property
    def unit(self) -> float:
        """The world length of one voxel (its smallest side), the opacity reference."""
        return float(np.min(self.voxel))

    def fits(self, size, fmt: str) -> bool:
        """Whether the texture has `size` (x, y, z) and format `fmt`."""
        return tuple(self.texture.size) == tuple(size) and self.texture.dtype == fmt

    def place(self, spacing, bounds, bricks: np.ndarray) -> None:
        """Lay the texture out in the world for voxel `spacing` (x, y, z), with the index
        `bounds` of its voxels with opacity > 0 (`chronocl.render.upload.occupied_corners`)
        and its brick grid (`brick_grid.from_rgba`)."""
        nx, ny, nz = size = self.texture.size
        self.extent, self.voxel = world_geometry((nz, ny, nx), spacing)
        self.occupied = occupied_corners(bounds, size, self.extent, self.voxel)
        self.bricks = brick_grid.texture(self.texture.ctx, bricks, self.bricks)

    def write(self, data: np.ndarray, given_up=None) -> None:
        """Write the whole texture from `data` (Z, Y, X, 4) in its format. With `given_up`, in
        `TUNING.upload_slabs` z-slabs, SupersededError raised between them once it returns
        true (the texture then holds a mix: written whole again before it is drawn)."""
        nz = data.shape[0]
        if given_up is None or nz < TUNING.upload_slabs:
            self.texture.write(data)
            return
        cuts = np.linspace(0, nz, TUNING.upload_slabs + 1).astype(int)
        for z0, z1 in pairwise(cuts.tolist()):
            if given_up():
                raise SupersededError("newer input came while the refined frame was uploaded")
            self.write_slab(data, z0, z1)

    def write_slab(self, data: np.ndarray, z0: int, z1: int) -> None:
        """Write rows z0..z1 of `data` (Z, Y, X, 4, the texture's size and format)."""
        nx, ny, _ = self.texture.size
        slab = np.ascontiguousarray(data[z0:z1])
        self.texture.write(slab, viewport=(0, 0, z0, nx, ny, z1 - z0))

    def write_bricks(self, rgba: np.ndarray, which: np.ndarray) -> None:
        """Write the bricks `which` ((Z, Y, X)/B bool) of the C-contiguous RGBA8 `rgba`
        (Z, Y, X, 4, the texture's size) into the RGBA8 texture, reading `rgba` in place: per
        z-slab of bricks, the box of its bricks in `which`."""
        _, ny, nx, _ = rgba.shape
        store, sub, bind = _gl_functions()
        self.texture.use(location=self.texture.ctx.default_texture_unit)
        bind(GL_PIXEL_UNPACK_BUFFER, 0)  # the pointer is host memory, not a buffer's offset
        base = rgba.ctypes.data
        store(GL_UNPACK_ROW_LENGTH, nx)
        store(GL_UNPACK_IMAGE_HEIGHT, ny)
        store(GL_UNPACK_ALIGNMENT, 4)
        try:
            for x0, y0, z0, x1, y1, z1 in brick_boxes(which, self.texture.size):
                at = base + 4 * ((z0 * ny + y0) * nx + x0)
                size = (x1 - x0, y1 - y0, z1 - z0)
                sub(GL_TEXTURE_3D, 0, x0, y0, z0, *size, GL_RGBA, GL_UNSIGNED_BYTE, at)
        finally:
            store(GL_UNPACK_ROW_LENGTH, 0)
            store(GL_UNPACK_IMAGE_HEIGHT, 0)

    def release(self) -> None:
        self.texture.release()
        if self.bricks is not None:
            self.bricks.release()
            self.bricks = None


def brick_boxes(which: np.ndarray, size) -> list[tuple[int, ...]]:
    """Voxel boxes (x0, y0, z0, x1, y1, z1) covering the bricks of `which` ((Z, Y, X)/B bool)
    in a volume of `size` (x, y, z): per z-slab of bricks, the box of its bricks."""
    nx, ny, nz = size
    boxes = []
    for bz in np.flatnonzero(which.any(axis=(1, 2))):
        ys = np.flatnonzero(which[bz].any(axis=1))
        xs = np.flatnonzero(which[bz].any(axis=0))
        boxes.append(
            (
                int(xs[0]) * B, int(ys[0]) * B, int(bz) * B,
                min((int(xs[-1]) + 1) * B, nx), min((int(ys[-1]) + 1) * B, ny),
                min((int(bz) + 1) * B, nz),
            )
        )  # fmt: skip
    return boxes


GL_TEXTURE_3D, GL_RGBA, GL_UNSIGNED_BYTE = 0x806F, 0x1908, 0x1401
GL_UNPACK_ROW_LENGTH, GL_UNPACK_IMAGE_HEIGHT, GL_UNPACK_ALIGNMENT = 0x0CF2, 0x806E, 0x0CF5
GL_PIXEL_UNPACK_BUFFER = 0x88EC


@cache
def _gl_functions():
    """glPixelStorei, glTexSubImage3D and glBindBuffer of the current EGL context."""
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
