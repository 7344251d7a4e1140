"""Progress bars (rich) on stderr for anything that may take more than a second."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

T = TypeVar("T")


def _bar() -> Progress:
    """A bar on stderr with count, a `rate` field, elapsed and remaining time."""
    columns = (
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    return Progress(*columns, console=Console(stderr=True), transient=False)


def track(items: Iterable[T], total: int, description: str, enabled: bool) -> Iterator[T]:
    """Yield `items`, showing a bar with count, rate and time left when `enabled`."""
    if not enabled:
        yield from items
        return
    with _bar() as bar, _erased_on_error(bar):
        task = bar.add_task(description, total=total, rate="")
        for item in items:
            yield item
            speed = bar.tasks[0].speed
            bar.update(task, advance=1, rate=f"{speed:.1f}/s" if speed else "")


@contextlib.contextmanager
def _erased_on_error(bar: Progress) -> Iterator[None]:
    """Leave no bar behind when the work fails, so the error is the only line shown."""
    try:
        yield
    except BaseException:
        bar.live.transient = True
        bar.console.quiet = True  # the bar's own console: nothing more is drawn on stop
        raise


@contextlib.contextmanager
def meter(
    total: int, description: str, enabled: bool, done: int = 0, unit: str = "slabs"
) -> Iterator[Callable[[int], None]]:
    """Yield `advance(nbytes)`: one call per finished item, showing items/s and MB/s of data.

    `done` items were finished before (a resumed run); rates count only this run's items.
    """
    if not enabled:
        yield lambda nbytes=0: None
        return
    start, count, moved = time.perf_counter(), 0, 0

    with _bar() as bar, _erased_on_error(bar):
        task = bar.add_task(description, total=total, completed=done, rate="")

        def advance(nbytes: int = 0) -> None:
            nonlocal count, moved
            count += 1
            moved += nbytes
            dt = max(time.perf_counter() - start, 1e-9)
            rate = f"{count / dt:.2f} {unit}/s, {moved / dt / 1e6:.0f} MB/s"
            bar.update(task, advance=1, rate=rate)

        yield advance
