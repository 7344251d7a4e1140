"""One panel of a client's page: its integration session, its current chronovolume and that
chronovolume's display volume (chronocl/render/volume.py), allocated once per shape and format
and rewritten in place. The texture data's host staging is not the panel's: it comes from the
process's pool of reused host buffers for the write and goes back to it after
(`chronocl.core.memory`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from chronocl.core.errors import SupersededError
from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.integration.interactive.session import Session
from chronocl.render import brick_grid
from chronocl.render.upload import convert, display_format
from chronocl.render.volume import Volume


@dataclass
class ViewSlot:
    """One panel: its session (window + spec), current chronovolume and texture."""

    session: Session | None = None
    cv: Chronovolume | None = None
    volume: Volume | None = None
    uploaded: Chronovolume | None = None
    written: Chronovolume | None = None  # whose RGBA `volume`'s texture holds (slab_upload)
    # the window's winners where it recolours: GPU textures, or on the OpenCL device (llvmpipe)
    recolour: object | None = None  # (viewer/recolouring.py `Prepared`)
    why_not_recoloured: str | None = None  # the last frame's edit integrated: why (one line)
    # Textures of other shapes or formats, kept for reuse: frames alternate between a coarse
    # level and full resolution, and allocating a 512^3 texture costs about a second here.
    kept: dict = field(default_factory=dict)
    allocated: int = 0  # textures allocated since the last frame was sent (its header says)

    def release_gl(self) -> None:
        self.release_recolour()
        if self.volume is not None:
            self.volume.release()
            self.volume = None
            self.uploaded = self.written = None
        for vol in self.kept.values():
            vol.release()
        self.kept = {}

    def texture(self, ctx, size: tuple[int, int, int], fmt: str) -> Volume:
        """The slot's volume for a texture of `size` (x, y, z) and format `fmt`, about to be
        written (nothing in it is shown until then): the current one, else the one kept for
        them (the current one kept in its place; at most `TUNING.kept_textures` besides it),
        else a new one, counted in `allocated`."""
        vol = self.volume
        if vol is None or not vol.fits(size, fmt):
            self.release_recolour()  # its winners are the old texture's
            if vol is not None:
                self.kept[(vol.texture.size, vol.texture.dtype)] = vol
            vol = self.kept.pop((tuple(size), fmt), None)
            while len(self.kept) > TUNING.kept_textures:
                self.kept.pop(next(iter(self.kept))).release()
            if vol is None:
                vol = Volume.allocate(ctx, size, fmt)
                self.allocated += 1
        self.volume, self.uploaded, self.written = vol, None, None
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
    shape or format takes the texture kept for it (`ViewSlot.texture`: the coarse level and
    full resolution alternate), else allocates one. With `given_up` (a refine's frame) the
    texture is written in `TUNING.upload_slabs` z-slabs and SupersededError raised between them
    once it returns true; the slot then shows nothing uploaded (its next frame writes it again).

    The format follows `display_format` (docs/display.md, measured by bench/upload.py): RGBA8
    above 32^3 (a quarter of float32's bytes, and llvmpipe draws it faster at every size
    measured; 256^3: upload 0.65 s -> 0.15 s, upload + 512^2 draw 2x faster), float32 below.
    The conversion runs on a thread pool into a staging buffer from the pool of reused host
    buffers (`chronocl.core.memory.recycled_empty`), given back once written: the next frame
    of any view takes its memory again, and an idle panel holds none. It finds the occupied
    box in the same pass. The whole texture is written each time: at 256^3 the RGBA8 write
    costs 12-16 ms, and finding the unchanged slabs means comparing with the previous frame's
    data, as many bytes as the write moves (a TF edit or a window slide changes nearly every
    voxel anyway). A refine's chronovolume whose slabs were written as they integrated
    (`slot.written`) is not written again.
    """
    nz, ny, nx, _ = cv.rgba.shape
    if given_up is not None and given_up():  # before the occupancy pass, too
        raise SupersededError("newer input came before the refined frame was uploaded")
    # RGBA8 from the kernels (a display chronovolume) as it is, whatever the size
    fmt = "f1" if cv.rgba.dtype == np.uint8 else display_format(nz * ny * nx)
    # RGBA8 (no NaN to hide a brick's opacity): its box from the brick grid, not a pass
    data, occ = convert(cv.rgba, fmt, pooled=True, occupancy=cv.rgba.dtype != np.uint8)
    bricks = brick_grid.submit(data)  # the empty-space grid, beside the texture write
    # Written slab by slab while it integrated (`chronocl.viewer.slab_upload`): nothing to write
    if slot.written is cv and slot.volume is not None:
        vol = slot.volume
    else:
        vol = slot.texture(rc.ctx, (nx, ny, nz), fmt)
        vol.write(data, given_up)  # given up: half written, uploaded again next time
    grid = bricks.result()
    bounds = occ.bounds() if occ is not None else brick_grid.occupied_bounds(grid, data)
    vol.place(cv.spacing, bounds, grid)
    slot.uploaded, slot.written = cv, None
    return vol
