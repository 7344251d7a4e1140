"""A TF edit that only recolours: which views may, and which recolourer does it.

Eligibility: the view shows its window integrated at full resolution in its texture, and the
new spec differs from the one shown only where `winners.why_not` allows (max, min, first_hit,
change). Where it does not, the frame says why (`slot.why_not_recoloured`, the frame header's
`why_integrated`). Dispatch: on a GPU, the compute pass rewrites the view's texture
(`chronocl.render.recolour.gl`), and the frame's chronovolume (`InTexture`) reads its RGBA back
from it only when something reads `rgba` (a probe, a save, framing, a movie's frame): an edit
that nothing read is never read back (512 MB at 512^3), because the texture is its
owner until it takes another frame (`settle`); on llvmpipe with an RGBA8 texture, the
OpenCL device recolours brick by brick (`chronocl.render.recolour.bricks`, several times faster
there than llvmpipe's compute shaders: bench/recolour.py), and only what changed goes up (the
frame's `upload_ms` counts that write, `recolour_ms` the rest: `FrameTimes`).

The winners (value and step per voxel) are those the kernels wrote as they integrated the
window (max, min, change: `LevelSession.winners`), else gathered from the level-0 session's
resident steps; they are prepared on the first edit of a window (or at idle, `prepare`), then
kept in the slot; any integration of the window makes them stale.
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass

import numpy as np

from chronocl.core import process_memory
from chronocl.core.errors import ChronoclError
from chronocl.core.interrupt import checkpoint
from chronocl.core.memory import recycled_empty
from chronocl.core.selection import Selection
from chronocl.data.chronovolume import Chronovolume
from chronocl.engine.buffers import DeviceLimitError
from chronocl.integration.interactive.level_session import Recolour
from chronocl.integration.interactive.winners import RECOLOURED
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.recolour import Changed, Recolourer, show
from chronocl.render.recolour.bricks import BrickRecolourer, shown_output, takes_over
from chronocl.render.recolour.gl import available, recolourer, software_gl
from chronocl.viewer.frames import FrameTimes
from chronocl.viewer.gl_thread import on_gl
from chronocl.viewer.slots import ViewSlot


@dataclass
class Prepared:
    """A slot's winners, prepared by `recolourer` for the window integrated whose t_index is
    `t_index` (weakly held: a new integration frees the old one)."""

    t_index: weakref.ref
    recolourer: Recolourer
    winners: object  # what `recolourer.prepare` gave
    value_range: tuple  # the range the winners' u were gathered at
    written: weakref.ref | None = None  # the chronovolume last written into `texture`
    texture: object | None = None
    held: np.ndarray | None = None  # the bricks that may be coloured in it (host RGBA8)

    def release(self) -> None:
        self.winners.release()


class Recolouring:
    """Recolours the views of one client where a TF edit allows it."""

    def __init__(self, times: FrameTimes, device: str | None = None) -> None:
        self.device = device  # the OpenCL device of recolouring on the host
        self.times = times  # the frame's, summed here (recolour, upload, read-back)
        # each view's chronovolume whose RGBA is still only in its texture (weakly held: one
        # nothing holds any more is never read)
        self._unread: list[tuple[ViewSlot, weakref.ref]] = []

    def view(self, slot: ViewSlot, spec: IntegrationSpec, sel: Selection) -> Chronovolume | None:
        """The view's chronovolume for `spec` recoloured, its texture rewritten; None where the
        edit integrates, with the reason in `slot.why_not_recoloured` (None where it recoloured
        or nothing was edited: the spec shown is `spec`)."""
        slot.why_not_recoloured = None
        s, shown = slot.session, slot.cv
        if s is not None and s.asked == spec:
            return None  # no edit: a slide or a jump
        found = _recolourable(slot, spec, sel)
        if isinstance(found, str):
            slot.why_not_recoloured = found
            return None
        full, new, new_range = found  # max/min: another range keeps the winners
        times = self.times
        t, uploaded, read = time.perf_counter(), times.recolour_upload_ms, times.readback_ms
        prepared = slot.recolour
        if (
            not isinstance(prepared, Prepared)
            or prepared.t_index() is not shown.t_index
            or prepared.value_range != new_range
        ):
            prepared = self._prepare(slot, full, shown, new_range)
            if prepared is None:  # why: `_prepare` said
                return None
        meta = {**shown.metadata, "spec": new.to_dict(), "value_range": list(new_range)}
        spacing, held = shown.spacing, _held_by(prepared, shown, slot)
        if prepared.recolourer.gl_thread:  # the compute pass writes the texture, below
            fmt = slot.volume.texture.dtype
            unread = InTexture(shown.shape, fmt, shown.t_index, meta, times)
            cv, changed = unread, None
        else:  # RGBA8 on the host; what changed is written into the texture below
            changed = prepared.recolourer.apply(prepared.winners, new, slot.volume)
            cv = Chronovolume(changed.rgba, shown.t_index, meta)
        # all that showed the old frame shows the new one before the texture is rewritten, so
        # that an old frame never read is read back only where something else still holds it
        slot.cv, slot.uploaded = cv, cv
        s.adopt(spec, new, cv)
        del shown, found, full
        self.settle(slot)
        if changed is None:  # (written, the texture owns it: an error before, nothing does)
            slot.volume = on_gl(_apply_and_show, prepared, new, slot.volume, spacing, unread)
            self._unread.append((slot, weakref.ref(unread)))
        else:
            self._show(slot, prepared, changed, held, spacing, cv)
        spent = 1e3 * (time.perf_counter() - t)  # less the texture writes and reads timed apart
        times.recolour_ms += (
            spent - (times.recolour_upload_ms - uploaded) - (times.readback_ms - read)
        )
        return cv

    def settle(self, slot: ViewSlot) -> None:
        """The slot's texture takes another frame next: the frame it holds whose RGBA was never
        read is read back now where anything but the slot still holds it (a session keeping
        it to show again, a caller), and otherwise let go unread (call it on the worker's
        thread, or on the GL thread while the worker waits for it)."""
        mine = [ref for s, ref in self._unread if s is slot]
        if not mine:
            return
        self._unread = [(s, ref) for s, ref in self._unread if s is not slot]
        for ref in mine:
            if slot.uploaded is not None and slot.uploaded is ref():
                slot.uploaded = None  # it is rewritten next: the slot shows nothing meanwhile
            cv = ref()
            if cv is not None:
                cv.read()

    def prepare(self, slot: ViewSlot) -> bool:
        """Gather the winners of the window the slot shows, where its mode recolours and they
        are not ready, so that the first TF edit only recolours (the viewer calls it at idle,
        given up by new input: `chronocl.core.interrupt`). Whether it prepared them."""
        s, shown = slot.session, slot.cv
        if s is None or s.asked is None or shown is None:
            return False
        if s.spec.mode not in RECOLOURED:
            return False
        prepared = slot.recolour
        if isinstance(prepared, Prepared) and prepared.t_index() is shown.t_index:
            return False
        found = _recolourable(slot, s.asked, s.selection)
        return not isinstance(found, str) and self._prepare(slot, found.level, shown) is not None

    def _show(self, slot: ViewSlot, prepared: Prepared, changed: Changed, held, spacing, cv):
        """Write what changed into the slot's texture (all of it where `held`, the bricks the
        texture may colour, is None: `_held_by`)."""
        t = time.perf_counter()
        on_gl(_write, changed, held, spacing)
        self.times.recolour_upload_ms += 1e3 * (time.perf_counter() - t)
        prepared.written, prepared.texture = weakref.ref(cv), slot.volume.texture
        prepared.held = changed.coloured

    def _prepare(self, slot: ViewSlot, full, shown: Chronovolume, at=None) -> Prepared | None:
        """The window's winners where the recolouring runs (`_release_and_pick`); their u at
        the value range `at` (None: the one `shown` is coloured at)."""
        own = tuple(map(float, shown.metadata["value_range"]))
        at = own if at is None else tuple(map(float, at))
        old = slot.recolour
        held = None
        if isinstance(old, Prepared) and not old.recolourer.gl_thread:
            held = old.winners.take_held()  # its outputs' memory, already touched
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
        kept = full.kept_winners(at)  # the kernels wrote them: nothing to gather
        limit = process_memory.current()
        if limit is not None:  # steps read ahead or kept give way to the winners and outputs
            has_output = start is not None or takes_over(held, shown.shape)
            limit.fit(_prepared_bytes(shown, on_gpu, has_output, kept is not None))
        w = kept if kept is not None else full.winners(at)
        if w is None:
            slot.why_not_recoloured = "a step of the window is not in memory"
            return None
        checkpoint("preparing the recolouring", 1, 2)  # at idle: input that came meanwhile
        ref = weakref.ref(shown.t_index)
        if on_gpu:
            prepared = Prepared(ref, *on_gl(_prepare_on_gpu, w), at)
        else:
            bricks = on_host(w, self.device, held, start)
            if bricks is None:  # its spans are rows of bricks; llvmpipe's pass: slower
                slot.why_not_recoloured = (
                    "a row of bricks of the winners is over the OpenCL device's largest buffer"
                )
                return None
            prepared = Prepared(ref, BrickRecolourer(self.device), bricks, at)
            if start is not None:  # the texture holds the shown RGBA: an edit writes what changes
                prepared.written, prepared.texture = weakref.ref(shown), slot.volume.texture
                prepared.held = bricks.output[1]
        slot.recolour = prepared
        return prepared


class TextureLostError(ChronoclError, RuntimeError):
    """A recoloured chronovolume's RGBA was asked for after its texture took another frame."""


