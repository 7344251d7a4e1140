"""The rates an interactive session's choices are made from, measured on the machine at hand,
in one place (`Costs`): which level a frame is drawn at (`session.LatencyModel` predicts each
level's frame from the rates of integrating, reading and displaying it), whether a window
slides incrementally or is integrated again, and whether a coarse frame reads full
resolution's steps ahead. Pure: fed numbers, it answers; the sessions feed it what they timed
(`LevelSession._update`: integrations from resident steps and slides; `LevelSession._stream`:
windows streamed; `Session._at`: reads and a coarse frame's cores; `Session.record_display`:
the viewer's upload and draw).

**Slide or integrate.** A one-step slide costs about the same whatever the window's width (a
few leaves, one step integrated alone into a partial volume, and combines of two partials; the
splits of the stacks amortised: docs/window.md); integrating the window from its resident steps
costs its width in voxel-steps; and a sliding state is filled once, by its first slide, at about
a leaf and a combine per step. With, per level,

    d = ms per voxel-step of an integration from resident steps    (`record_direct`)
    s = voxel-steps of integration (d) of a steady one-step slide   (`record_slide`)
    f = voxel-steps of integration of a state's fill, per step      (`record_slide(fill=W)`)

a slide of `k` steps of a window of `W` over `V` voxels is predicted at `s * d * V * k`, and
integrating it at `d * V * W`; a state already filled keeps sliding while `s * k < W`. A state
still to be filled costs its fill besides, `f * d * V * W` in one frame (at 256^3, W = 50 on 2
cores: 6-11 s), which pays only over the slides that follow. So it is bought as skis are rented
(`Move.rent`): each slide of `k` steps of a window integrated where no state was kept adds what
integrating cost over a steady slide, `d * V * (W - s * k)`, and the integration that brings
the sum up to the fill keeps a state, which the next slide fills: after about
`f * W / (W - s)` integrated one-step slides since the window was jumped to. A jump, an
integration under another spec, a window that streams and a fill given up for newer input
start the sum again. Whatever the user does next, that costs never much more than twice what
the best choice knowing the moves to come would. The sum is kept in steps integrated (units
of `d * V`), as s and f are. Before 2026-12-01 the fill's share `f * d * V` was taken as paid
on each slide (a scrub across the whole window assumed): every jump at W >= s + f was followed
by a fill, a 6-11 s frame at 256^3, W = 50 here, even where the user slid two steps
(bench/slide_window.py).

Each machine and engine finds its own rates: until measured, s and f are guessed
(`TUNING.slide_steps`, `fill_steps`, from this machine); where the window's steps travel to the
device for every integration (a GPU whose memory holds not the window), d is mostly that
transfer, which a slide pays only for its entering steps and a fill once per step: both are
then guessed at 1, so the first slide after a jump integrates and keeps a state and the second
fills it. The first slide measures f, the next ones s.

s and f are kept in units of d as it stood when they were measured (a slide's ms over the
integration rate then), not in ms: on a machine shared with other work both slow down alike, and
in ms a slide timed while the machine was busy weighed against every later integration at the
busy rate, for good, since an integrated window measures no slide (bench/slide_window.py, 256^3
alpha on 2 cores shared at load 2.4-7, 2026-11-30: d was 0.40-0.83 ns a voxel-step run to run).

Rates are per level (a coarse level's voxels cost more each: fixed overheads), and s and f per
kind of slide besides (`Move.inverts`: a mode sliding by its sums alone adds the entering and
takes out the leaving steps, two pieces, where the others combine partials, about seven): one
kind's slides say little of the other's. d and f are running
averages (`tuning.running`), s the mean of the last `TUNING.slide_memory` slides (so that
the splits of the stacks, a slide in tens dearer than the others, count at their share). A
level's rate of integrating is the one `LatencyModel` predicts its frames from, too.

**Read ahead or not.** While a coarse level shows a window (a scrub), its full-resolution steps
can be read in the background so that the refine at the stop finds them. The reads take host
cores; they pay where the coarse frames leave a core idle for them, and where reading the
window at the stop would cost more than the latency target. `Costs` measures the cores a
coarse frame's integration keeps busy (the process's CPU time over the wall time: all of them
on a CPU device, a fraction of one where a GPU integrates) and a full-resolution step's read
time, and reads ahead where `cores - busy >= 1` and `missing * read > target`. On the 2-core
PoCL machine where this was measured, reading ahead beside the coarse frames took the cores
they needed (the longest stall 195 -> 1 535 ms) and the stop was no faster at a lower priority
(docs/window.md): busy there is about 2 of 2 cores.
"""

from __future__ import annotations

import os
from typing import NamedTuple

