"""Sliding-window aggregation of an associative operation that has no inverse.

Alpha compositing, first hit and max/min combine partial chronovolumes
associatively but cannot take a step back out (docs/semantics.md, sliding windows). A
`SlidingAggregate` holds the steps of a window in time order and their
aggregate under `op(earlier, later)`, and lets the window move either way:
steps enter and leave at both ends (scrubbing forward and backward).

It is the two-stacks scheme made double-ended: the window is split into a
front stack (its top the oldest step) and a back stack (its top the newest),
each holding, level by level, the aggregate from the middle of the window out
to that level. Pushing combines one leaf onto the top; popping drops the top.
A stack that runs empty is refilled by splitting the other one (three
quarters to the side being emptied: cheap for steady scrubbing, and a change
of direction still finds steps on both sides), so every step is rebuilt a
constant number of times on average, whichever way the user scrubs. Leaves
are recomputed from resident data when needed, never stored.

Keeping every level would hold W partial volumes. Each stack keeps only every
B-th level (B = ceil(sqrt(W))) as a checkpoint, its top and the level under it,
and, while it is being popped, the B levels below its top; a missing level is
rebuilt from the checkpoint under it. A stack being pushed onto needs only its
top (each push combines onto it), so once a slide's direction is set one side
holds the B levels and the other two: at most ceil(W/B) + B + 2 partial volumes
(16 at W = 50 where both sides keeping B held 22; 1.5 GiB less at 256^3 alpha).
Memory is O(sqrt W) partial volumes and each slide costs an amortised constant
number of leaves and combines, independent of W; a turn of direction rebuilds
the popped side's levels from a checkpoint (about one piece a slide more on a
scrub that turns every other step, still under steady scrubbing's seven).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

P = TypeVar("P")


class _Stack(Generic[P]):
    """Steps from the middle of the window (bottom) to one end (top), with level aggregates."""

    def __init__(self, leaf: Callable[[int], P], op: Callable[[P, P], P], outer_is_later: bool):
        # The stack holds the leaf and combine functions, not its aggregate: no cycle, so a
        # dropped aggregate frees its partial volumes at once.
        self.leaf, self.op = leaf, op
        self.outer_is_later = outer_is_later
        self.block = 1  # checkpoint spacing, set by the aggregate for the window's width
        self.items: list[int] = []
        self.aggs: dict[int, P] = {}
        self.popping = False  # its last move was a pop: it keeps the B levels below its top
        self.leaves = 0  # leaf evaluations so far
        self.combines = 0  # op evaluations so far

    def rebuild(self, items: Sequence[int], block: int) -> None:
        self.items = list(items)
        self.aggs = {}
        self.block = block

    def _leaf(self, step: int) -> P:
        self.leaves += 1
        return self.leaf(step)

    def _up(self, below: P | None, leaf: P) -> P:
        """The aggregate one level up: the new step sits on the outer side."""
        if below is None:
            return leaf
        self.combines += 1
        return self.op(below, leaf) if self.outer_is_later else self.op(leaf, below)

    def _keep(self, level: int) -> bool:
        b, top = self.block, len(self.items) - 1
        return level % b == 0 or level >= top - 1 or (self.popping and level > top - b)

    def _trim(self) -> None:
        for level in [lv for lv in self.aggs if not self._keep(lv)]:
            del self.aggs[level]

    def top(self) -> P | None:
        """The aggregate of the whole stack (None when empty)."""
        if not self.items:
            return None
        return self._at(len(self.items) - 1)

    def _at(self, level: int) -> P:
        if level in self.aggs:
            return self.aggs[level]
        start = max((lv for lv in self.aggs if lv < level), default=-1)
        acc = self.aggs.get(start)
        for j in range(start + 1, level + 1):
            acc = self._up(acc, self._leaf(self.items[j]))
            if self._keep(j):
                self.aggs[j] = acc
        assert acc is not None
        return acc

    def push(self, step: int) -> None:
        self.popping = False
        self.items.append(step)
        self._at(len(self.items) - 1)  # the new top combines onto the level below it
        self._trim()

    def pop(self) -> int:
        self.popping = True
        self.aggs.pop(len(self.items) - 1, None)
        return self.items.pop()


class SlidingAggregate(Generic[P]):
    """Aggregate of a window of steps that slides both ways.

    `leaf(step)` computes one step's partial; `op(earlier, later)` combines the
    partials of two adjacent runs of steps and must be associative.
    """

    def __init__(self, leaf: Callable[[int], P], op: Callable[[P, P], P]) -> None:
        self.op = op
        self._front: _Stack[P] = _Stack(leaf, op, outer_is_later=False)
        self._back: _Stack[P] = _Stack(leaf, op, outer_is_later=True)
        self._combines = 0  # op evaluations of `value` (the stacks count their own)
        self.reset(())

    @property
    def leaves(self) -> int:
        """Leaf evaluations so far."""
        return self._front.leaves + self._back.leaves

    @property
    def combines(self) -> int:
        """op evaluations so far."""
        return self._front.combines + self._back.combines + self._combines

    def reset(self, steps: Sequence[int], front_share: int | None = None) -> None:
        """Start over with `steps` (oldest first); nothing is computed until needed.

        The oldest `front_share` steps (default: half, rounded up) go to the front stack.
        """
        steps = list(steps)
        block = block_size(len(steps))
        half = (len(steps) + 1) // 2 if front_share is None else front_share
        self._front.rebuild(steps[:half][::-1], block)
        self._back.rebuild(steps[half:], block)

    @property
    def steps(self) -> list[int]:
        """The window's steps, oldest first."""
        return self._front.items[::-1] + self._back.items

    @property
    def held(self) -> int:
        """Partial volumes held now."""
        return len(self._front.aggs) + len(self._back.aggs)

    def push_back(self, step: int) -> None:
        """A newer step enters at the end."""
        self._back.push(step)

    def push_front(self, step: int) -> None:
        """An older step enters at the start."""
        self._front.push(step)

    def pop_front(self) -> int:
        """The oldest step leaves."""
        if not self._front.items:
            self._split(-(-3 * len(self.steps) // 4))
        return self._front.pop()

    def pop_back(self) -> int:
        """The newest step leaves."""
        if not self._back.items:
            self._split(len(self.steps) // 4)
        return self._back.pop()

    def value(self, op: Callable[[P, P], P] | None = None) -> P:
        """The aggregate of the window, oldest step first; `op` (default: the aggregate's, to
        which it must be equal) combines its two ends, the result kept nowhere."""
        front, back = self._front.top(), self._back.top()
        if front is None and back is None:
            raise IndexError("the sliding window is empty")
        if front is None or back is None:
            return front if back is None else back  # type: ignore[return-value]
        self._combines += 1
        return (op or self.op)(front, back)

    def _split(self, front_share: int) -> None:
        steps = self.steps
        if not steps:
            raise IndexError("pop from an empty sliding window")
        self.reset(steps, front_share)


def block_size(n: int) -> int:
    """ceil(sqrt(n)), at least 1."""
    return max(1, math.isqrt(max(0, n - 1)) + 1)