class InTexture(Chronovolume):
    """A view's chronovolume recoloured by the GPU's compute pass, whose RGBA is in the view's
    texture only: `rgba` reads it back (on the GL thread) the first time anything reads it.
    Its shape and `rgba_dtype` are known without it. The texture stays its owner until it
    takes another frame (`Recolouring.settle`, which reads it back first where something
    still holds it)."""

    def __init__(self, shape, fmt: str, t_index, metadata: dict, times: FrameTimes) -> None:
        self._volume = None  # the texture holding the RGBA (None: read, or not written yet)
        self._shape = tuple(shape)
        self._dtype = np.dtype(np.uint8 if fmt == "f1" else np.float32)
        self._times = times  # where its read-back counts
        self._rgba: np.ndarray | None = None
        super().__init__(None, t_index, metadata)  # type: ignore[arg-type]

    @property  # type: ignore[override]
    def rgba(self) -> np.ndarray:
        if self._rgba is None:
            self.read()
        return self._rgba  # type: ignore[return-value]

    @rgba.setter
    def rgba(self, value: np.ndarray | None) -> None:
        self._rgba = value
        if value is not None:
            self._volume = None

    @property
    def rgba_dtype(self) -> np.dtype:
        return self._dtype

    @property
    def shape(self) -> tuple[int, int, int]:
        return self._shape  # type: ignore[return-value]

    @property
    def dims(self) -> tuple[int, int, int]:
        return self._shape[::-1]  # type: ignore[return-value]

    def __getstate__(self) -> dict:
        """A copy or a pickle holds the RGBA itself (read back now): the texture is no owner
        of theirs (`settle` knows only this one)."""
        self.read()
        return {**self.__dict__, "_volume": None, "_times": None}

    def read(self) -> None:
        """Read the RGBA back from the texture, unless it was read already."""
        if self._rgba is not None:
            return
        on_gl(self._read)  # (at once where this is the GL thread: a read inside a GL task)

    def _read(self, rc) -> None:
        """On the GL thread, where every write of the texture runs too."""
        if self._rgba is not None:
            return
        if self._volume is None:
            raise TextureLostError(
                "a recoloured view's RGBA was asked for while its texture held another frame; "
                "read the view's chronovolume while it is shown"
            )
        t = time.perf_counter()
        rgba = recycled_empty((*self._shape, 4), self._dtype)  # the one pool of host buffers
        self._volume.texture.read_into(rgba)
        self.rgba = rgba
        self._times.readback_ms += 1e3 * (time.perf_counter() - t)


