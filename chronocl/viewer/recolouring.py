"""A TF edit that only recolours: max, min, first_hit and change, at full resolution.

When a view's new spec differs from the one shown only where `winners.why_not` allows (the
transfer functions, for first_hit keeping which values pass its threshold) and the view
shows its window at full resolution, its texture is recoloured on the GL thread
(chronocl/render/recolour.py) instead of integrating: no step is read, nothing integrated,
nothing uploaded but two small tables. The winners (value and step per voxel) are those the
kernels wrote as they integrated the window (max, min, change: `Session.winners`), else gathered
from the level-0 session's resident steps, and uploaded on the first such edit of a window,
then kept in the slot for the next edits; any integration of the window makes them stale.

Where GL renders on the GPU, the compute pass rewrites the view's texture; the frame's
chronovolume (the new spec in its metadata, the window's t_index: the winners are the same)
gets its RGBA read back after the frame is sent (`finish`), so probes, saves and framing read
the recoloured volume without delaying the frame. Where GL is llvmpipe, the OpenCL device
recolours into RGBA8 on the host (several times faster there than llvmpipe's compute
shaders: bench/recolour.py), only the bricks the new TFs or the last ones may colour
(chronocl/render/recolour_bricks.py), and only those go up into the texture
(recolour_upload.py): the frame's `upload_ms` counts that write, `recolour_ms` the rest.
"""

from __future__ import annotations

import functools
import time
import weakref
from dataclasses import dataclass

import numpy as np

from chronocl.core import process_memory
from chronocl.core.interrupt import checkpoint
from chronocl.core.selection import Selection
from chronocl.data.chronovolume import Chronovolume
from chronocl.engine.buffers import DeviceLimitError
from chronocl.integration.interactive.levels import AutoSession
from chronocl.integration.interactive.winners import RECOLOURED
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.recolour import RecolourVolume, available, recolourer
from chronocl.render.recolour_bricks import BrickRecolour, Sparse, takes_over
from chronocl.render.recolour_host import HostRecolour, gather, shown_output, software_gl
from chronocl.render.recolour_upload import show
from chronocl.viewer.gl_thread import on_gl
from chronocl.viewer.slots import ViewSlot


@dataclass
class Prepared:
    """A slot's winners (on the GPU or the OpenCL device), for the window integrated whose
    t_index is `t_index` (weakly held: a new integration frees the old one)."""

    t_index: weakref.ref
    volume: RecolourVolume | BrickRecolour
    value_range: tuple  # the range the winners' u were gathered at
    written: weakref.ref | None = None  # the chronovolume last written into `texture`
    texture: object | None = None
    held: np.ndarray | None = None  # the bricks that may be coloured in it

    def release(self) -> None:
        self.volume.release()


