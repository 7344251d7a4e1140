"""Write a directory store atomically: build it at a temporary sibling, rename when complete.

A failed or interrupted write leaves at most a hidden ``.NAME.partial-*``
folder next to the target, never something that opens as a valid store.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

from .errors import OutputExistsError


def check_output(path: str | os.PathLike, overwrite: bool) -> Path:
    """Return `path` as a Path; raise if it exists and `overwrite` is false."""
    from .paths import check_writable

    check_writable(path)  # its folder must take new files: probed before any work
    target = Path(path)
    if target.exists() and not overwrite:
        raise OutputExistsError(
            f"output {str(target)!r} already exists; "
            "pass --overwrite (overwrite=True) to replace it"
        )
    return target


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling directory that replaces `path` when the block succeeds."""
    target = check_output(path, overwrite)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.parent / f".{target.name}.partial-{uuid.uuid4().hex[:8]}"
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    commit_directory(tmp, target)


def commit_directory(tmp: Path, target: Path) -> None:
    """Move the finished directory `tmp` to `target`, replacing whatever is there."""
    if target.exists():
        # Directories cannot be replaced in one rename: move the old one aside first.
        old = target.parent / f".{target.name}.old-{uuid.uuid4().hex[:8]}"
        os.replace(target, old)
        os.replace(tmp, target)
        if old.is_dir():
            shutil.rmtree(old, ignore_errors=True)
        else:
            old.unlink(missing_ok=True)
    else:
        os.replace(tmp, target)


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling file path that replaces `path` when the block succeeds."""
    target = check_output(path, overwrite)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.parent / f".{target.name}.partial-{uuid.uuid4().hex[:8]}{target.suffix}"
    try:
        yield tmp
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, target)
