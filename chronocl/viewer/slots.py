"""One panel of a client's page: its integration session, its current chronovolume and that
chronovolume's 3D texture, and how a chronovolume is laid out in the raycaster's world."""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

from chronocl.core.errors import SupersededError
from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.integration.interactive.session import Session
from chronocl.render import brick_grid
from chronocl.render.camera import world_extent
from chronocl.render.raycaster import Volume
from chronocl.render.upload import convert, display_format


@dataclass
class ViewSlot:
    """One panel: its session (window + spec), current chronovolume and texture."""

    session: Session | None = None
    cv: Chronovolume | None = None
    volume: Volume | None = None
    uploaded: Chronovolume | None = None
    written: Chronovolume | None = None  # whose RGBA `volume`'s texture holds (slab_upload)
    staging: np.ndarray | None = None  # the texture data's host buffer, reused frame to frame
    # the window's winners where it recolours: GPU textures, or on the OpenCL device (llvmpipe)
    recolour: object | None = None  # (viewer/recolouring.py `Prepared`)
    why_not_recoloured: str | None = None  # the last frame's edit integrated: why (one line)
    # Textures of other shapes or formats, kept for reuse: frames alternate between a coarse
    # level and full resolution, and allocating a 512^3 texture costs about a second here.
    kept: dict = field(default_factory=dict)

    def release_gl(self) -> None:
        self.release_recolour()
        if self.volume is not None:
            self.volume.release()
            self.volume = None
            self.uploaded = self.written = None
        for vol in self.kept.values():
            vol.release()
        self.kept = {}
        self.staging = None

    def swap_volume(self, key: tuple) -> Volume | None:
        """Keep the current texture under its (size, format) and take the one kept for `key`
        (None: none kept); at most `TUNING.kept_textures` stay besides the current one."""
        self.release_recolour()  # its winners are the old texture's
        if self.volume is not None:
            self.kept[(self.volume.texture.size, self.volume.texture.dtype)] = self.volume
        self.volume = self.uploaded = self.written = None
        vol = self.kept.pop(key, None)
        while len(self.kept) > TUNING.kept_textures:
            self.kept.pop(next(iter(self.kept))).release()
        return vol

    def release_recolour(self) -> None:
        """Free the winners and their outputs (on the GL thread where they are textures)."""
        if self.recolour is not None:
            self.recolour.release()  # type: ignore[attr-defined]
            self.recolour = None

    def forget_frame(self) -> None:
        """Let go of the chronovolume shown (another window comes: its integration takes the
        memory); the texture stays, and is written again with the next one."""
        self.cv = self.uploaded = self.written = None

    def drop_session(self) -> None:
        if self.session is not None:
            self.session.close()
        self.session, self.cv = None, None


def upload(rc, slot: ViewSlot, cv: Chronovolume, given_up=None) -> Volume:
    """The chronovolume as a 3D texture, rewriting the slot's texture in place when its shape
    and format are unchanged (allocating a new 3D texture costs more than the write); a new
    shape or format takes the texture kept for it (`ViewSlot.swap_volume`: the coarse level and
    full resolution alternate), else allocates one. With `given_up` (a refine's frame) the
    texture is written in `TUNING.upload_slabs` z-slabs and SupersededError raised between them
    once it returns true; the slot then shows nothing uploaded (its next frame writes it again).

    The format follows `display_format` (docs/display.md, measured by bench/upload.py): RGBA8
    above 32^3 (a quarter of float32's bytes, and llvmpipe draws it faster at every size
    measured; 256^3: upload 0.65 s -> 0.15 s, upload + 512^2 draw 2x faster), float32 below.
    The conversion runs on a thread pool into the slot's staging buffer, reused frame to
    frame, and finds the occupied box in the same pass. The whole texture is written each
    time: at 256^3 the RGBA8 write costs 12-16 ms, and finding the unchanged slabs means
    comparing with the previous frame's data, as many bytes as the write moves (a TF edit
    or a window slide changes nearly every voxel anyway). A refine's chronovolume whose slabs
    were written as they integrated (`slot.written`) is not written again.
    """
    nz, ny, nx, _ = cv.rgba.shape
    if given_up is not None and given_up():  # before the occupancy pass, too
        raise SupersededError("newer input came before the refined frame was uploaded")
    # RGBA8 from the kernels (a display chronovolume) as it is, whatever the size
    fmt = "f1" if cv.rgba.dtype == np.uint8 else display_format(nz * ny * nx)
    data, occ = convert(cv.rgba, fmt, slot.staging)
    bricks = brick_grid.submit(data)  # the empty-space grid, beside the texture write
    vol = slot.volume
    # Written slab by slab while it integrated (`chronocl.viewer.slab_upload`): nothing to write
    prewritten = slot.written is cv and vol is not None
    slot.written = None
    if not prewritten:
        if vol is None or vol.texture.size != (nx, ny, nz) or vol.texture.dtype != fmt:
            vol = slot.swap_volume(((nx, ny, nz), fmt))
        if vol is not None:
            _write(slot, vol, data, given_up)
        else:
            vol = new_volume(rc, (nx, ny, nz), fmt, data)
    if data is not cv.rgba:  # RGBA8 from the kernels is sent as it is: the staging stays
        slot.staging = data
    extent, voxel = geometry(cv)
    vol.extent, vol.unit = extent, float(np.min(voxel))
    vol.occupied = occ.corners(extent, voxel)
    vol.bricks = brick_grid.texture(rc.ctx, bricks.result(), vol.bricks)
    slot.volume, slot.uploaded = vol, cv
    return vol


def new_volume(rc, size: tuple[int, int, int], fmt: str, data: np.ndarray | None = None) -> Volume:
    """A 3D texture of `size` (x, y, z) and format `fmt` as a volume (placed by `upload`)."""
    import moderngl

    tex = rc.ctx.texture3d(size, 4, data, dtype=fmt)
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return Volume(tex, np.zeros(3), 0.0, (np.zeros(3), np.zeros(3)))


def _write(slot: ViewSlot, vol: Volume, data: np.ndarray, given_up) -> None:
    """Write `data` into the volume's texture, in slabs where it may be given up."""
    nz, ny, nx = data.shape[:3]
    if given_up is None or nz < TUNING.upload_slabs:
        vol.texture.write(data)
        return
    cuts = np.linspace(0, nz, TUNING.upload_slabs + 1).astype(int)
    for z0, z1 in pairwise(cuts.tolist()):
        if given_up():
            slot.volume, slot.uploaded = vol, None  # half written: uploaded again next time
            raise SupersededError("newer input came while the refined frame was uploaded")
        vol.texture.write(np.ascontiguousarray(data[z0:z1]), viewport=(0, 0, z0, nx, ny, z1 - z0))


def geometry(cv: Chronovolume) -> tuple[np.ndarray, np.ndarray]:
    """World extent (x, y, z; longest side 1) and voxel size, as the raycaster lays them out."""
    nz, ny, nx = cv.shape
    extent = world_extent(cv.shape, cv.spacing)
    return extent, extent / np.array([nx, ny, nz])
