"""The moderngl raycaster: a chronovolume as a 3D texture, rays through the box, PNG-ready pixels.

See kernels/glsl/raycast.frag for the compositing. A `Volume` (chronocl/render/volume.py) is
an uploaded chronovolume (RGBA16F or RGBA8 texture, trilinear or nearest) with its world-space
box; `draw` renders one view of it into an (H, W, 3) uint8 array, top-down; with `shading`
(chronocl/render/shading.py) it runs the lit build of the shader, without it the unlit one,
unchanged. Each volume carries its brick occupancy grid (chronocl/render/brick_grid.py), across
whose empty bricks rays jump (`skip`, on by default; the picture is the same), and `samples`
counts what a ray costs.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np

from chronocl.core.errors import InvalidParameterError, SupersededError
from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.render import brick_grid
from chronocl.render.camera import Camera
from chronocl.render.gl import gl_context, program
from chronocl.render.shading import OFF, Shading
from chronocl.render.upload import convert, occupancy, occupied_corners
from chronocl.render.volume import Volume

MIN_SIZE, MAX_SIZE = 16, 8192
BRICKS_UNIT = 5  # the brick grid's texture unit, clear of the volume's (0) and others' low units


def check_size(size: tuple[int, int]) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"image size {size!r} must be two integers (W, H)") from None
    if not (MIN_SIZE <= w <= MAX_SIZE and MIN_SIZE <= h <= MAX_SIZE):
        raise InvalidParameterError(
            f"image size {w}x{h} is outside {MIN_SIZE}..{MAX_SIZE} pixels per side; "
            "choose e.g. --size 512x512"
        )
    return w, h


class Raycaster:
    """Renders uploaded chronovolumes on the process's GL context."""

    def __init__(self, ctx=None) -> None:
        """On the process's context, or on `ctx` (a context current in the calling thread)."""
        self.ctx = gl_context() if ctx is None else ctx
        self.prog = program(self.ctx, "raycast")
        self.vao = self.ctx.vertex_array(self.prog, [])
        self._lit: tuple | None = None  # the lit program and its vertex array, on first use
        self._counting: tuple | None = None  # the COUNT_SAMPLES build, on first use
        self.outline_prog = program(self.ctx, "outline")
        self._fbos: dict[tuple, object] = {}  # (size, f4): the framebuffers drawn last, last

    def upload(self, cv: Chronovolume, dtype: str = "f2", nearest: bool = False) -> Volume:
        """Upload premultiplied RGBA (Z, Y, X, 4) as a new 3D texture (f4: float32, f2: half
        float, f1: 8 bit), converted by `chronocl.render.upload.convert` (the viewer's
        helper; the viewer keeps its textures and rewrites them in place, see
        chronocl/viewer/slots.py). Half float stays the default for renders and turntables:
        their golden images and pixel-exact tests are recorded with it."""
        nz, ny, nx, _ = cv.rgba.shape
        dtype = "f1" if cv.rgba.dtype == np.uint8 else dtype  # RGBA8 from the kernels as it is
        data, occ = convert(cv.rgba, dtype, occupancy=dtype != "f1")  # RGBA8: from the grid
        vol = Volume.allocate(self.ctx, (nx, ny, nz), dtype, data, nearest)
        grid = brick_grid.from_rgba(data)
        bounds = occ.bounds() if occ is not None else brick_grid.occupied_bounds(grid, data)
        vol.place(cv.spacing, bounds, grid)
        return vol

    def draw(
        self,
        volume: Volume,
        camera: Camera,
        size: tuple[int, int],
        *,
        background: tuple[float, float, float] = (0.0, 0.0, 0.0),
        clip: tuple[float, float, float, float] | None = None,
        jitter: bool = True,
        step: float = 1.0,
        outline: bool = False,
        shading: Shading = OFF,
        skip: bool = True,
        stop: Callable[[], bool] | None = None,
    ) -> np.ndarray:
        """Render one view; returns (H, W, 3) uint8, top-down.

        `step` is the sampling distance in voxels. `clip` = (nx, ny, nz, offset): keep the
        part of the volume on the normal's side of a plane; offset -1..1 moves the plane from
        the box's back (everything kept) to its front (nothing kept), 0 through the centre.
        `shading` lights the samples (chronocl/render/shading.py); off, the unlit shader runs.
        `skip` jumps rays across the empty bricks of the volume's brick grid (same picture).
        With `stop` (work that newer input gives up: a viewer's refine) the view is drawn in
        TUNING.draw_bands bands of rows, and SupersededError raised before each once `stop()` is
        true (the same picture: every pixel's ray is its own).
        """
        w, h = check_size(size)
        fbo = self._fbo((w, h))
        fbo.use()
        fbo.clear(*background, 1.0)
        prog, vao = self.lit() if shading.enabled else (self.prog, self.vao)
        view_proj, half = self._set_uniforms(
            prog, volume, camera, (w, h), background, clip, jitter, step, skip
        )
        if shading.enabled:
            set_shading(prog, shading, volume)
        self.ctx.disable(self.ctx.DEPTH_TEST | self.ctx.BLEND)
        if stop is None:
            vao.render(vertices=3)
        else:
            self._draw_in_bands(vao, (w, h), stop)
        if outline:
            self._draw_outline(view_proj, half, background)
        pixels = np.frombuffer(fbo.read(components=3, alignment=1), dtype=np.uint8)
        return pixels.reshape(h, w, 3)[::-1].copy()

    def _draw_in_bands(self, vao, size: tuple[int, int], stop: Callable[[], bool]) -> None:
        w, h = size
        edges = np.linspace(0, h, TUNING.draw_bands + 1).round().astype(int)
        try:
            for a, b in itertools.pairwise(edges):
                if stop():
                    raise SupersededError("newer input came before the refined frame was drawn")
                self.ctx.scissor = (0, int(a), w, int(b - a))
                vao.render(vertices=3)
                self.ctx.finish()  # drawn before input is looked at again
        finally:
            self.ctx.scissor = None

    def samples(
        self,
        volume: Volume,
        camera: Camera,
        size: tuple[int, int],
        *,
        clip: tuple[float, float, float, float] | None = None,
        jitter: bool = True,
        step: float = 1.0,
        skip: bool = True,
    ) -> np.ndarray:
        """What each ray of `draw` costs: (H, W, 2) float32, top-down, of (volume samples
        taken, brick grid reads), from the COUNT_SAMPLES build of the shader (lighting changes
        no count: it reads neighbours only of samples that are taken)."""
        w, h = check_size(size)
        if self._counting is None:
            prog = program(self.ctx, "raycast", ("COUNT_SAMPLES",))
            self._counting = (prog, self.ctx.vertex_array(prog, []))
        prog, vao = self._counting
        fbo = self._fbo((w, h), counts=True)
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        self._set_uniforms(prog, volume, camera, (w, h), (0.0, 0.0, 0.0), clip, jitter, step, skip)
        self.ctx.disable(self.ctx.DEPTH_TEST | self.ctx.BLEND)
        vao.render(vertices=3)
        counts = np.frombuffer(fbo.read(components=4, dtype="f4"), dtype=np.float32)
        return counts.reshape(h, w, 4)[::-1, :, :2].copy()

    def _set_uniforms(self, prog, volume, camera, size, background, clip, jitter, step, skip):
        """The uniforms and textures every build of raycast.frag takes; returns (view_proj,
        half the extent) for the outline."""
        if not (math.isfinite(step) and 0.05 <= step <= 8):
            raise InvalidParameterError(f"step is {step} voxels; use 0.05 to 8")
        w, h = size
        view, proj = camera.matrices(volume.extent, w / h)
        view_proj = proj @ view
        half = volume.extent / 2
        prog["inv_view_proj"].write(np.linalg.inv(view_proj).T.astype("f4").tobytes())
        prog["box_min"].value = tuple(-half)
        prog["box_max"].value = tuple(half)
        prog["hit_min"].value = tuple(volume.occupied[0])
        prog["hit_max"].value = tuple(volume.occupied[1])
        prog["step_world"].value = step * volume.unit
        prog["unit_world"].value = volume.unit
        diagonal_steps = float(np.linalg.norm(volume.extent)) / (step * volume.unit)
        prog["max_steps"].value = int(diagonal_steps) + 2
        prog["jitter"].value = bool(jitter)
        if prog.get("background", None) is not None:  # the COUNT_SAMPLES build has none
            prog["background"].value = tuple(float(c) for c in background)
        prog["clip_enabled"].value = clip is not None
        prog["clip_plane"].value = clip_plane(clip, volume.extent) if clip else (0, 0, 0, 0)
        volume.texture.use(location=0)
        prog["volume"].value = 0
        bricks = volume.bricks if skip else None
        prog["skip_empty"].value = bricks is not None
        prog["brick_voxels"].value = float(brick_grid.BRICK)
        if bricks is not None:
            bricks.use(location=BRICKS_UNIT)
            prog["brick_count"].value = tuple(bricks.size)
        prog["bricks"].value = BRICKS_UNIT
        return view_proj, half

    def lit(self) -> tuple:
        """The shading program (raycast.frag with SHADING) and its vertex array."""
        if self._lit is None:
            prog = program(self.ctx, "raycast", ("SHADING",))
            self._lit = (prog, self.ctx.vertex_array(prog, []))
        return self._lit

    def _fbo(self, size: tuple[int, int], counts: bool = False):
        """The framebuffer of `size` (RGBA8 and depth; with `counts`, float32 RGBA alone), made
        on first use; those of the `TUNING.kept_framebuffers` sizes drawn last are kept, the
        others released with their renderbuffers (moderngl releases a framebuffer's
        attachments only when asked: github.com/moderngl/moderngl/issues/226)."""
        key = (size, counts)
        fbo = self._fbos.pop(key, None)
        if fbo is None:
            ctx = self.ctx
            if counts:
                fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer(size, 4, dtype="f4")])
            else:
                fbo = ctx.framebuffer(ctx.renderbuffer(size, 4), ctx.depth_renderbuffer(size))
        self._fbos[key] = fbo
        while len(self._fbos) > TUNING.kept_framebuffers:
            old = self._fbos.pop(next(iter(self._fbos)))
            for attachment in (*old.color_attachments, old.depth_attachment):
                if attachment is not None:
                    attachment.release()
            old.release()
        return fbo

    def _draw_outline(self, view_proj: np.ndarray, half: np.ndarray, background) -> None:
        corners = np.array(
            [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype="f4"
        ) * half.astype("f4")
        edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
        lines = np.array([corners[i] for edge in edges for i in edge], dtype="f4")
        vbo = self.ctx.buffer(lines.tobytes())
        vao = self.ctx.vertex_array(self.outline_prog, [(vbo, "3f", "position")])
        self.outline_prog["view_proj"].write(view_proj.T.astype("f4").tobytes())
        grey = 0.35 if sum(background) > 1.5 else 0.65
        self.outline_prog["color"].value = (grey, grey, grey)
        vao.render(mode=self.ctx.LINES)
        vao.release()
        vbo.release()


def set_shading(prog, shading: Shading, volume: Volume) -> None:
    """The lit shader's uniforms: a voxel in texture space, and the scale that turns opacity
    differences two voxels apart into the change per `unit_world` (spacing honoured)."""
    dims = np.array(volume.texture.size, dtype=np.float64)  # voxels along x, y, z
    prog["texel"].value = tuple(1.0 / dims)
    prog["grad_scale"].value = tuple(volume.unit / (2.0 * volume.voxel))
    for name in ("ambient", "diffuse", "specular", "shininess"):
        prog[name].value = float(getattr(shading, name))


def occupied_box(alpha: np.ndarray, extent: np.ndarray, voxel: np.ndarray):
    """World corners of the voxels with opacity > 0, grown by one voxel (trilinear reach) and
    kept inside the box; an empty volume gives an empty box."""
    return occupied_corners(occupancy(alpha).bounds(), alpha.shape[::-1], extent, voxel)


def check_clip(clip: object) -> tuple[float, float, float, float]:
    """A clip plane (nx, ny, nz, offset): four finite numbers, a normal that is not zero, and
    the offset in -1..1 (beyond, the plane misses the box: all kept or nothing drawn)."""
    try:
        values = [float(v) for v in clip]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise InvalidParameterError(
            f"clip {clip!r} must be four numbers nx,ny,nz,offset, e.g. --clip 1,0,0,0"
        ) from None
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise InvalidParameterError(
            f"clip {clip!r} must be four finite numbers nx,ny,nz,offset, e.g. --clip 1,0,0,0"
        )
    n = np.array(values[:3])
    if not float(np.linalg.norm(n)) > 1e-12:
        raise InvalidParameterError(
            "clip plane normal is (0, 0, 0); give a direction, e.g. --clip 1,0,0,0"
        )
    if not -1.0 <= values[3] <= 1.0:
        raise InvalidParameterError(
            f"clip offset is {values[3]:g}; use -1 (keep everything) to 1 (keep nothing), "
            "0 cuts through the centre"
        )
    return values[0], values[1], values[2], values[3]


def clip_plane(clip: tuple[float, float, float, float], extent: np.ndarray) -> tuple:
    """World-space plane (n, d) keeping dot(n, p) + d >= 0, from (nx, ny, nz, offset)."""
    values = check_clip(clip)
    n = np.array(values[:3])
    n /= float(np.linalg.norm(n))
    reach = 0.5 * float(np.abs(n) @ extent)  # the box's half-width along n
    return (*n, -values[3] * reach)
