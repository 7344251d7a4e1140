"""Vector magnitudes and multi-variable stores, built from readers' unwritten steps.

`magnitude_steps` turns the steps of two or three components (NetCDF variables, or raw / npy /
TIFF inputs of the same shape) into the steps of their magnitude sqrt(u² + v² + w²), computed
in float32 one step at a time. `write_variables` writes several variables into one store: the
first is the store itself (so every tool that opens the store sees it, exactly as a
one-variable store), each other one a complete store of its own under ``variables/<name>/``
with its own statistics and levels; the whole store appears at once when complete.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator, Sequence

import numpy as np

from chronocl.core.atomic import atomic_directory
from chronocl.core.errors import InvalidDataError, InvalidParameterError
from chronocl.data.steps import Steps
from chronocl.data.timeseries import TimeSeries, open_store
from chronocl.data.writer import VARIABLES, write_store

_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*")


def split_names(value: str | Sequence[str], flag: str, counts: Sequence[int] = ()) -> list[str]:
    """Names given as 'a,b,c' or a list, each once (and as many as one of `counts`)."""
    items = value.split(",") if isinstance(value, str) else [str(v) for v in value]
    names = [n.strip() for n in items if n.strip()]
    if counts and len(names) not in counts:
        want = " or ".join(str(c) for c in counts)
        raise InvalidParameterError(
            f"{flag} takes {want} comma-separated names (e.g. {flag} u,v,w); got {len(names)}"
        )
    twice = [n for n in names if names.count(n) > 1]
    if twice:
        raise InvalidParameterError(f"{flag} names {twice[0]} twice; name each once")
    return names


def magnitude_steps(parts: Sequence[Steps], names: Sequence[str], where: str = "") -> Steps:
    """The steps of the magnitude of the components `parts` (named `names`, found in `where`),
    float32.

    Every component must have the same number of steps, volume shape and spacing; that is
    checked here, before anything is read.
    """
    first = parts[0]
    for name, part in zip(names[1:], parts[1:], strict=True):
        for what in ("n_steps", "volume_shape", "spacing"):
            a, b = getattr(first, what), getattr(part, what)
            if tuple(np.atleast_1d(a)) != tuple(np.atleast_1d(b)):
                label = what.replace("_", " ").replace("n steps", "steps")
                raise InvalidDataError(
                    f"components {names[0]} and {name} differ in {label} ({a} and {b}); "
                    "the components of a magnitude must have the same shape"
                )

    def read() -> Iterator[np.ndarray]:
        out = np.empty(first.volume_shape, np.float32)
        square = np.empty_like(out)
        for steps in zip(*(p.read() for p in parts), strict=True):
            out[...] = 0
            for step in steps:
                value = np.asarray(step).astype(np.float32, copy=False)
                np.multiply(value, value, out=square)
                out += square
            yield np.sqrt(out)

    return Steps(
        read,
        n_steps=first.n_steps,
        volume_shape=tuple(first.volume_shape),
        dtype=np.dtype(np.float32),
        spacing=first.spacing,
        source=f"magnitude of {', '.join(names)}" + (f" in {where}" if where else ""),
        times=first.times,
        labels=first.labels,
        attrs={**first.attrs, "variable": None, "quantity": "magnitude", "components": names},
    )


def write_variables(
    out: str | os.PathLike,
    parts: Sequence[tuple[str, Steps]],
    *,
    overwrite: bool = False,
    progress: bool = False,
    nan_fill: float | None = None,
) -> TimeSeries:
    """Write each (name, steps) of `parts` as a variable of one new store at `out`; returns
    the store opened at its first variable."""
    names = [name for name, _ in parts]
    for name in names:
        if not _NAME.fullmatch(name):
            raise InvalidParameterError(
                f"variable name {name!r} cannot name a folder of the store; rename it in the "
                "file first (letters, digits, _ . + -)"
            )
    with atomic_directory(out, overwrite) as tmp:
        for i, (name, steps) in enumerate(parts):
            target = tmp / VARIABLES / name if i else tmp
            target.parent.mkdir(parents=True, exist_ok=True)
            written = steps.written()
            written["attrs"] = {**written["attrs"], "variable": name, "variables": names}
            write_store(target, steps.read(), **written, progress=progress, nan_fill=nan_fill)
    return open_store(out)