def _held_by(prepared: Prepared, shown: Chronovolume, slot: ViewSlot) -> np.ndarray | None:
    """The bricks that may be coloured in the slot's texture, where it holds the last output
    `prepared` wrote on the host (None: unknown, the whole texture is written)."""
    ours = prepared.written is not None and prepared.written() is shown
    return prepared.held if ours and prepared.texture is slot.volume.texture else None


def _recolourable(slot: ViewSlot, spec: IntegrationSpec, sel: Selection) -> Recolour | str:
    """The recolouring (`Session.recolours`, the level-0 `LevelSession.recolours`: that
    session, `spec` fixed for its window and its value range) where the slot shows window
    `sel` integrated at full resolution, in its texture, and `spec` only recolours it; else
    why not (one line, for the frame's header)."""
    s, shown = slot.session, slot.cv
    if spec.mode not in RECOLOURED:
        return f"{spec.mode} mixes every step's colour"
    if s is None or shown is None or shown.t_index is None:
        return "no integrated window with a step per voxel is shown"
    if slot.volume is None or slot.uploaded is not shown:
        return "the texture holds another frame"
    return s.recolours(spec, sel, shown)


def _prepared_bytes(shown: Chronovolume, on_gpu: bool, outputs_held: bool, kept: bool) -> int:
    """The host memory a window's recolouring takes beyond what it holds already: the winners
    (a float32 value and a step index per voxel; on the GPU they leave the host once
    uploaded, but are gathered there first), unless `kept` (the kernels wrote them) and, on
    the OpenCL device, its RGBA8 output unless it takes over the last one's."""
    voxels = int(np.prod(shown.shape))
    winners = 0 if kept else voxels * (4 + 2)  # u, and k at its widest (uint16)
    outputs = 0 if on_gpu or outputs_held else 4 * voxels
    return winners + outputs