class Recolouring:
    """Recolours the views of one client where a TF edit allows it."""

    def __init__(self, device: str | None = None) -> None:
        self.device = device  # the OpenCL device of recolouring on the host
        self.ms = 0.0  # recolouring time of the last frame's views
        self.upload_ms = 0.0  # of which writing textures (llvmpipe's brick-wise path)
        self._unread: list[tuple[Chronovolume, object]] = []

    def view(self, slot: ViewSlot, spec: IntegrationSpec, sel: Selection) -> Chronovolume | None:
        """The view's chronovolume for `spec` recoloured, its texture rewritten; None where the
        edit integrates (a coarse window shown, another window, or an edit that may change
        the winners), with the reason in `slot.why_not_recoloured` (None where it recoloured
        or the mode never does)."""
        slot.why_not_recoloured = None
        s, shown = slot.session, slot.cv
        if not isinstance(s, AutoSession) or s.asked == spec or spec.mode not in RECOLOURED:
            return None
        found = _recolourable(slot, spec, sel)
        if isinstance(found, str):
            slot.why_not_recoloured = found
            return None
        full, new = found
        t, uploaded = time.perf_counter(), self.upload_ms
        prepared = slot.recolour
        new_range = full.value_range_of(new)  # max/min: another range keeps the winners
        if (
            not isinstance(prepared, Prepared)
            or prepared.t_index() is not shown.t_index
            or prepared.value_range != new_range
        ):
            prepared = self._prepare(slot, full, shown, new)
            if prepared is None:  # why: `_prepare` said
                return None
        fmt = slot.volume.texture.dtype
        meta = {**shown.metadata, "spec": new.to_dict(), "value_range": list(new_range)}
        if isinstance(prepared.volume, BrickRecolour) and fmt == "f1":  # llvmpipe: by bricks
            sp = prepared.volume.sparse(new)
            cv = Chronovolume(sp.rgba, shown.t_index, meta)
            self._show(slot, prepared, sp, shown, cv)
        elif isinstance(prepared.volume, HostRecolour):  # RGBA on the host, uploaded as integrated
            cv = Chronovolume(prepared.volume.recolour(new, fmt, reuse=True), shown.t_index, meta)
            slot.cv = cv
        else:  # the texture rewritten on the GPU, its RGBA read back by `finish`
            vol = on_gl(_recolour, prepared.volume, new, shown.spacing, fmt, slot.volume)
            rgba = np.empty((*shown.shape, 4), dtype=np.uint8 if fmt == "f1" else np.float32)
            cv = Chronovolume(rgba, shown.t_index, meta)
            slot.cv, slot.volume, slot.uploaded = cv, vol, cv
            self._unread.append((cv, vol))
        full.adopt(spec, new, cv)
        s.adopt(spec, new, cv)
        self.ms += 1e3 * (time.perf_counter() - t) - (self.upload_ms - uploaded)
        return cv

    def prepare(self, slot: ViewSlot) -> bool:
        """Gather the winners of the window the slot shows, where its mode recolours and they
        are not ready, so that the first TF edit only recolours (the viewer calls it at idle,
        given up by new input: `chronocl.core.interrupt`). Whether it prepared them."""
        s, shown = slot.session, slot.cv
        if not isinstance(s, AutoSession) or s.asked is None or shown is None:
            return False
        if s.spec.mode not in RECOLOURED:
            return False
        prepared = slot.recolour
        if isinstance(prepared, Prepared) and prepared.t_index() is shown.t_index:
            return False
        found = _recolourable(slot, s.asked, s.selection)
        return not isinstance(found, str) and self._prepare(slot, found[0], shown, None) is not None

    def _show(self, slot: ViewSlot, prepared: Prepared, sp: Sparse, shown, cv) -> None:
        """Write what changed of `sp` into the slot's texture (all of it unless the texture
        holds the last one written)."""
        ours = prepared.written is not None and prepared.written() is shown
        held = prepared.held if ours and prepared.texture is slot.volume.texture else None
        t = time.perf_counter()
        on_gl(_write, slot.volume, sp, held, shown.spacing)
        self.upload_ms += 1e3 * (time.perf_counter() - t)
        prepared.written, prepared.texture = weakref.ref(cv), slot.volume.texture
        prepared.held = sp.coloured
        slot.cv, slot.uploaded = cv, cv

    def _prepare(self, slot: ViewSlot, full, shown: Chronovolume, spec) -> Prepared | None:
        """The window's winners where the recolouring runs: on the GPU where GL is one with
        compute shaders, else (llvmpipe) on the OpenCL device (render/recolour_bricks.py);
        their u at `spec`'s value range (None: the one `shown` is coloured at)."""
        own = tuple(map(float, shown.metadata["value_range"]))
        at = own if spec is None else full.value_range_of(spec)
        old = slot.recolour
        held = None
        if isinstance(old, Prepared) and isinstance(old.volume, BrickRecolour):
            held = old.volume.take_held()  # its outputs' memory, already touched
        del old  # its winners' memory goes back once released: the gather takes it again
        on_gpu = on_gl(_release_and_pick, slot)
        if on_gpu is None:
            slot.why_not_recoloured = "no recolourer here (GL without compute shaders)"
            return None
        # on the host, the first edit recolours into the RGBA8 shown (nothing else holds it:
        # the texture has its own copy), else into the last window's output; not where u is
        # gathered at another range (the bricks coloured in the shown follow from its own u)
        ours = at == own and not on_gpu
        start = shown.rgba if ours and shown_output(shown.rgba, shown.shape) else None
        if start is not None:
            held = None  # that output's memory goes back now: the gather below takes it
        limit = process_memory.current()
        if limit is not None:  # steps read ahead or kept give way to the winners and outputs
            rgba = 4 if slot.volume.texture.dtype == "f1" else 16  # the display format's bytes
            has_output = start is not None or takes_over(held, shown.shape)
            kept = full.has_winners(spec)  # the kernels wrote them: nothing to gather
            limit.fit(_prepared_bytes(shown, on_gpu, has_output, rgba, kept))
        w = full.winners(functools.partial(gather, device=self.device), spec)
        if w is None:
            slot.why_not_recoloured = "a step of the window is not in memory"
            return None
        checkpoint("preparing the recolouring", 1, 2)  # at idle: input that came meanwhile
        volume = on_gl(_upload, w) if on_gpu else on_host(w, self.device, held, start)
        prepared = Prepared(weakref.ref(shown.t_index), volume, at)
        if start is not None and isinstance(volume, BrickRecolour):
            # the texture holds the shown RGBA: an edit writes only the bricks it changes
            prepared.written, prepared.texture = weakref.ref(shown), slot.volume.texture
            prepared.held = volume.held()
        slot.recolour = prepared
        return slot.recolour

    def finish(self) -> None:
        """Read the recoloured textures back into their chronovolumes' RGBA."""
        unread, self._unread = self._unread, []
        if unread:
            on_gl(lambda rc: [vol.texture.read_into(cv.rgba) for cv, vol in unread])