from chronocl.core.tuning import TUNING, running

# Pieces (leaves + combines) of a one-step slide through a `SlidingAggregate`, the splits of its
# stacks amortised: counted over 200 slides at W = 10 and 50 (5.5 and 6.7; tests/test_costs.py
# counts them); an inverting mode without an aggregated part integrates the entering and the
# leaving step alone: 2. Only their ratio scales the guess for such a mode.
SLIDE_PIECES = 7.0
INVERT_PIECES = 2.0


class Move(NamedTuple):
    """A move of a session's window, as its slide is costed: at `level`, `shift` steps entering,
    the window's steps sent to the device for every integration (`travels`), the sliding state
    filled already (`filled`: its fill is paid), a mode sliding by sums alone (`inverts`), and
    what the slides of its window integrated since it was last jumped to cost over the slides
    of a filled state (`rent`, in steps integrated, as s and f: the fill is paid once it
    reaches the fill's)."""

    level: int = 0
    shift: int = 1
    travels: bool = False
    filled: bool = False
    inverts: bool = False
    rent: float = 0.0


ONE_STEP = Move()


class Costs:
    """The rates an interactive session's choices are made from, measured on the machine at
    hand, per level: integrating a window, sliding it and filling its sliding state, reading a
    step, a frame's upload and draw (the viewer's), and the cores a coarse frame keeps busy.
    `why_not` says whether a slide is predicted cheaper (None) or why not, `why_not_read_ahead`
    whether coarse frames read ahead; a `LatencyModel` predicts each level's frame from them.
    Shared by the levels of a `Session` and by the sessions of a viewer's views: one machine,
    one engine (and one store for the reads: a viewer measures them anew for another data
    set)."""

    def __init__(self, cores: int | None = None) -> None:
        self.direct: dict[int, float] = {}  # level -> ms per voxel-step, integrated
        # (level, inverts) -> voxel-steps of integration of a steady one-step slide, of a
        # state's fill per step, and the slides averaged so far (up to TUNING.slide_memory)
        self.slide: dict[tuple[int, bool], float] = {}
        self.fill: dict[tuple[int, bool], float] = {}
        self._slides: dict[tuple[int, bool], int] = {}
        # level -> ms per voxel-step of a window streamed from the store, its reads with it
        # (a level policy's alone: nothing slides while a window streams)
        self.streamed: dict[int, float] = {}
        self.reads: dict[int, float] = {}  # level -> ms per voxel of reading a step
        self.display: dict[int, float] = {}  # level -> ms per voxel of a frame's upload + draw
        self.cores = cores_here() if cores is None else cores
        self.busy: float | None = None  # the cores a coarse frame's integration keeps busy

    def record_streamed(self, level: int, ms: float, voxels: int, steps: int) -> None:
        """A window of `steps` steps over `voxels` voxels streamed and integrated in `ms`."""
        self.streamed[level] = running(self.streamed.get(level), ms / max(1, voxels * steps))

    def record_read(self, level: int, seconds: float | None, voxels: int) -> None:
        """A step of `voxels` voxels read at `level` in `seconds` (None: none read yet)."""
        if seconds:
            self.reads[level] = running(self.reads.get(level), 1e3 * seconds / voxels)

    def read_ms(self, level: int, voxels: int) -> float | None:
        """The ms reading a step of `voxels` voxels at `level` takes: at the larger of the
        finest level's rate measured and the level's own (None: no read measured yet)."""
        if not self.reads:
            return None
        return max(self.reads[min(self.reads)], self.reads.get(level, 0.0)) * voxels

    def record_display(self, level: int, ms: float, voxels: int) -> None:
        """A frame of `level`, `voxels` voxels, uploaded and drawn in `ms`."""
        self.display[level] = running(self.display.get(level), ms / voxels)

    def record_frame(self, wall_s: float, cpu_s: float) -> None:
        """A coarse frame's integration took `wall_s`, and the process `cpu_s` of CPU time."""
        if wall_s > 0:
            self.busy = running(self.busy, min(float(self.cores), cpu_s / wall_s))

    def record_direct(self, level: int, ms: float, voxels: int, steps: int) -> None:
        """A window of `steps` steps over `voxels` voxels integrated from its steps in `ms`."""
        self.direct[level] = running(self.direct.get(level), ms / max(1, voxels * steps))

    def record_slide(
        self,
        level: int,
        ms: float,
        voxels: int,
        steps: int = 1,
        fill: int = 0,
        inverts: bool = False,
    ) -> None:
        """A slide of `steps` entering steps that took `ms` over `voxels` voxels; `fill`: the
        width of the window whose state this slide filled (0: a steady slide); `inverts`: of a
        mode sliding by its sums alone. Kept against the level's integration rate now (none
        yet: nothing to weigh it by, and a session integrates a window before it slides it)."""
        d, key = self.direct.get(level), (level, inverts)
        if not d or not (steps or fill):  # (a state showing its window again: no step slid)
            return
        if fill:
            self.fill[key] = running(self.fill.get(key), ms / max(1, voxels * fill) / d)
            return
        n = self._slides[key] = min(TUNING.slide_memory, self._slides.get(key, 0) + 1)
        value, old = ms / max(1, voxels * steps) / d, self.slide.get(key)
        self.slide[key] = value if old is None else old + (value - old) / n

    def predict(self, voxels: int, width: int, move: Move = ONE_STEP) -> tuple | None:
        """(ms integrating, ms sliding, whether sliding is measured) for `move` of a window of
        `width` over `voxels` voxels (None: nothing integrated at its level yet)."""
        d = self.direct.get(move.level)
        if d is None:
            return None
        shift = max(1, abs(move.shift))
        pieces = INVERT_PIECES if move.inverts else SLIDE_PIECES
        guess = 1.0 if move.travels else TUNING.slide_steps * pieces / SLIDE_PIECES
        key = (move.level, move.inverts)
        steady = self.slide.get(key, guess) * d * voxels * shift
        fill = 0.0
        if not move.filled:  # what of it the integrations since the jump have not paid yet
            fill = max(0.0, self._fill_ms(voxels, width, move) - move.rent * d * voxels)
        measured = key in self.slide and (move.filled or key in self.fill)
        return d * voxels * width, steady + fill, measured

    def slide_ms(self, voxels: int, width: int, move: Move = ONE_STEP) -> float | None:
        """The ms `move` of a window of `width` over `voxels` voxels takes as a slide itself: a
        steady slide, and where its state is still to be filled the whole fill (None: nothing
        integrated at its level yet)."""
        steady = self.predict(voxels, width, move._replace(filled=True))
        if steady is None:
            return None
        return steady[1] + (0.0 if move.filled else self._fill_ms(voxels, width, move))

    def rent(self, voxels: int, width: int, move: Move = ONE_STEP) -> float:
        """What `move` of a window of `width` over `voxels` voxels, integrated, costs over the
        steady slide of a filled state, in steps integrated (kept so, as s and f, a machine
        growing busier weighs it at today's rate; 0: nothing integrated at its level yet, or
        no more)."""
        got = self.predict(voxels, width, move._replace(filled=True))
        d = self.direct.get(move.level)
        if got is None or not d:
            return 0.0
        return max(0.0, got[0] - got[1]) / (d * voxels)

    def _fill_ms(self, voxels: int, width: int, move: Move) -> float:
        """The ms filling the sliding state of a window of `width` over `voxels` voxels takes
        (the level integrated: `predict`)."""
        key = (move.level, move.inverts)
        f = self.fill.get(key, 1.0 if move.travels else TUNING.fill_steps)
        return f * self.direct[move.level] * voxels * width

    def why_not(self, voxels: int, width: int, move: Move = ONE_STEP) -> str | None:
        """None where sliding is predicted to pay (or nothing is measured yet), else why not."""
        got = self.predict(voxels, width, move)
        if got is None:
            return None
        direct, slide, measured = got
        if slide < direct:
            return None
        how = "measured" if measured else "not measured yet; guessed"
        fill = ""
        if not move.filled:
            whole = self._fill_ms(voxels, width, move)
            paid = min(whole, move.rent * self.direct[move.level] * voxels)
            paid = f"{paid:.0f} ms of it paid by integrating since the jump"
            fill = f", its state's fill included: {whole:.0f} ms, {paid}"
        return (
            f"integrating the window is predicted at {direct:.0f} ms, sliding it at {slide:.0f} "
            f"ms ({how}{fill}): cheaper to integrate"
        )

    def why_not_read_ahead(self, missing: int, voxels: int, target_ms: float) -> str | None:
        """None where reading `missing` full-resolution steps of `voxels` voxels ahead pays
        (the latency target `target_ms`), else why not."""
        if missing <= 0:
            return "every step of the window is resident"
        read_ms = self.read_ms(0, voxels)
        if self.busy is None or read_ms is None:
            return "nothing measured yet"
        if missing * read_ms <= target_ms:
            return f"reading the {missing} steps at the stop takes {missing * read_ms:.0f} ms"
        idle = self.cores - self.busy
        if idle < TUNING.reader_cores:
            return f"the coarse frames keep {self.busy:.1f} of {self.cores} cores busy"
        return None


def cores_here() -> int:
    """The cores this process may run on (its affinity where the system says, else all)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
