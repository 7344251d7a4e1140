"""One level of an interactive session: a series, a moving time window, and the chronovolume
kept up to date.

A `LevelSession` is what a `Session` (a viewer's or a notebook's) integrates each level with. Its
steps come from a `WindowManager` (resident under the memory budget, prefetched in
the scrub direction, no step read twice while resident). How a new window is
integrated depends on the time positions (docs/semantics.md, sliding windows):

- ``absolute`` positions with forward or backward order: a step's colour does
  not depend on the window, so the window's state is updated instead of
  recomputed. Each mode says how (`chronocl.modes`): modes that slide by
  inversion keep sums in fixed point and add the entering and subtract the
  leaving steps exactly (a part they aggregate, like additive's opacity, slides
  like the others); the rest slide through a `SlidingAggregate` of partial
  chronovolumes, combined on the engine.
- ``relative`` positions, importance orders, jumps to a window that does not
  overlap the last one, and spec changes: the window is re-integrated, from
  resident data only.

The partial volumes that sliding holds are charged to the same memory budget
as the resident steps; when both do not fit, the session re-integrates. On a GPU
they stay on the device, held from its budget too (`Slider`, docs/window.md).

A `LevelSession` integrates one level of the series; a `Session`
(`chronocl.integration.interactive.session`) takes one from its `SessionPool` for each level and
pooling it shows.
"""

from __future__ import annotations

import dataclasses
import time
from typing import NamedTuple

import numpy as np

from chronocl.core.budget import human
from chronocl.core.errors import InvalidParameterError, SupersededError
from chronocl.core.interrupt import watched
from chronocl.core.process_memory import Streaming
from chronocl.core.selection import Selection, parse_selection
from chronocl.core.tuning import TUNING
from chronocl.data.bricks import PartlyResidentBricks, ResidentBricks, SeriesBricks
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.data.window import WindowManager
from chronocl.engine.device_steps import DeviceBricks, DeviceWindow
from chronocl.integration.inmemory import (
    Job,
    WinnersOut,
    check_level,
    integrate_bricks,
    value_range,
    window_job,
)
from chronocl.integration.interactive.costs import Move
from chronocl.integration.interactive.moves import fixed
from chronocl.integration.interactive.settings import Settings, manager_key
from chronocl.integration.interactive.slider import (
    Slider,
    slide_plan,
    slides_by_sums,
    slides_to,
)
from chronocl.integration.interactive.winners import RECOLOURED, Winners, why_not
from chronocl.integration.interactive.winners import winners as gathered
from chronocl.modes.base import FaintSums
from chronocl.modes.spec import IntegrationSpec


