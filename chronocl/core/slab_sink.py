"""Slabs of a chronovolume handed on as soon as they are finished.

The viewer's refine writes each finished z-slab of a display chronovolume into its texture
while the next slab integrates (`chronocl.viewer.slab_upload`), instead of writing the whole
volume after the integration. `chronocl.integration.inmemory.integrate_bricks` calls `finished`
after each slab it writes in its final form; outside `slabs_to` nobody listens, so the command
line and the library run as before.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

Sink = Callable[[np.ndarray, int, int], None]  # (the whole output, z0, z1): rows z0..z1 done

_sink: ContextVar[Sink | None] = ContextVar("chronocl_slab_sink", default=None)


@contextmanager
def slabs_to(sink: Sink) -> Iterator[None]:
    """Within: `sink(rgba, z0, z1)` hears each z-slab of a display chronovolume once its rows
    of `rgba` are final (they are not written again)."""
    token = _sink.set(sink)
    try:
        yield
    finally:
        _sink.reset(token)


def listening() -> bool:
    return _sink.get() is not None


def finished(rgba: np.ndarray, z0: int, z1: int) -> None:
    """Rows z0..z1 of `rgba` are final."""
    sink = _sink.get()
    if sink is not None:
        sink(rgba, z0, z1)
