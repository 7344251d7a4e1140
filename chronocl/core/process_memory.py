"""The process's memory limit (the viewer's `--memory`): resident steps give way to the rest.

A viewer's memory goes to the steps its windows keep resident (`chronocl.data.window`) and to
what its frames hold: chronovolumes, recolouring's winners and outputs, textures and their
staging, device copies, the OpenCL and GL drivers' own memory, one set per view and client.
Those are many, sized by the data, the views and the drivers. So instead of a ledger of
estimates, the process's resident memory itself (what the kernel counts: every buffer) is kept
under the limit, and the steps are what gives way:

- before each frame and each step read, steps read ahead or kept from older windows are
  dropped and the pages of free slots handed back, until the resident steps plus what the
  frames need fit the limit (`fit`). The memory of dead outputs and staging kept for the next
  frames (`chronocl.core.memory.spares`, the pool of reused host buffers) counts as the
  frames': the next frame takes it again, so dropping it would lower no peak and fault as
  much in afresh (about 1 s for 1 GB at 512^3);
  what nobody takes goes back after `TUNING.spare_seconds`;
- what the frames need is what the process holds beside its steps now or after any of the last
  frames, whichever is more, and at least what the clients' views now expect theirs to hold
  (`floor`, `expect`) with the process's own (`TUNING.process_bytes`);
- the steps of the windows being shown are never dropped. So a window is kept resident only
  where its steps fit beside what the views' frames are expected to hold (`expect`) and the
  process's own memory (`TUNING.process_bytes`): `window_room`, against which a viewer weighs the
  steps of every window shown that stays resident (`resident`, each step once) before a
  frame; where they do not fit, the steps that still fit stay and the rest of its views'
  windows stream from the store slab by slab (`chronocl.integration.interactive.session`).
  Where frames still exceed the limit, `excess` says by how much (the viewer logs it once).

One limit per process (`limited`), shared by every client's window managers, which register
with it when they are made (`register`). Without one (a script, `chronocl integrate`) each
manager keeps to its own budget only, as before.
"""

from __future__ import annotations

import threading
import weakref
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from typing import NamedTuple, Protocol

from chronocl.core.budget import resident_bytes
from chronocl.core.tuning import TUNING


class Residency(NamedTuple):
    """A window's decision (`ProcessLimit.resident`): whether it all stays resident, the bytes
    every window shown needs, the room they have, and the window's steps that stay."""

    fits: bool
    need: int
    room: int
    keep: frozenset[int]


class Streaming(NamedTuple):
    """A window that does not all stay resident: why, the bytes its streamed slabs may take,
    and its steps that stay resident (the rest are read from the store slab by slab)."""

    why: str
    room: int
    keep: frozenset[int] = frozenset()


class Holder(Protocol):
    """What holds steps that may give way (a `chronocl.data.window.WindowManager`)."""

    def held_bytes(self) -> int: ...

    def settled_bytes(self) -> int: ...

    def shed(self, nbytes: int, ahead: bool, wait: bool) -> int: ...


