"""Recolouring on the GPU: a TF edit of max, min, first_hit or change without integrating.

The winners of a window (`chronocl.integration.interactive.winners.Winners`: per voxel the
value that won and the winning step) go up once, as two 3D textures. A TF edit then uploads
the data TF's LUT and one texel per window step of the time TF, and a compute pass
(kernels/glsl/recolour.comp) writes each voxel's premultiplied RGBA into the display texture
the raycaster already samples, in its format (RGBA8 or float32), and finds its occupied box
and its brick grid (empty-space skipping) on the way. The raycaster then draws it unchanged,
trilinear and lit as an integrated chronovolume is: the picture equals the integrated one up
to the rounding of two float32 evaluations of the same LUT (tests/test_recolour.py).

Needs OpenGL 4.3 compute shaders (llvmpipe and GPU drivers have them); `available` says
whether the context has them, and without them a TF edit integrates as before.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from chronocl.integration.interactive.winners import Winners, step_table
from chronocl.modes.spec import IntegrationSpec
from chronocl.render import brick_grid
from chronocl.render.camera import world_extent
from chronocl.render.gl import shader_source
from chronocl.render.raycaster import Volume
from chronocl.render.upload import display_format

GROUP = 8  # recolour.comp's groups: 8 x-rows (along y), one invocation a row
_IMAGE_FORMAT = {"f1": "rgba8", "f4": "rgba32f"}


def available(ctx) -> bool:
    """Whether `ctx` runs compute shaders (OpenGL 4.3)."""
    return ctx.version_code >= 430


@dataclass
class RecolourVolume:
    """A window's winners on the GPU, and the display texture they are recoloured into."""

    won_u: object
    won_k: object
    winners: Winners  # its steps and spec; the arrays are on the GPU (empty here)
    dims: tuple[int, int, int]  # voxels along x, y, z
    volume: Volume | None = None  # its own display texture, made on the first recolour into none

    def release(self) -> None:
        """Free the winners' textures and the display texture of its own, if it made one."""
        self.won_u.release()
        self.won_k.release()
        if self.volume is not None:
            self.volume.release()
            self.volume = None


_recolourers: dict[int, tuple[object, Recolourer]] = {}


def recolourer(ctx) -> Recolourer:
    """The `Recolourer` of `ctx`, built on first use (call it in the thread owning `ctx`)."""
    held = _recolourers.get(id(ctx))
    if held is None or held[0] is not ctx:
        held = _recolourers[id(ctx)] = (ctx, Recolourer(ctx))
    return held[1]


