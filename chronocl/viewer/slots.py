"""One panel of a client's page: its integration session, its current chronovolume and that
chronovolume's 3D texture, and how a chronovolume is laid out in the raycaster's world."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chronocl.data.chronovolume import Chronovolume
from chronocl.integration.session import Session
from chronocl.render.raycaster import Volume, occupied_box

FLOAT_TEXTURE_VOXELS = 2**23  # 128 MB of float32 RGBA


@dataclass
class ViewSlot:
    """One panel: its session (window + spec), current chronovolume and texture."""

    session: Session | None = None
    cv: Chronovolume | None = None
    volume: Volume | None = None
    uploaded: Chronovolume | None = None

    def release_gl(self) -> None:
        if self.volume is not None:
            self.volume.release()
            self.volume = None
            self.uploaded = None

    def drop_session(self) -> None:
        if self.session is not None:
            self.session.close()
        self.session, self.cv = None, None


def upload(rc, slot: ViewSlot, cv: Chronovolume) -> Volume:
    """The chronovolume as a 3D texture, rewriting the slot's texture in place when its shape
    and type are unchanged (allocating a new 3D texture costs more than the write).

    Volumes up to `FLOAT_TEXTURE_VOXELS` go up as float32: no conversion on the host, and
    llvmpipe samples them about twice as fast as half floats; larger ones as half floats.
    """
    import moderngl

    nz, ny, nx, _ = cv.rgba.shape
    if nz * ny * nx <= FLOAT_TEXTURE_VOXELS:
        dtype, data = "f4", np.ascontiguousarray(cv.rgba, dtype=np.float32)
    else:
        dtype, data = "f2", cv.rgba.astype(np.float16)
    vol = slot.volume
    if vol is not None and vol.texture.size == (nx, ny, nz) and vol.texture.dtype == dtype:
        vol.texture.write(data)
    else:
        slot.release_gl()
        tex = rc.ctx.texture3d((nx, ny, nz), 4, data, dtype=dtype)
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        vol = Volume(tex, np.zeros(3), 0.0, (np.zeros(3), np.zeros(3)))
    extent, voxel = geometry(cv)
    vol.extent, vol.unit = extent, float(np.min(voxel))
    vol.occupied = occupied_box(cv.rgba[..., 3], extent, voxel)
    slot.volume, slot.uploaded = vol, cv
    return vol


def geometry(cv: Chronovolume) -> tuple[np.ndarray, np.ndarray]:
    """World extent (x, y, z; longest side 1) and voxel size, as the raycaster lays them out."""
    nz, ny, nx = cv.shape
    dz, dy, dx = cv.spacing
    physical = np.array([nx * dx, ny * dy, nz * dz], dtype=np.float64)
    extent = physical / physical.max()
    return extent, extent / np.array([nx, ny, nz])