class ProcessLimit:
    """`total` bytes for the whole process (see the module's docstring)."""

    def __init__(self, total: int) -> None:
        self.total = int(total)
        self._expected: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # `expect`
        self._windows: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # `resident`
        self.over = 0  # bytes past the limit after the last fit, with nothing left to drop
        self._after: deque[int] = deque(maxlen=TUNING.recent_frames)
        self._holders: weakref.WeakSet = weakref.WeakSet()
        self._lock = threading.Lock()

    def register(self, holder: Holder) -> None:
        with self._lock:
            self._holders.add(holder)

    def expect(self, owner: object, nbytes: int) -> None:
        """What `owner` (a client's views) expects its frames to hold before one is measured;
        `floor` is the sum over the owners alive (0: none now)."""
        with self._lock:
            self._expected[owner] = int(nbytes)

    @property
    def floor(self) -> int:
        with self._lock:
            return sum(self._expected.values())

    def steps(self) -> int:
        """Bytes the registered holders keep in steps (resident, loading, warm free slots)."""
        return sum(h.held_bytes() for h in self._holders_now())

    def beside(self) -> int:
        """What the process holds now beside its steps: its resident memory less the steps
        read and the slots warmed (a step being read is not subtracted: its pages fill as it
        is read, and counting them held before they are would hide memory beside)."""
        resident = resident_bytes()
        if resident is None:
            return 0
        return max(0, resident - sum(h.settled_bytes() for h in self._holders_now()))

    def need(self) -> int:
        """What the frames are taken to need beside the steps: what was measured, and never
        less than what the views now shown expect with the process's own (a view added, or a
        mode holding more, gets its room before its frame, not after: the soak's second
        view peaked 15% over the limit when only earlier frames were counted)."""
        measured = max(self.beside(), max(self._after) if self._after else 0)
        return max(measured, self.floor + TUNING.process_bytes)

    def window_room(self) -> int:
        """Bytes the windows shown may keep resident: the limit less what every client's views
        expect their frames to hold at their peak (`expect`) and the process's own."""
        return self.total - self.floor - TUNING.process_bytes

    def resident(
        self, owner: object, key: object, steps: set[int], step_bytes: int, reserve: int = 0
    ) -> Residency:
        """Whether `owner`'s window `steps` of data set `key` may stay resident: the steps of
        every window shown that stays resident, the other owners' and this one, each step
        once, fit `window_room`. Decided and noted at once (two clients deciding together
        both counted the other's old window): where it fits, later decisions count it. Where
        it does not, the steps that still fit beside the others' and `reserve` (what the
        streamed slabs take) stay: those the others keep, then the window's last (a window
        slides forward more often than back); the rest stream, and later decisions count the
        kept ones."""
        with self._lock:
            others: dict[object, tuple[set[int], int]] = {}
            for o, (k, st, nbytes) in self._windows.items():
                if o is not owner:
                    others.setdefault(k, (set(), nbytes))[0].update(st)
            theirs = others.get(key, (set(), 0))[0]
            before = sum(len(st) * nbytes for st, nbytes in others.values())
            own = sorted(set(steps) - theirs)
            need = before + len(own) * int(step_bytes)
            room = self.total - sum(self._expected.values()) - TUNING.process_bytes
            fits = need <= room
            if fits:
                keep = frozenset(steps)
            else:
                more = max(0, room - before - reserve) // max(1, int(step_bytes))
                keep = frozenset(set(steps) & theirs) | frozenset(
                    own[len(own) - more :] if more else ()
                )
            if keep:
                self._windows[owner] = (key, keep, int(step_bytes))
            else:
                self._windows.pop(owner, None)
            return Residency(fits, need, room, keep)

    def room(self) -> int:
        """Bytes more steps may take now without dropping any."""
        return self.total - self.steps() - self.need()

    def fit(self, extra: int = 0, *, ahead: bool = True, caller: Holder | None = None) -> int:
        """Drop steps nobody shows until `extra` more bytes of steps fit beside the rest; steps
        read ahead are dropped too unless `ahead` is false (a read ahead makes room only from
        older steps). A holder's caller (which holds its own lock) sheds the others only where
        their lock is free; a caller holding none (a frame) waits for each. Returns the bytes
        still over (0: fits)."""
        over = extra - self.room()
        for holder in self._holders_now(first=caller):
            if over <= 0:
                break
            holder.shed(over, ahead, wait=caller is None or holder is caller)
            over = extra - self.room()
        self.over = max(0, over)
        return self.over

    def excess(self) -> int:
        """Bytes the process holds over the limit now (0: within it)."""
        return max(0, (resident_bytes() or 0) - self.total)

    def frame_done(self) -> None:
        """Note what the process holds beside its steps after a frame (`need`)."""
        self._after.append(self.beside())

    def _holders_now(self, first: Holder | None = None) -> list[Holder]:
        with self._lock:
            holders = list(self._holders)
        if first is not None and first in holders:
            holders.remove(first)
            holders.insert(0, first)
        return holders


_active: list[ProcessLimit] = []  # the limits set, the newest last


def current() -> ProcessLimit | None:
    """The process's limit, where one was set (`limited`): the newest still set."""
    return _active[-1] if _active else None


@contextmanager
def limited(limit: ProcessLimit | None) -> Iterator[ProcessLimit | None]:
    """`limit` is the process's while the block runs (a viewer's lifetime; blocks of two
    viewers may overlap in any order)."""
    if limit is None:
        yield None
        return
    _active.append(limit)
    try:
        yield limit
    finally:
        _active.remove(limit)
