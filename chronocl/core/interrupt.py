"""Work that is given up when newer input comes, and says how far it got.

The viewer refines a picture to full resolution while the user may act again at any moment.
It runs the refine inside `interruptible(check, progress)`; the long loops under it (the
slabs of an integration, the steps a window waits for) call `checkpoint` between their
pieces, which raises `SupersededError` as soon as `check()` says the work is no longer
wanted and tells `progress` how far it got. Work that is only told of (`reported`: a frame
answering input, which the page waits for) hears the same checkpoints and is never given up, nor
split into pieces for it. Outside both a checkpoint does nothing, so the command line and the
library run as before.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

from chronocl.core.errors import SupersededError

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class _Watch:
    check: Callable[[], bool] | None  # None: reported, never given up
    progress: Progress | None


_current: ContextVar[_Watch | None] = ContextVar("chronocl_interrupt", default=None)


@contextmanager
def interruptible(
    check: Callable[[], bool] | None, progress: Progress | None = None
) -> Iterator[None]:
    """Give the work inside up (SupersededError at its next checkpoint) once `check()` is
    true (None: never); `progress(stage, done, total)` hears each checkpoint."""
    token = _current.set(_Watch(check, progress))
    try:
        yield
    finally:
        _current.reset(token)


def reported(progress: Progress) -> AbstractContextManager[None]:
    """`progress(stage, done, total)` hears each checkpoint of the work inside, which is never
    given up (not `watched`)."""
    return interruptible(None, progress)


def checkpoint(stage: str, done: int, total: int) -> None:
    """Between two pieces of long work: `done` of `total` pieces of `stage` are done."""
    watch = _current.get()
    if watch is None:
        return
    if watch.check is not None and watch.check():
        raise SupersededError(f"{stage} given up at {done} of {total}: newer input came")
    if watch.progress is not None:
        watch.progress(stage, done, total)


def watched() -> bool:
    """Whether the work running now can be given up (it runs inside `interruptible`): then it
    goes in pieces, each a checkpoint."""
    watch = _current.get()
    return watch is not None and watch.check is not None


def heard() -> bool:
    """Whether a checkpoint now is heard at all (inside `interruptible` or `reported`)."""
    return _current.get() is not None