def on_host(w, device: str | None, held: tuple | None = None, start=None):
    """The winners prepared on the OpenCL device brick by brick, in z-spans of rows of bricks
    under its largest buffer (`held`: the outputs of the last; `start`: the RGBA8 shown, the
    first edit's output); None where one row of bricks (8 z planes) is over that buffer."""
    try:
        return BrickRecolourer(device).prepare(w, held, start)
    except DeviceLimitError:
        return None


def _release_and_pick(rc, slot: ViewSlot) -> bool | None:
    """Free the slot's old winners; whether to recolour on the GPU (None: nowhere): the OpenCL
    device's bricks where GL is a software one and the texture RGBA8, else the compute pass."""
    slot.release_recolour()
    if software_gl(rc.ctx) and slot.volume.texture.dtype == "f1":
        return False
    return True if available(rc.ctx) else None


def _prepare_on_gpu(rc, w) -> tuple:
    gl = recolourer(rc.ctx)
    return gl, gl.prepare(w)


def _apply_and_show(rc, prepared: Prepared, spec, into, spacing, cv: InTexture):
    """The compute pass writes `cv` into the texture (`into`, where it fits), which holds it
    from now on."""
    changed = prepared.recolourer.apply(prepared.winners, spec, into)
    show(changed, spacing)
    cv._volume = changed.volume
    return changed.volume


def _write(rc, changed: Changed, held, spacing) -> None:
    show(changed, spacing, held)
