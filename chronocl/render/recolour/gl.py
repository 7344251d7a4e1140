"""Recolouring on the GPU: the winners as two 3D textures, each edit one compute pass.

`prepare` uploads the winners once (R32F values, R8UI or R16UI step indices); an edit then
uploads the data TF's LUT and one texel per window step of the time TF, and
kernels/glsl/recolour.comp writes each voxel's premultiplied RGBA into the display texture the
raycaster samples, in its format (RGBA8 or float32), finding its occupied box and brick grid on
the way. The picture equals the integrated one up to the rounding of two float32 evaluations of
the same LUT (tests/test_recolour.py).

Needs OpenGL 4.3 compute shaders (llvmpipe and GPU drivers have them: `available`); call
everything on the thread owning the context.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from chronocl.integration.interactive.winners import Winners, step_table
from chronocl.modes.spec import IntegrationSpec
from chronocl.render import brick_grid
from chronocl.render.gl import shader_source
from chronocl.render.recolour import Changed, empty_bounds
from chronocl.render.upload import display_format
from chronocl.render.volume import Volume

GROUP = 8  # recolour.comp's groups: 8 x-rows (along y), one invocation a row
_IMAGE_FORMAT = {"f1": "rgba8", "f4": "rgba32f"}
SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast", "lavapipe")


def available(ctx) -> bool:
    """Whether `ctx` runs compute shaders (OpenGL 4.3)."""
    return ctx.version_code >= 430


def software_gl(ctx) -> bool:
    """Whether the GL context renders on the CPU (Mesa's llvmpipe and kin)."""
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(name in renderer for name in SOFTWARE_GL)


@dataclass
class GLWinners:
    """A window's winners on the GPU, and the display texture of its own where the viewer's
    does not fit (made on first use)."""

    won_u: object
    won_k: object
    winners: Winners  # its steps and spec; the arrays are on the GPU (empty here)
    dims: tuple[int, int, int]  # voxels along x, y, z
    volume: Volume | None = None

    def release(self) -> None:
        """Free the winners' textures and the display texture of its own, if it made one."""
        self.won_u.release()
        self.won_k.release()
        if self.volume is not None:
            self.volume.release()
            self.volume = None


_recolourers: dict[int, tuple[object, GLRecolourer]] = {}


def recolourer(ctx) -> GLRecolourer:
    """The `GLRecolourer` of `ctx`, built on first use."""
    held = _recolourers.get(id(ctx))
    if held is None or held[0] is not ctx:
        held = _recolourers[id(ctx)] = (ctx, GLRecolourer(ctx))
    return held[1]


class GLRecolourer:
    """`chronocl.render.recolour.Recolourer` on one GL context (built once per context)."""

    gl_thread = True

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

    def prepare(self, winners: Winners) -> GLWinners:
        """The winners as two 3D textures; the host keeps no copy."""
        import moderngl

        w = winners
        nz, ny, nx = w.u.shape
        u = self.ctx.texture3d((nx, ny, nz), 1, np.ascontiguousarray(w.u), dtype="f4")
        kd = "u1" if w.k.dtype == np.uint8 else "u2"
        k = self.ctx.texture3d((nx, ny, nz), 1, np.ascontiguousarray(w.k), dtype=kd)
        for tex in (u, k):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        empty = dataclasses.replace(
            w, u=np.empty((0, 0, 0), np.float32), k=np.empty((0, 0, 0), w.k.dtype)
        )
        return GLWinners(u, k, empty, (nx, ny, nz))

    def apply(self, prepared: GLWinners, spec: IntegrationSpec, into: Volume | None) -> Changed:
        """The winners under `spec` written into `into`'s texture where it has their size,
        else into a texture of `prepared`'s own (in the viewer's `display_format`)."""
        nx, ny, nz = dims = prepared.dims
        fmt = into.texture.dtype if into is not None else display_format(nx * ny * nz)
        vol = into if _fits(into, dims, fmt) else self._own(prepared, fmt)
        w = prepared.winners
        lut = np.ascontiguousarray(spec.data_tf.lut, dtype=np.float32)
        table = step_table(spec, w.steps, w.n_steps)
        lut_tex, table_tex = self._table(lut), self._table(table)
        try:
            prog = self._program(fmt)
            textures = [prepared.won_u, prepared.won_k, lut_tex, table_tex]
            for unit, (name, tex) in enumerate(
                zip(("won_u", "won_k", "data_lut", "step_table"), textures, strict=True)
            ):
                tex.use(location=unit)
                prog[name].value = unit
            prog["lut_size"].value = lut.shape[0]
            prog["none_k"].value = w.none
            prog["dims"].value = dims
            prog["unorm8"].value = fmt == "f1"
            gz, gy, gx = brick_grid.grid_shape((nz, ny, nx))
            prog["brick"].value = brick_grid.BRICK
            prog["grid_dims"].value = (gx, gy, gz)
            self._bounds.write(empty_bounds().tobytes())
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
        bricks = np.minimum(peaks, 255).astype(np.uint8).reshape(gz, gy, gx)
        return Changed(vol, bounds, bricks, rewritten=bricks.size)

    def _own(self, prepared: GLWinners, fmt: str) -> Volume:
        """`prepared`'s own display texture in `fmt`, made (again) where it has none in it."""
        if prepared.volume is not None and not _fits(prepared.volume, prepared.dims, fmt):
            prepared.volume.release()
            prepared.volume = None
        if prepared.volume is None:
            prepared.volume = Volume.allocate(self.ctx, prepared.dims, fmt)
        return prepared.volume

    def _table(self, rows: np.ndarray):
        """A (n, 1) RGBA32F texture of float32 `rows` (n, 4), read texel by texel."""
        import moderngl

        tex = self.ctx.texture((rows.shape[0], 1), 4, rows.tobytes(), dtype="f4")
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return tex

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


def _fits(v: Volume | None, dims, fmt: str) -> bool:
    return v is not None and v.fits(dims, fmt)