class Recolourer:
    """Uploads winners and recolours them on one GL context (built once per context)."""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self._programs: dict[str, object] = {}
        self._bounds = ctx.buffer(reserve=24)
        self._grid = None  # the brick grid's buffer, sized on first use

    def _program(self, fmt: str):
        if fmt not in self._programs:
            source = shader_source("recolour.comp").replace("OUT_FORMAT", _IMAGE_FORMAT[fmt])
            self._programs[fmt] = self.ctx.compute_shader(source)
        return self._programs[fmt]

    def upload(self, w: Winners) -> RecolourVolume:
        """The winners as two 3D textures (R32F values, R8UI or R16UI step indices)."""
        import moderngl

        nz, ny, nx = w.u.shape
        u = self.ctx.texture3d((nx, ny, nz), 1, np.ascontiguousarray(w.u), dtype="f4")
        kd = "u1" if w.k.dtype == np.uint8 else "u2"
        k = self.ctx.texture3d((nx, ny, nz), 1, np.ascontiguousarray(w.k), dtype=kd)
        for tex in (u, k):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        # the host keeps no copy: the winners' arrays are dropped here
        empty = dataclasses.replace(
            w, u=np.empty((0, 0, 0), np.float32), k=np.empty((0, 0, 0), w.k.dtype)
        )
        return RecolourVolume(u, k, empty, (nx, ny, nz))

    def recolour(
        self,
        rv: RecolourVolume,
        spec: IntegrationSpec,
        spacing: tuple[float, float, float],
        fmt: str | None = None,
        volume: Volume | None = None,
    ) -> Volume:
        """`rv`'s display texture recoloured under `spec` (its TFs; everything else as the
        winners were integrated), with its world box, occupied box and brick grid; `spacing`
        (x, y, z); `fmt` the texture's format ("f1" RGBA8, "f4" float32; default: the
        viewer's `display_format` for the size). Written into `volume` (a viewer's texture of
        the window) when it has the size and format, else into a texture of `rv`'s own."""
        import moderngl

        nx, ny, nz = rv.dims
        fmt = fmt or display_format(nx * ny * nz)

        def fits(v: Volume | None) -> bool:
            return (
                v is not None and tuple(v.texture.size) == (nx, ny, nz) and v.texture.dtype == fmt
            )

        if fits(volume):
            vol = volume
        else:
            if rv.volume is not None and not fits(rv.volume):
                rv.volume.release()
                rv.volume = None
            if rv.volume is None:
                tex = self.ctx.texture3d((nx, ny, nz), 4, dtype=fmt)
                tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                tex.repeat_x = tex.repeat_y = tex.repeat_z = False
                rv.volume = Volume(tex, np.zeros(3), 0.0, (np.zeros(3), np.zeros(3)))
            vol = rv.volume
        w = rv.winners
        lut = np.ascontiguousarray(spec.data_tf.lut, dtype=np.float32)
        table = step_table(spec, w.steps, w.n_steps)
        lut_tex = self.ctx.texture((lut.shape[0], 1), 4, lut.tobytes(), dtype="f4")
        table_tex = self.ctx.texture((table.shape[0], 1), 4, table.tobytes(), dtype="f4")
        try:
            for tex in (lut_tex, table_tex):
                tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            prog = self._program(fmt)
            for unit, (name, tex) in enumerate(
                [
                    ("won_u", rv.won_u),
                    ("won_k", rv.won_k),
                    ("data_lut", lut_tex),
                    ("step_table", table_tex),
                ]
            ):
                tex.use(location=unit)
                prog[name].value = unit
            prog["lut_size"].value = lut.shape[0]
            prog["none_k"].value = w.none
            prog["dims"].value = (nx, ny, nz)
            prog["unorm8"].value = fmt == "f1"
            gz, gy, gx = brick_grid.grid_shape((nz, ny, nx))
            prog["brick"].value = brick_grid.BRICK
            prog["grid_dims"].value = (gx, gy, gz)
            self._bounds.write(np.array([1 << 30] * 3 + [-1] * 3, dtype=np.int32).tobytes())
            self._bounds.bind_to_storage_buffer(1)
            grid = self._grid_buffer(gx * gy * gz)
            grid.bind_to_storage_buffer(2)
            vol.texture.bind_to_image(0, read=False, write=True)
            prog.run(-(-ny // GROUP), nz, 1)
            self.ctx.memory_barrier()
            bounds = np.frombuffer(self._bounds.read(), dtype=np.int32)
            peaks = np.frombuffer(grid.read(size=4 * gx * gy * gz), dtype=np.uint32)
        finally:
            lut_tex.release()
            table_tex.release()
        extent, voxel = volume_geometry((nx, ny, nz), spacing)
        vol.extent, vol.unit = extent, float(np.min(voxel))
        vol.occupied = occupied_corners(bounds, (nx, ny, nz), extent, voxel)
        bricks = np.minimum(peaks, 255).astype(np.uint8).reshape(gz, gy, gx)
        vol.bricks = brick_grid.texture(self.ctx, bricks, vol.bricks)
        return vol

    def _grid_buffer(self, n: int):
        """The brick grid's buffer (a uint per brick), zeroed, grown when too small."""
        if self._grid is None or self._grid.size < 4 * n:
            if self._grid is not None:
                self._grid.release()
            self._grid = self.ctx.buffer(reserve=4 * n)
        self._grid.clear()
        return self._grid

    def release(self) -> None:
        self._bounds.release()
        if self._grid is not None:
            self._grid.release()
        for prog in self._programs.values():
            prog.release()
        self._programs = {}


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
