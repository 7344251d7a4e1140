"""Time-step selections: which steps of a series a chronovolume integrates.

A selection is a strictly increasing tuple of step indices s_0 < ... < s_{W-1}
inside [0, T): either a window ``[t0, t1)`` with a stride, or an explicit list.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

from chronocl.core.errors import InvalidSelectionError


@dataclass(frozen=True)
class Selection:
    """The selected steps of a series with `n_steps` steps in all."""

    steps: tuple[int, ...]
    n_steps: int

    def __post_init__(self) -> None:
        if self.n_steps < 1:
            raise InvalidSelectionError("the series has no time steps; ingest at least one step")
        if not self.steps:
            raise InvalidSelectionError(
                "the selection is empty; choose at least one time step, e.g. --window 0:10"
            )
        bad = [s for s in self.steps if not 0 <= s < self.n_steps]
        if bad:
            raise InvalidSelectionError(
                f"time step {bad[0]} is outside [0, {self.n_steps}); "
                f"choose steps between 0 and {self.n_steps - 1}"
            )
        if any(b <= a for a, b in itertools.pairwise(self.steps)):
            raise InvalidSelectionError(
                f"selected steps {list(self.steps)} must be strictly increasing without repeats; "
                "list each step once, in increasing order (an importance order goes in "
                "--order / order=[...])"
            )

    @property
    def width(self) -> int:
        """W, the number of selected steps."""
        return len(self.steps)

    @property
    def stride(self) -> int:
        """Spacing of the first two steps (1 for a single step): what a slide moves by."""
        return self.steps[1] - self.steps[0] if len(self.steps) > 1 else 1

    @classmethod
    def window(cls, t0: int, t1: int, stride: int, n_steps: int) -> Selection:
        """Steps t0, t0+stride, ... below t1."""
        if stride < 1:
            raise InvalidSelectionError(f"stride must be at least 1, got {stride}")
        inside = 0 <= min(t0, t1) and max(t0, t1) <= n_steps  # else: outside, below
        if t0 == t1 and inside:
            raise InvalidSelectionError(
                f"window {t0}:{t1} is empty: it ends where it starts; the end is exclusive, "
                f"so write {t0}:{t0 + 1} for step {t0} alone"
            )
        if t1 < t0 and inside:
            raise InvalidSelectionError(
                f"window {t0}:{t1} is reversed: write {t1}:{t0} (windows run forward; to "
                "integrate the newest step first use --order backward / order='backward')"
            )
        if not (0 <= t0 < t1 <= n_steps):
            raise InvalidSelectionError(
                f"window {t0}:{t1} is outside the series' steps [0, {n_steps}); "
                f"use 0 <= t0 < t1 <= {n_steps}"
            )
        return cls(tuple(range(t0, t1, stride)), n_steps)

    def describe(self) -> str:
        """Short label, e.g. '0:30:3' or '2,5,9'."""
        s = self.steps
        if len(s) == 1:
            return str(s[0])
        stride = s[1] - s[0]
        if all(b - a == stride for a, b in itertools.pairwise(s)):
            return f"{s[0]}:{s[-1] + 1}" + (f":{stride}" if stride != 1 else "")
        return ",".join(map(str, s))


def parse_selection(window: object, n_steps: int, times: Sequence | None = None) -> Selection:
    """Build a Selection from a string ('0:30', '0:30:2', '3,7,9'), slice, range or list of steps.

    A tuple of two or three numbers is refused: ``(0, 10)`` reads as the range 0..9 to a
    Python user and as the steps 0 and 10 to a list; the error names both spellings. A window
    of times ('2.0:20.0') is refused too, naming the steps whose `times` (the series' time
    labels, where given) lie in it.
    """
    if isinstance(window, Selection):
        if window.n_steps != n_steps:
            raise InvalidSelectionError(
                f"the selection was made for {window.n_steps} steps but the series has {n_steps}"
            )
        return window
    if window is None:
        return Selection.window(0, n_steps, 1, n_steps)
    if isinstance(window, slice):
        start = 0 if window.start is None else window.start
        stop = n_steps if window.stop is None else window.stop
        step = 1 if window.step is None else window.step
        return Selection.window(int(start), int(stop), int(step), n_steps)
    if isinstance(window, str):
        return _parse_string(window.strip(), n_steps, times)
    if isinstance(window, tuple) and len(window) in (2, 3):
        raise _ambiguous(window)
    if isinstance(window, Sequence):
        try:
            steps = tuple(int(s) for s in window)
        except (TypeError, ValueError):
            raise InvalidSelectionError(
                f"selection {window!r} must hold integer time steps"
            ) from None
        return Selection(steps, n_steps)
    raise InvalidSelectionError(
        f"cannot read a time selection from {window!r}; use 't0:t1[:stride]' or a list of steps"
    )


def _ambiguous(window: tuple) -> InvalidSelectionError:
    """The error for a 2- or 3-tuple window, naming both readings."""
    try:
        numbers = [int(v) for v in window]
    except (TypeError, ValueError):
        numbers = None
    if numbers is None:
        return InvalidSelectionError(
            f"cannot read a time selection from {window!r}; use 't0:t1[:stride]' or a list of steps"
        )
    as_range = ":".join(map(str, numbers))
    steps = " and ".join(map(str, numbers)) if len(numbers) == 2 else ", ".join(map(str, numbers))
    return InvalidSelectionError(
        f"window {tuple(numbers)} is ambiguous: for the range write '{as_range}' or "
        f"range({', '.join(map(str, numbers))}); for steps {steps} alone write {numbers}"
    )


def _parse_string(text: str, n_steps: int, times: Sequence | None = None) -> Selection:
    try:
        if ":" in text:
            parts = [p.strip() for p in text.split(":")]
            if len(parts) not in (2, 3):
                raise ValueError(text)
            t0 = int(parts[0]) if parts[0] else 0
            t1 = int(parts[1]) if parts[1] else n_steps
            stride = int(parts[2]) if len(parts) == 3 and parts[2] else 1
            steps = None
        else:
            steps = tuple(int(p) for p in text.split(","))
    except ValueError:
        raise _unreadable(text, n_steps, times) from None
    if steps is None:
        return Selection.window(t0, t1, stride, n_steps)
    return Selection(steps, n_steps)


def _unreadable(text: str, n_steps: int, times: Sequence | None) -> InvalidSelectionError:
    """The error for a window that is not one of steps; for one of two times ('2.0:20.0'), the
    steps whose times lie in it, where the series' `times` are numbers."""
    usage = "use 't0:t1[:stride]' (e.g. 0:30:3) or a comma list of steps (e.g. 2,5,9)"
    parts = text.split(":")
    try:
        lo, hi = (float(p) for p in parts)
        labels = [float(t) for t in times] if times is not None else None
    except (TypeError, ValueError):
        return InvalidSelectionError(f"cannot read time window {text!r}; {usage}")
    increasing = labels is not None and all(
        math.isfinite(a) and a < b for a, b in itertools.pairwise([*labels, math.inf])
    )
    if not increasing:  # no steps to name: labels missing, out of order or not finite
        return InvalidSelectionError(
            f"window {text!r} looks like times, but windows count steps (0 to {n_steps}); "
            "`chronocl info STORE` lists each step's time"
        )
    inside = [i for i, t in enumerate(labels) if lo <= t < hi]
    if not inside:
        return InvalidSelectionError(
            f"window {text!r} looks like times, but windows count steps, and no step's time "
            f"lies in [{lo:g}, {hi:g}) (the times run {labels[0]:g} to {labels[-1]:g})"
        )
    a, b = inside[0], inside[-1]
    return InvalidSelectionError(
        f"window {text!r} looks like times, but windows count steps: the times in "
        f"[{lo:g}, {hi:g}) are steps {a} to {b} ({labels[a]:g} to {labels[b]:g}): write "
        f"--window {a}:{b + 1}"
    )
