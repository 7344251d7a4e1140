"""A refine's texture written slab by slab while the next slab integrates.

A sharp 512^3 frame spent 0.5 s integrating and then 0.28 s uploading here, and on an H100
host 0.95 s integrating and 0.94 s uploading. With `chronocl.core.slab_sink` the integration
hands on each z-slab of its display (RGBA8) chronovolume as soon as it is final, and
`SlabUpload` queues its texture write on the GL thread, which writes it while the engine
integrates the next slab; the frame's `upload` then finds the texture written
(`ViewSlot.written`) and only places it. Writes stay in the GL thread's queue order, so a
refine given up half way is rewritten whole by the next frame's upload (the slot's `uploaded`
is cleared at the first slab).

It pays only where the integration leaves the host's cores free (a GPU engine): on a CPU
device the kernels take every core, and llvmpipe's texture writes the same ones (512^3 here:
1 099 ms with slabs against 1 064 without, medians of five edits taken in turn). So the viewer
writes slabs for engines that do not run on the host (`pays`), or as CHRONOCL_SLAB_UPLOAD
(1 / 0) says.
"""

from __future__ import annotations

import time
from concurrent.futures import Future

import numpy as np

from chronocl.core import env
from chronocl.data.chronovolume import Chronovolume
from chronocl.engine import get_engine
from chronocl.engine.base import Engine
from chronocl.render.volume import Volume
from chronocl.viewer.gl_thread import gl_submit
from chronocl.viewer.slots import ViewSlot

FORMAT = "f1"  # the display chronovolume's RGBA8, written as it is


def pays(engine: str | Engine, device: str | None) -> bool:
    """Whether a refine's slabs are written as they integrate: for an engine that writes the
    display format and does not run on the host's cores, unless CHRONOCL_SLAB_UPLOAD says."""
    forced = env.get("CHRONOCL_SLAB_UPLOAD")
    if forced in ("0", "1"):
        return forced == "1"
    eng = get_engine(engine, device) if isinstance(engine, str) else engine
    return eng.writes_display and eng.copies_to_device


class SlabUpload:
    """The slabs of one slot's refined chronovolume, written to its texture as they come."""

    def __init__(self, slot: ViewSlot) -> None:
        self.slot = slot
        self.target: np.ndarray | None = None  # the RGBA whose slabs were written
        self.volume: Volume | None = None
        self.rows = 0
        self.jobs: list[Future] = []
        self.ms = 0.0  # the GL thread's time writing, overlapped with the integration

    def put(self, rgba: np.ndarray, z0: int, z1: int) -> None:
        """Queue the write of rows z0..z1 of `rgba` (a `chronocl.core.slab_sink` sink)."""
        if self.target is not None and rgba is not self.target:
            return  # another volume integrated under the same refine: uploaded as usual
        self.target = rgba
        self.rows += z1 - z0
        self.jobs.append(gl_submit(self._write, rgba, z0, z1))

    def _write(self, rc, rgba: np.ndarray, z0: int, z1: int) -> None:
        """On the GL thread: the slot's texture of this shape takes rows z0..z1."""
        t = time.perf_counter()
        if self.volume is None:
            nz, ny, nx, _ = rgba.shape
            # Until the last slab it holds no chronovolume's picture: a frame drawn from it
            # first uploads again.
            self.volume = self.slot.texture(rc.ctx, (nx, ny, nz), FORMAT)
        self.volume.write_slab(rgba, z0, z1)
        self.ms += 1e3 * (time.perf_counter() - t)

    def done(self, cv: Chronovolume | None) -> None:
        """Wait for the writes; the texture holds `cv` when every row of its RGBA was written
        and no frame took the slot's texture meanwhile."""
        for job in self.jobs:
            job.result()
        whole = self.target is not None and self.rows == self.target.shape[0]
        slot = self.slot
        if cv is not None and whole and cv.rgba is self.target and slot.volume is self.volume:
            slot.written = cv