def _recolourable(slot: ViewSlot, spec: IntegrationSpec, sel: Selection) -> tuple | str:
    """(the level-0 session, `spec` fixed for its window) where the slot shows window `sel`
    integrated at full resolution, in its texture, and `spec` only recolours it; else why not
    (one line, for the frame's header)."""
    s, shown = slot.session, slot.cv
    if not isinstance(s, AutoSession) or shown is None or shown.t_index is None:
        return "no integrated window with a step per voxel is shown"
    if s.selection != sel:
        return "another window"
    if s.shown_level != 0:
        return "a coarse level is shown"
    if slot.volume is None or slot.uploaded is not shown:
        return "the texture holds another frame"
    full = s.pool.sessions.get((0, spec.integration.pool))
    if full is None or full.selection != sel:
        return "the window is not integrated at full resolution"
    new, reason = full.recolours(spec)  # a reason when it has integrated nothing
    if reason is not None:
        return reason
    if full.current() is not shown:
        return "the full-resolution window holds another frame"
    return full, new


def _prepared_bytes(
    shown: Chronovolume, on_gpu: bool, outputs_held: bool, rgba: int, kept: bool = False
) -> int:
    """The host memory a window's recolouring takes beyond what it holds already: the winners
    (a float32 value and a step index per voxel; on the GPU they leave the host once
    uploaded, but are gathered there first), unless `kept` (the kernels wrote them) and, on
    the OpenCL device, its output of `rgba` bytes a voxel (the texture's format) unless it
    takes over the last one's."""
    voxels = int(np.prod(shown.shape))
    winners = 0 if kept else voxels * (4 + 2)  # u, and k at its widest (uint16)
    outputs = 0 if on_gpu or outputs_held else rgba * voxels
    return winners + outputs


def _release_and_pick(rc, slot: ViewSlot) -> bool | None:
    """Free the slot's old winners; whether to recolour on the GPU (None: nowhere)."""
    if slot.recolour is not None:
        slot.recolour.release()  # type: ignore[attr-defined]
        slot.recolour = None
    if not software_gl(rc.ctx):
        return True if available(rc.ctx) else None
    return False


def _upload(rc, w) -> RecolourVolume:
    return recolourer(rc.ctx).upload(w)


def _write(rc, vol, sp: Sparse, held, spacing) -> None:
    show(rc.ctx, vol, sp, held, spacing)


def _recolour(rc, rv: RecolourVolume, spec, spacing, fmt: str, volume):
    return recolourer(rc.ctx).recolour(rv, spec, spacing, fmt, volume=volume)


def on_host(w, device: str | None, held: list | None = None, start=None) -> HostRecolour:
    """The winners on the OpenCL device: brick by brick where the whole volume fits one
    buffer (its kernels index all of it; `held`: the outputs of the last), else in spans
    (`HostRecolour`); `start`: the RGBA8 shown, the first edit's output."""
    try:
        return BrickRecolour(w, device, held, start)
    except DeviceLimitError:
        return HostRecolour(w, device, start)
