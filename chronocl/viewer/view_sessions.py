"""The views of one client: a slot per panel (its integration session, chronovolume and texture)
over one data set. The panels' sessions share the data set's resident steps (one window manager
per level and pooling; in a server, shared by every client: `SharedSteps`) and integrate only
what changed: a slide of the window goes through `Session.show`, which integrates the new
window from resident steps (incrementally where the rates measured on this machine predict a
slide cheaper than integrating the window again: `Views.slide_costs`, `costs.Costs`);
a camera change integrates nothing (silhouettes aside).

OpenCL integration is serialised per process (`INTEGRATE_LOCK`: the engine is shared).
"""

from __future__ import annotations

import dataclasses
import math
import threading
from contextlib import nullcontext

from chronocl.core import process_memory
from chronocl.core.budget import human
from chronocl.core.errors import InvalidParameterError, SupersededError
from chronocl.core.process_memory import Streaming
from chronocl.core.slab_sink import slabs_to
from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.window import WindowManager
from chronocl.integration.interactive.costs import Costs
from chronocl.integration.interactive.session import Session
from chronocl.integration.interactive.settings import manager_key
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.frames import FrameTimes
from chronocl.viewer.gl_thread import gl_submit, release_on_gl
from chronocl.viewer.recolouring import Recolouring
from chronocl.viewer.slab_upload import SlabUpload, pays
from chronocl.viewer.slots import ViewSlot
from chronocl.viewer.view_state import ViewState

INTEGRATE_LOCK = threading.Lock()