class LevelSession:
    """One level of a `Session`: a series, a window and an integration spec at that level,
    which `show` brings up to date and returns as a Chronovolume (built by a `SessionPool`
    from its `Session`'s settings, `setup`: its spec and budget this level's; `manager`:
    another's resident steps, parallel views of one window; `streaming`: it streams from the
    start, `stream`). It never writes into a chronovolume it returned."""

    def __init__(
        self,
        series: TimeSeries,
        setup: Settings,
        *,
        level: int = 0,
        manager: WindowManager | None = None,
        streaming: Streaming | None = None,
    ) -> None:
        self.base = series
        # The spec as asked; `self.spec` is it with its value range fixed (`fix_range`).
        self.asked = self.spec = setup.asked
        self.engine = setup.engine
        self.budget = setup.budget
        self.display = setup.display
        self.costs = setup.costs  # the rates measured, this level's recorded into them
        self.weighs_slides = setup.weighs_slides  # slide only where they predict it cheaper
        self.selection: Selection | None = None
        self.stats: dict = {}
        self._arrays: dict[int, np.ndarray] = {}
        # CPU devices read the window where the manager's slots hold it; others stack it.
        in_place = self.engine.reads_in_place
        self._bricks = ResidentBricks(self._arrays, in_place=in_place)
        self._slider: Slider | None = None
        # what the slides integrated since the window was jumped to cost over slides of a
        # filled state, in steps integrated: a state is filled once it reaches the fill's
        # (`costs.Move.rent`)
        self._rent = 0.0
        self._cv: Chronovolume | None = None
        # (t_index, winners) the kernels wrote with the window's integration (`winners`)
        self._won: tuple[np.ndarray, Winners] | None = None
        self.streaming = streaming  # `stream`
        prefetch = setup.prefetch
        self.level = check_level(series, level)
        self.series = series.level(self.level, self.spec.integration.pool)
        # GPUs keep the window's steps in device memory: an edit uploads none, a slide one.
        self._device = DeviceWindow(self.engine, self.series)
        # Sessions that show one window in several views can share one manager's resident steps.
        managers = setup.managers
        self.owns_manager = manager is None and managers is None
        if manager is None and managers is not None:
            key = manager_key(self.level, self.spec.integration.pool)
            if key not in managers:
                managers[key] = WindowManager(self.series, self.budget, prefetch=prefetch)
            manager = managers[key]
        self.manager = manager or WindowManager(self.series, self.budget, prefetch=prefetch)

    # -- public --------------------------------------------------------------------------
    def window(self) -> Selection:
        """The window shown (before any: every step)."""
        if self.selection is None:
            self.selection = parse_selection(None, self.base.n_steps)
        return self.selection

    def show(self, selection: Selection, spec: IntegrationSpec | None = None) -> Chronovolume:
        """The chronovolume of `selection` under `spec` (default: the current one): a window
        and a spec change at once, integrated once."""
        self.asked, spec = fixed(self.base, self.asked, self.spec, spec, selection)
        if spec != self.spec:  # of this session's pooling (`SessionPool.session`)
            self.spec = spec
            self._slider, self._rent = None, 0.0
            self._cv = self._won = None
        return self._update(selection)

    def current(self) -> Chronovolume:
        """The chronovolume of the current window and spec."""
        if self._cv is None:
            return self._update(self.window())
        return self._cv

    def winners(self, value_range: tuple | None = None) -> Winners | None:
        """The window's winners, to recolour a TF edit without integrating: those the kernels
        wrote with the window's integration (a display session in max, min or change), else
        gathered by the session's engine (`Engine.gather`) from the window's resident steps;
        their u at `value_range` (an edit's, `Session.recolours`), else the shown's. None where
        the mode has none, nothing is integrated or a step of the window is not resident."""
        kept = self.kept_winners(value_range)
        if kept is not None:
            return kept
        cv, spec, arrays = self._cv, self.spec, self._arrays
        if cv is None or cv.t_index is None or spec.mode not in RECOLOURED:
            return None
        steps = self.window().steps
        if any(s not in arrays for s in steps):
            return None
        vr = tuple(value_range if value_range is not None else cv.metadata["value_range"])
        return gathered(cv.t_index, arrays, steps, self.base.n_steps, vr, spec, self.engine)

    def kept_winners(self, value_range: tuple | None = None) -> Winners | None:
        """The winners the kernels wrote with the chronovolume shown (nothing to gather), their
        u at `value_range` (None: the range it is coloured at), under the spec shown; else
        None."""
        cv, won = self._cv, self._won
        if cv is None or won is None or won[0] is not cv.t_index:
            return None
        vr = value_range if value_range is not None else cv.metadata["value_range"]
        want = tuple(map(float, vr))
        if want != tuple(map(float, won[1].value_range)):
            return None
        return dataclasses.replace(won[1], spec=self.spec)  # the spec shown, as gathered

    def value_range_of(self, spec: IntegrationSpec) -> tuple[float, float]:
        """The value range `spec` normalises the window's values by."""
        return tuple(map(float, value_range(self.series, self.window(), spec)))

    def recolours(self, spec: IntegrationSpec) -> Recolour | str:
        """Where `spec` only recolours the last chronovolume: this session, `spec` fixed for
        the window and the value range it colours at; else why not, in one line."""
        if self._cv is None:
            return "nothing is integrated yet"
        _, new = fixed(self.base, self.asked, self.spec, spec, self.window())
        steps = tuple(self._cv.metadata["selection"]["steps"])
        old_range = tuple(self._cv.metadata["value_range"])
        at = self.value_range_of(new)
        why = why_not(self.spec, new, old_range, at, steps, self.base.n_steps)
        return Recolour(self, new, at) if why is None else why

    def adopt(self, asked: IntegrationSpec, spec: IntegrationSpec, cv: Chronovolume) -> None:
        """Show `cv`, this window recoloured under `spec` (asked as `asked`), as if integrated.
        The sliding state held the old colours: the next slide integrates the window again."""
        self.asked, self.spec, self._cv, self._slider = asked, spec, cv, None
        self._rent = 0.0  # a state for another spec: its rent starts again

    def read_ahead(self, selection: Selection) -> str | None:
        """Start reading `selection`'s steps in the background (a `Session` shows the window at
        a coarse level meanwhile); else why not: the window streams (`streams`), or it is over
        the room the sliding state and a kept brick leave its manager beside the steps this
        session still holds (those its state slides from; the others go first, as `leaving`
        lets them go: a library's session is not told, and read a window beside the last)."""
        if self.streams(selection):
            return "full resolution streams its window"
        self.leaving(selection)
        window = selection.width * self.manager.step_bytes
        held = len(set(self._arrays) - set(selection.steps))
        if window + held * self.manager.step_bytes > self.manager.budget:
            beside = f" beside the {held} steps its state slides from" if held else ""
            left = human(self.manager.budget)
            return f"the window needs {human(window)}{beside} > {left} left to it"
        self.manager.request(selection.steps, owner=self)
        return None

    def leaving(self, selection: Selection) -> None:
        """`selection` is shown next: the chronovolume of another window is never shown again,
        so it goes now, before any view integrates (the new one takes its memory); the steps
        leaving go too (`_give_way`), before another view reads `selection` (two views of one
        window jumping held the old window while the first read the new one, and both old
        frames: 4 GB over the steady 8.8 at 512^3)."""
        if self.selection is None or selection == self.selection:
            return
        if not slides_to(self.selection, selection):
            self._rent = 0.0  # a jump, seen where this level draws none of the frames between
        self._cv = self._won = None
        self._give_way(selection)

    def stream(self, why: Streaming | None) -> None:
        """From now on the window streams from the store (`why`: the reason, the bytes its
        slabs may take and the steps that stay resident), or stays resident again (None): a
        viewer's decision for every view at once, before a frame
        (`chronocl.viewer.view_sessions`). Streaming, it holds only the steps kept, and the
        others nobody else wants give way now, before any view streams them (held meanwhile,
        the window was there twice over at the peak); the chronovolume and winners shown
        stay."""
        self.streaming = why
        if why is None:
            return
        held = self._arrays
        leaving = [s for s in held if s not in why.keep]
        if not self.owns_manager:
            self.manager.let_go(self)
        self._hold({s: a for s, a in held.items() if s in why.keep})
        del held
        self._bricks.forget()
        self._slider, self._rent = None, 0.0
        self.manager.drop(leaving)

    def set_aside(self) -> None:
        """Hold nothing of the window: another pooling's session of this level shows it now.
        Its steps stay resident in the shared manager but may give way; its chronovolume,
        sliding state and device copies go (shown again, the window integrates anew)."""
        if not self.owns_manager:  # its window gives way to the others' (`let_go`)
            self.manager.let_go(self)
        self._device.release()
        self._hold({})
        self._bricks.forget()
        self._slider, self._rent = None, 0.0
        self._cv = self._won = None

    def close(self) -> None:
        if self.owns_manager:
            self.manager.close()
        self.set_aside()

    # -- internals -----------------------------------------------------------------------
    def _update(self, selection: Selection) -> Chronovolume:
        t = time.perf_counter()
        old = self.selection
        if old is not None and selection == old and self._cv is not None:
            return self._cv
        if old is None or not slides_to(old, selection):
            self._rent = 0.0  # a jump: even where it streams or its integration is given up
        window = selection.width * self.manager.step_bytes
        if self.streams(selection):  # a viewer's memory limit leaves no room, or the budget
            why = f"the window needs {human(window)} > budget {human(self.budget)}"
            return self._stream(selection, t, self.streaming or Streaming(why, self.budget))
        voxels, move = int(np.prod(self.series.volume_shape)), self._move(selection)
        width, budget = selection.width, self.budget
        costs = self.costs if self.weighs_slides else None
        reason, keep, state = slide_plan(self.spec, voxels, width, window, budget, costs, move)
        self._bricks.keep = keep
        if self.owns_manager:
            self.manager.budget = self.budget - (0 if reason else state) - keep * window
        direction = 0 if old is None else int(np.sign(selection.steps[0] - old.steps[0]))
        self._give_way(selection, slides=reason is None)
        t_read = time.perf_counter()
        arrays = dict(
            zip(
                selection.steps,
                self.manager.get(selection.steps, direction, owner=self),
                strict=True,
            )
        )
        read_ms = 1e3 * (time.perf_counter() - t_read)
        leaving = {s: a for s, a in self._arrays.items() if s not in arrays}
        self._hold(arrays)
        self.selection = selection
        slider, cv, faint = self._slider, None, None
        path = "reintegrate"
        if reason is None and slider is not None and slider.can_move_to(selection):
            # Neither holds until it completes: a slide failing half way (out of memory) is torn
            self._cv, self._slider, self._won = None, None, None
            t_slide, fill = time.perf_counter(), 0 if slider.placed else selection.width
            try:
                cv = slider.move_to(selection, {**leaving, **arrays})
            except FaintSums as too_faint:  # integrated below; the state, moved, slides on
                faint, reason = slider, f"{too_faint}; integrated"
            except SupersededError:
                if fill:  # a fill given up (newer input) bought nothing: no retry at every frame
                    self._rent = 0.0
                raise
            else:
                self._slider, path = slider, "incremental"
                ms = 1e3 * (time.perf_counter() - t_slide)  # the first slide of a state fills it
                self.costs.record_slide(self.level, ms, voxels, move.shift, fill, move.inverts)
        if cv is None:
            job = window_job(self.series, selection, self.spec)
            bricks = self._device.bricks(self._arrays, selection.width) or self._bricks
            # Neither the last chronovolume nor the sliding state holds for this window until
            # the integration below completes (it may be given up: `chronocl.core.interrupt`).
            self._cv, self._slider, self._won = None, None, None
            t_direct = time.perf_counter()
            # a viewer's full-resolution window in max, min or change: each voxel's winner too,
            # as it integrates (its TF edits recolour level 0 alone)
            won = WinnersOut() if self.display and self.level == 0 else None
            slab = self._slab_rows(bricks)
            cv = integrate_bricks(
                job, self.engine, bricks, slab=slab, display=self.display, winners=won
            )
            ms = 1e3 * (time.perf_counter() - t_direct)
            self.costs.record_direct(self.level, ms, voxels, selection.width)
            self._keep_won(cv, won, job)
            # Jumps and spec changes integrate directly (one pass over the window); the
            # sliding state starts from this window and is filled lazily on the next slide.
            if faint is not None:
                self._slider = faint
            elif reason is None:
                self._slider = Slider(
                    self.series,
                    self.engine,
                    self.spec,
                    selection,
                    job.value_range,
                    self._device,
                    self.display,
                )
        self._cv = cv
        # a state filled has paid the rent; a slide integrated pays its share (in `_move`)
        self._rent = 0.0 if path == "incremental" or faint is not None else move.rent
        self._record(t, path, reason, read_ms)
        return cv

    def _move(self, selection: Selection) -> Move:
        """The move to `selection` as a slide is costed: the steps entering where the state can
        slide (else a one-step slide's, which decides whether the window integrated now keeps a
        state), the steps sent to the device for every integration, the state's fill paid, and
        the rent paid towards it (none after a jump: `_update` starts it again); a slide
        integrated, with no state to slide, pays its own share at once, so the integration that
        brings the rent up to the fill keeps a state, and the next slide fills it."""
        old, slider = self.selection, self._slider
        slides = old is not None and slides_to(old, selection)
        move = Move(self.level, inverts=slides_by_sums(self.spec), rent=self._rent)
        move = move._replace(travels=self._device.why is not None)
        if not slides:
            return move
        entering = len(set(selection.steps) - set(old.steps))
        if slider is not None and slider.can_move_to(selection):
            return move._replace(shift=entering, filled=slider.placed)
        if self.weighs_slides and entering:
            voxels = int(np.prod(self.series.volume_shape))
            paid = self.costs.rent(voxels, selection.width, move._replace(shift=entering))
            move = move._replace(rent=move.rent + paid)
        return move

    def streams(self, selection: Selection) -> bool:
        """Whether `selection` is streamed from the store by z-slabs, not kept resident: a
        viewer's limit leaves it no room (`stream`), or it is over this level's budget."""
        window = selection.width * self.manager.step_bytes
        return self.streaming is not None or window > self.budget

    def slide_ms(self, selection: Selection, spec: IntegrationSpec) -> float | None:
        """The ms moving to `selection` under `spec` (fixed: `moves.fixed`) is predicted to take
        where it slides incrementally (a viewer's costs, `costs.Costs.slide_ms`), else None:
        a level policy predicts such a frame from it, not from integrating its window."""
        slider, costs = self._slider, self.costs
        if not self.weighs_slides or self.streaming is not None:
            return None
        if slider is None or spec != self.spec:
            return None
        if slider.faint:  # (its next slide is likely faint too: a slide and an integration)
            return None
        if self.selection is None or not slider.can_move_to(selection):
            return None
        voxels, move = int(np.prod(self.series.volume_shape)), self._move(selection)
        window = selection.width * self.manager.step_bytes
        reason, _, _ = slide_plan(spec, voxels, selection.width, window, self.budget, costs, move)
        return None if reason else costs.slide_ms(voxels, selection.width, move)

    def _give_way(self, selection: Selection, slides: bool = True) -> None:
        """Let go of what moving to `selection` will not read, before its steps are read: where
        it is integrated anew (it does not slide, or its state cannot) every step outside it
        (`_let_go`); where its state slides, the stacked brick kept for a spec change (the old
        window's, stale once it moves) and the steps leaving an aggregate, which only drops
        them (a slide by sums reads them to take them out: `slider.slide_plan` charges them)."""
        if not (slides and self._slider is not None and self._slider.can_move_to(selection)):
            self._let_go(selection)
            return
        self._bricks.forget()
        if self.spec.integration.slides != "invert":
            wanted = set(selection.steps)
            self._hold({s: a for s, a in self._arrays.items() if s in wanted})

    def _let_go(self, selection: Selection) -> None:
        """Drop the steps that leave a window integrated anew before the entering ones are
        read, so that their slots take them: held, they left entering steps arrays outside
        the slots' block, and each window holding one was stacked (5 GB copied at 512^3)."""
        wanted = set(selection.steps)
        self._hold({s: a for s, a in self._arrays.items() if s in wanted})
        self._bricks.forget()
        self._slider = None

    def _hold(self, arrays: dict[int, np.ndarray]) -> None:
        """The window's step arrays, for the session and its bricks alike: a step either one
        still held could not give way in the shared manager (`WindowManager._held`)."""
        self._arrays = arrays
        self._bricks.arrays = arrays

    def _stream(self, selection: Selection, t: float, streaming: Streaming) -> Chronovolume:
        """A window whose steps have no room to stay resident (`streaming`: why, the bytes its
        slabs may take and the steps kept resident): integrated z-slab by z-slab, the steps
        kept copied from memory and the rest read from the store, each slab's brick a quarter
        of the room at most but at least 1/`TUNING.stream_slabs` of the volume (slabs of a row
        or two decoded every chunk once a row), no sliding; a display session at full
        resolution keeps its winners as it would resident, so that its TF edits recolour
        without streaming the window again (unless the value range changes)."""
        why, room, keep = streaming
        job = window_job(self.series, selection, self.spec)
        rows = max(
            room // (4 * max(1, job.row_bytes)),
            -(-self.series.volume_shape[0] // TUNING.stream_slabs),
        )
        self._slider, self.selection, self._cv, self._won = None, selection, None, None
        self._bricks.forget()
        kept = [s for s in selection.steps if s in keep]
        t_read = time.perf_counter()
        arrays = self.manager.get(kept, owner=self) if kept else []
        read_ms = 1e3 * (time.perf_counter() - t_read)
        self._hold(dict(zip(kept, arrays, strict=True)))
        del arrays
        bricks = PartlyResidentBricks(self.series, self._arrays) if kept else None
        won = WinnersOut() if self.display and self.level == 0 else None
        cv = integrate_bricks(
            job,
            self.engine,
            bricks or SeriesBricks(self.series),
            slab=max(1, rows),
            display=self.display,
            winners=won,
        )
        voxels = int(np.prod(self.series.volume_shape))
        ms = 1e3 * (time.perf_counter() - t)
        self.costs.record_streamed(self.level, ms, voxels, selection.width)
        self._keep_won(cv, won, job)
        self._cv = cv
        some = f"{len(kept)} of {selection.width} steps resident, the rest " if kept else ""
        self._record(t, "streamed", f"{why}: {some}streamed by z-slabs", read_ms)
        return self._cv

    def _slab_rows(self, bricks: object) -> int | None:
        """Rows per slab of a window integrated from `bricks`: work that may be given up (a
        viewer's refine) integrates a window read in place on the host, or from its steps kept
        on the device (`DeviceBricks`), in `TUNING.refine_slabs` slabs, so newer input stops it
        within one slab's time and each finished slab is handed on (`chronocl.core.slab_sink`)
        while the next integrates; such slabs cost no copy. Otherwise (and for a window
        stacked, which a kept brick serves whole again) as many rows as the engine takes at
        once."""
        free = isinstance(bricks, DeviceBricks) or (bricks is self._bricks and bricks.in_place)
        if not (watched() and free):
            return None
        return -(-self.series.volume_shape[0] // TUNING.refine_slabs)

    def _keep_won(self, cv: Chronovolume, won: WinnersOut | None, job: Job) -> None:
        """Keep the winners the kernels wrote integrating `cv` (`won`), with its t_index."""
        if won is not None and won.u is not None:
            sel, n = job.selection, self.base.n_steps
            w = Winners(won.u, won.k, sel.steps, n, job.value_range, self.spec)
            self._won = (cv.t_index, w)

    def _record(self, t: float, path: str, reason: str | None, read_ms: float) -> None:
        self.stats = {
            "level": self.level,
            "integrate_ms": 1e3 * (time.perf_counter() - t),
            # of it, waiting for the window's resident steps: their reads (a streamed window's
            # other steps are read as it integrates); 0 where they were resident or read ahead
            "read_ms": read_ms,
            "path": path,
            "incremental": path == "incremental",
            "why_not_incremental": reason,
            "steps": list(self.selection.steps),
            "resident_steps": len(self.manager.resident()),
            "reads": sum(self.manager.reads.values()),
            "held_partials": 0 if self._slider is None else self._slider.held,
            "device_steps": None if self._device.slots is None else self._device.slots.resident(),
            "why_not_on_device": self._device.why,
            # why the window is read from the store slab by slab, not resident (None: it is);
            # kept by a recolouring's stats (`Session.adopt`): the window still streams
            "streamed": reason if path == "streamed" else None,
        }


class Recolour(NamedTuple):
    """An edit that only recolours the window shown (`LevelSession.recolours`)."""

    level: LevelSession  # the session that holds the window's winners
    spec: IntegrationSpec  # the edit's spec, fixed for the window
    value_range: tuple[float, float]  # the range it colours at (max/min: may be another)


class SessionPool:
    """The level sessions of a `Session`: one per level and, coarse, pooling of `series`
    (`manager_key`), built when first asked for from `setup`, sharing its engine and, when it
    has `managers`, the window managers in it (the views of one client). `finest` (the level
    a `Session` refines to) gets the whole budget, coarser levels an eighth; `manager` serves
    the session of its `manager_key` (another session's resident steps)."""

    def __init__(
        self,
        series: TimeSeries,
        setup: Settings,
        finest: int = 0,
        manager: tuple[tuple[int, str], WindowManager] | None = None,
    ) -> None:
        self.series = series
        self.setup = setup
        self.finest = finest
        self.manager = manager
        self.sessions: dict[tuple[int, str], LevelSession] = {}
        self.streaming: Streaming | None = None  # the finest level's (`stream`)
        self.closed = False

    def session(self, level: int, spec: IntegrationSpec) -> LevelSession:
        """The session of `level` for `spec`'s pooling (full resolution: one for all), the
        finest streaming as `stream` last said (one made since from the start)."""
        if self.closed:  # (it would make a window manager, and readers, that none closes)
            raise InvalidParameterError("this session is closed; make a new one")
        key = manager_key(level, spec.integration.pool)
        # Another pooling's session of the level held its window after a mode switch: a jump
        # then read the new window beside it, over the limit. One that owns its manager goes
        # whole (its steps are the other pooling's; coming back reads them again).
        for other, s in list(self.sessions.items()):
            if other != key and other[0] == level:
                if s.owns_manager:
                    s.close()
                    del self.sessions[other]
                else:
                    s.set_aside()
        if key not in self.sessions:
            o = self.setup
            # Coarse levels hold 1/8 of the voxels of the next finer one or less.
            budget = o.budget if level == self.finest else max(1, o.budget // 8)
            shared = self.manager
            self.sessions[key] = LevelSession(
                self.series,
                o._replace(asked=spec, budget=budget),
                level=level,
                manager=shared[1] if shared and shared[0] == key else None,
                streaming=self.streaming if level == self.finest else None,
            )
        return self.sessions[key]

    def stream(self, why: Streaming | None) -> None:
        """The finest level streams its window from now on (`LevelSession.stream`), or not
        (None); coarser levels' windows are small and stay resident."""
        self.streaming = why
        for (level, _), s in self.sessions.items():
            if level == self.finest:
                s.stream(why)

    def close(self) -> None:
        self.closed = True
        for s in self.sessions.values():
            s.close()
        self.sessions = {}
