"""How a session's window and spec move.

`Session.set_window`, `slide` and `set_spec` turn a move into the window (`jump`, `slid`) or
spec (`changed`) to show and call `Session.show`, which takes the spec to integrate from
`fixed`: its value range fitted to the first window shown and to the window of each spec
change, then kept, so every window of a slide uses the same range (a `LevelSession` takes the
spec so fixed as it is).

These are functions, not methods, so that a reader (or a tool) following a move sees each
call it makes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from chronocl.core.selection import Selection, parse_selection
from chronocl.data.series import TimeSeries
from chronocl.integration.inmemory import fix_range
from chronocl.modes.spec import IntegrationSpec

Window = int | str | Selection | Sequence[int]


def jump(t0: Window, t1: int | None, stride: int, n_steps: int) -> Selection:
    """The window [t0, t1) with a stride (or a '0:16:2' string, list or Selection) of a series
    of `n_steps`; InvalidSelectionError for steps outside it."""
    window = t0 if t1 is None else slice(int(t0), int(t1), int(stride))  # type: ignore[arg-type]
    return parse_selection(window, n_steps)


def slid(window: Selection, k: int, n_steps: int) -> Selection:
    """`window` moved by k strides (negative: back in time), clamped at either end of a series
    of `n_steps` (it keeps its width)."""
    steps = window.steps
    shift = int(k) * window.stride
    shift = max(-steps[0], min(shift, n_steps - 1 - steps[-1]))
    return Selection(tuple(s + shift for s in steps), window.n_steps)


def changed(
    asked: IntegrationSpec, spec: IntegrationSpec | None, changes: dict[str, object]
) -> IntegrationSpec:
    """The spec a change asks for: a whole `spec`, or fields of the one `asked` (mode="max")."""
    return spec if spec is not None else dataclasses.replace(asked, **changes)  # type: ignore[arg-type]


def fixed(
    base: TimeSeries,
    asked: IntegrationSpec,
    current: IntegrationSpec,
    spec: IntegrationSpec | None,
    selection: Selection,
) -> tuple[IntegrationSpec, IntegrationSpec]:
    """The spec asked and the spec to show `selection` of `base` under, its value range fixed,
    for a session that was `asked` and integrates `current` (`asked` itself until a window is
    shown) when `spec` (None: the current one) is asked now."""
    if spec is None or spec in (asked, current):
        if current is asked:  # nothing shown yet: fix the range for this window
            return asked, fix_range(base, asked, selection)
        return asked, current
    # A new spec: its range (when fitted) is fitted to this window.
    return spec, fix_range(base, spec, selection)