class SharedSteps:
    """The window managers of a server's data sets, one per data set, level and pooling, shared
    by every client: a second tab, or a page reconnecting while its old socket still holds its
    window, reads no step twice and holds none twice. Steps nobody shows stay until the process's
    memory limit needs their room (`chronocl.core.process_memory`); `close` frees them all."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._by_dataset: dict[int, dict[tuple[int, str], WindowManager]] = {}
        self._closed = False

    def of(self, dataset: int) -> dict[tuple[int, str], WindowManager]:
        """The managers of data set `dataset` (sessions add to it under INTEGRATE_LOCK)."""
        with self._lock:
            if self._closed:
                raise InvalidParameterError("the viewer is stopping; its steps were let go")
            return self._by_dataset.setdefault(dataset, {})

    def close(self) -> None:
        """Close every manager; under INTEGRATE_LOCK, so that no session adds one meanwhile."""
        with INTEGRATE_LOCK, self._lock:
            self._closed = True
            managers = [m for group in self._by_dataset.values() for m in group.values()]
            self._by_dataset = {}
            for m in managers:
                m.close()


class Views:
    """The panels' slots of one client, for the data set of the newest state. Without `shared`
    (a server's: `SharedSteps`) the views' window managers are their own, closed with them."""

    def __init__(
        self,
        datasets: list[Dataset],
        engine: str,
        device: str | None,
        memory: str | int | None,
        shared: SharedSteps | None = None,
    ) -> None:
        self.datasets = datasets
        self.engine, self.device, self.memory = engine, device, memory
        self.slots: list[ViewSlot] = []
        self._dataset = -1
        self._own = shared is None
        self._shared = shared or SharedSteps()
        self._managers: dict[tuple[int, str], WindowManager] = {}
        self.times = FrameTimes()  # the frame's, zeroed by the worker as it starts one
        self.recolouring = Recolouring(self.times, device)  # TF edits that only recolour
        # slide or integrate a window again: the rates the views' sessions measure, shared
        self.slide_costs = Costs()
        self.host_steps_why: str | None = None  # the last frame's steps_on_host
        # the last frame's views integrated their windows again where they could not slide
        # them, and why (its timings.why_not_incremental); a refine's views slid
        self.why_not_incremental: str | None = None
        self.refine_incremental = False
        self._slabs: bool | None = None  # whether they pay (`slab_upload.pays`), once known
        self._over = False  # whether the last frame left the process over its memory limit
        self._streaming: Streaming | None = None  # the views' windows stream: why
        # Each view's full-resolution window manager as of the last frame (None: no session),
        # replaced whole by the render thread after each frame: the event loop's residency
        # poll reads it, never the slots and sessions the render thread is replacing.
        self.shown_managers: tuple[WindowManager | None, ...] = ()

    def chronovolumes(self, state: ViewState) -> tuple[list[Chronovolume], float, bool]:
        """The views' chronovolumes for `state`, integrating only where something changed;
        with the milliseconds integration took and whether it was incremental."""
        series = self.datasets[state.dataset].series
        if self._dataset != state.dataset:
            for s in self.slots:
                _drop(s)
            self._close_managers()
            self._dataset = state.dataset
            self._managers = self._shared.of(state.dataset)
            # the store's, not the machine's: measured anew
            self.slide_costs.reads.clear()
            self.slide_costs.streamed.clear()
        while len(self.slots) < len(state.views):
            self.slots.append(ViewSlot())
        integrate_ms, incremental = 0.0, False
        for slot in self.slots[len(state.views) :]:  # views taken away hold nothing meanwhile
            _drop(slot)
        with INTEGRATE_LOCK:  # views moving let go first, not after another view integrated
            for i, slot in enumerate(self.slots[: len(state.views)]):
                if slot.session is not None:
                    sel = state.selection(series.n_steps, i)
                    if slot.session.selection != sel:
                        slot.forget_frame()
                        _release_winners(slot)
                    slot.session.leaving(sel)
        limit = process_memory.current()
        if limit is not None:  # steps read ahead or kept give way to the frame
            voxels = math.prod(series.volume_shape) * len(state.views)
            limit.expect(self, TUNING.frame_voxel_bytes * voxels)
            self._streaming = self._stream_or_not(limit, series, state)
            for slot in self.slots[: len(state.views)]:
                if slot.session is not None:
                    slot.session.stream(self._streaming)
            limit.fit()
        cvs, integrated = [], []
        for i in range(len(state.views)):
            slot = self.slots[i]
            spec = state.spec(i)
            if (
                state.quality == "preview"
                and spec.enhance.kind == "silhouette"
                and slot.session is not None
                and slot.session.selection is not None  # it showed one (its frame may be let go)
            ):
                # Silhouettes follow the camera; while dragging keep the last ones.
                old = slot.session.spec
                spec = dataclasses.replace(spec, enhance=old.enhance)
            with INTEGRATE_LOCK:
                sel = state.selection(series.n_steps, i)  # its own window, or the shared one
                try:
                    cv, ms, inc = self._integrate(slot, series, spec, sel)
                except SupersededError:  # given up for a newer request: kept
                    raise
                except Exception:  # its session may say it holds what it failed to make
                    _drop(slot)
                    raise
            integrate_ms += ms
            incremental = incremental or inc
            cvs.append(cv)
            if ms > 0:  # integrated for this frame (not its last chronovolume shown again)
                integrated.append(slot)
                self.times.read_ms += float(slot.session.stats.get("read_ms", 0.0))
        # A GPU session whose window does not fit the device: its steps go up every time.
        whys = (s.session.stats.get("why_not_on_device") for s in self.slots[: len(cvs)])
        self.host_steps_why = next((why for why in whys if why), None)
        self.why_not_incremental = self._why_integrated(integrated)  # (a session's stats stay)
        self.shown_managers = tuple(  # published whole: the timeline reads it (`residency`)
            None if s.session is None else self.manager(0, s.session.spec.integration.pool)
            for s in self.slots[: len(cvs)]
        )
        return cvs, integrate_ms, incremental

    def _stream_or_not(self, limit, series, state: ViewState) -> Streaming | None:
        """Whether this client's views keep their windows resident (None) or stream them
        (why, the bytes a slab may take, and the steps that stay resident): decided once per
        frame for every view, so that no view streams a step another keeps resident. They
        stream where the steps of every window shown (this client's views' and the other
        clients' resident ones, each step once) do not fit what the limit leaves beside every
        view's frames (`ProcessLimit.window_room`); the steps that fit beside the slabs stay."""
        n = series.n_steps
        windows = [state.selection(n, i).steps for i in range(len(state.views))]
        steps = set().union(*windows)
        step = math.prod(series.volume_shape) * series.dtype.itemsize
        # two slabs of the widest window at once: one integrated while the next is read
        slabs = 2 * max(map(len, windows), default=0) * -(-step // TUNING.stream_slabs)
        fits, need, room, keep = limit.resident(self, state.dataset, steps, step, slabs)
        if fits:
            return None
        why = (
            f"the windows shown need {human(need)} > the {human(max(room, 0))} that the memory "
            f"limit {human(limit.total)} leaves beside the views' frames"
        )
        return Streaming(why, max(room - (need - len(steps - keep) * step), slabs), keep)

    def _integrate(self, slot: ViewSlot, series, spec, sel) -> tuple[Chronovolume, float, bool]:
        s = slot.session
        slot.why_not_recoloured = None
        if s is not None and slot.cv is not None and s.asked == spec and s.selection == sel:
            return slot.cv, 0.0, False
        if s is None or (s.asked != spec and s.selection != sel):
            _drop(slot)
            s = slot.session = Session(
                series,
                memory=self.memory,
                engine=self.engine,
                device=self.device,
                spec=spec,
                level="auto",
                managers=self._managers,
                display=True,  # full-resolution frames as RGBA8 from the kernels
                slide_costs=self.slide_costs,
            )
            s.stream(self._streaming)
            cv = s.set_window(sel)
        else:  # recoloured where a TF edit allows, else slid where the windows overlap
            cv = self.recolouring.view(slot, spec, sel)
            if cv is None:
                if s.asked != spec:  # integrated anew: they go first
                    _release_winners(slot)
                cv = s.show(sel, spec)
        slot.cv = cv
        stats = s.stats or {}
        return cv, float(stats.get("integrate_ms", 0.0)), bool(stats.get("incremental", False))

    def frame_done(self) -> str | None:
        """After a frame: its memory noted for the process's limit; a line for the log when the
        windows shown and their frames alone went over it (once, until they fit again)."""
        limit = process_memory.current()
        if limit is None:
            return None
        limit.frame_done()
        limit.fit()
        was, over = self._over, limit.excess()
        self._over = over > 0
        if not self._over or was:
            return None
        return (
            f"the windows shown and their frames hold {human(over)} more than the memory "
            f"limit {human(limit.total)}, with nothing else left to let go (a shorter window, "
            "fewer views or a larger --memory fit)"
        )

    def streamed(self) -> str | None:
        """Why a view's window streams from the store instead of staying resident (its
        session's one line: the memory limit leaves its steps too little room), else None."""
        return self.said("streamed")

    def said(self, key: str) -> str | None:
        """The first reason the views' sessions give under `key` in their stats (why the
        window streams, why a coarse frame read nothing ahead), else None."""
        for slot in self.slots:
            why = slot.session.stats.get(key) if slot.session is not None else None
            if why:
                return why
        return None

    def sharp(self, n: int) -> bool:
        """Whether the first `n` views show full resolution (no coarser level to refine)."""
        return all(s.session is not None and not s.session.shown_level for s in self.slots[:n])

    def manager(self, level: int, pool: str) -> WindowManager | None:
        """The window manager of `level` and `pool` the views share, if one was made."""
        return self._managers.get(manager_key(level, pool))

    def full_resolution(self, views: range) -> None:
        """Bring views to full resolution (probes, saves and movies never use a coarse one)."""
        for i in views:
            slot = self.slots[i]
            if slot.session is None:
                continue
            if slot.cv is None:  # the frame that moved its window failed: made again
                with INTEGRATE_LOCK:
                    slot.cv = slot.session.current()
            self.refine_slot(slot)

    def refine_slot(self, slot: ViewSlot) -> float:
        """The slot's chronovolume at full resolution if it was coarse; the ms it took. A
        refine recolours nothing (its frame's `FrameTimes` started at zero)."""
        if slot is self.slots[0]:  # the refine's first view
            self.refine_incremental, self.why_not_incremental = False, None
        if self._slabs is None:
            self._slabs = pays(self.engine, self.device)
        if self._slabs and slot.session.shown_level != 0:  # type: ignore[union-attr]
            # a refine comes: its slabs rewrite the texture as it integrates, so an unread
            # recolour there goes first (at full resolution already nothing is rewritten)
            self.recolouring.settle(slot)
        writes = SlabUpload(slot)  # its texture written slab by slab as it integrates
        with INTEGRATE_LOCK, slabs_to(writes.put) if self._slabs else nullcontext():
            cv = slot.session.refine()  # type: ignore[union-attr]
        writes.done(cv)
        self.times.slab_upload_ms += writes.ms
        if cv is None:
            return 0.0
        slot.cv = cv
        stats = slot.session.stats  # type: ignore[union-attr]
        self.refine_incremental = self.refine_incremental or bool(stats.get("incremental"))
        self.why_not_incremental = self.why_not_incremental or self._why_integrated([slot])
        self.times.read_ms += float(stats.get("read_ms", 0.0))
        return float(stats.get("integrate_ms", 0.0))

    @staticmethod
    def _why_integrated(slots: list[ViewSlot]) -> str | None:
        """Why the first of `slots` whose window was integrated again did not slide it (a
        slide predicted dearer than integrating, on this machine's rates: `costs.Costs`;
        relative time positions; the memory budget), else None."""
        for s in slots:
            stats = s.session.stats if s.session is not None else {}
            if stats.get("path") == "reintegrate" and stats.get("why_not_incremental"):
                return stats["why_not_incremental"]
        return None

    def release(self) -> None:
        """Free the textures (on the GL thread), the sessions and the window managers."""
        slots, self.slots = self.slots, []
        self.shown_managers = ()
        if any(s.volume is not None for s in slots):
            release_on_gl(lambda rc: [s.release_gl() for s in slots])
        for s in slots:
            s.drop_session()
        self._close_managers()
        limit = process_memory.current()
        if limit is not None:
            limit.expect(self, 0)
            limit.resident(self, None, set(), 0)  # nothing shown: no window of its counts

    def _close_managers(self) -> None:
        """Let go of the data set's managers: closed where they are this client's own; shared,
        they stay, and the sessions closed before have let go of their windows in them
        (`WindowManager.let_go`)."""
        self._managers = {}
        if self._own:
            self._shared.close()
            self._shared = SharedSteps()


def _release_winners(slot: ViewSlot) -> None:
    """Let go of the slot's winners (viewer/recolouring.py `Prepared`): another window or
    session comes, for which they are stale. Freed on the GL thread, where they may be
    textures; GL work runs in turn, so before any winners prepared next."""
    prepared, slot.recolour = slot.recolour, None
    if prepared is not None:
        gl_submit(lambda rc: prepared.release())


def _drop(slot: ViewSlot) -> None:
    """The slot's session closed, and its winners with it (kept, a data set opened after an
    edit held the old one's, 1.2 GB at 512^3, until the next edit)."""
    _release_winners(slot)
    slot.drop_session()
