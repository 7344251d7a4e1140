"""Paths checked before any work starts: outputs that can be written and never touch an input,
inputs that are what they claim to be.

- `check_writable`: the output's nearest existing folder must take a new file. It is probed by
  creating and removing a temporary file, since ``os.access`` answers yes to root even on
  read-only places.
- `check_apart`: an output must not be an input, lie inside one, or be a folder that holds
  one (replacing it would delete the input), nor hold the working folder. Real paths are
  compared, with symlinks resolved.
- `check_input`: tells a missing path from a broken symlink, a symlink loop, an unreadable
  path, or a folder where a file is wanted.
- `check_target`: all of the output checks at once, as the commands call them.

Every failure is one line naming the path, the problem and the fix.
"""

from __future__ import annotations

import errno
import glob
import os
import stat
import tempfile
from collections.abc import Iterable
from pathlib import Path

from chronocl.core.errors import (
    InputNotFoundError,
    InvalidParameterError,
    OutputExistsError,
    OutputIsInputError,
    OutputNotWritableError,
)

GLOB_CHARS = set("*?[")  # a path holding one is a pattern
PathLike = str | os.PathLike


def _nearest_existing(path: Path) -> Path:
    """`path` or its closest ancestor that exists (a dangling symlink counts as existing)."""
    while not os.path.lexists(path) and path.parent != path:
        path = path.parent
    return path


def check_writable(path: PathLike) -> None:
    """Raise OutputNotWritableError unless a file can be created where `path` will be written.

    The output is written to a temporary sibling and renamed, so the folder that must take
    new files is `path`'s parent, or the nearest ancestor that exists when the parent is to
    be created.
    """
    target = Path(os.path.abspath(os.fspath(path)))
    folder = _nearest_existing(target.parent)
    if not folder.is_dir():
        what = "a broken symlink" if folder.is_symlink() and not folder.exists() else "a file"
        raise OutputNotWritableError(
            f"cannot write {os.fspath(path)!r}: {str(folder)!r} is {what}, not a folder; "
            "choose an output path in a folder"
        )
    try:
        fd, probe = tempfile.mkstemp(prefix=".chronocl-probe-", dir=folder)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise OutputNotWritableError(
            f"cannot write {os.fspath(path)!r}: folder {str(folder)!r} does not take new files "
            f"({reason}); choose an output location you can write"
        ) from None
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:  # pragma: no cover - a folder that takes files but not their removal
        pass


def _real(path: PathLike) -> Path:
    return Path(os.path.realpath(os.fspath(path)))


def _expand(item: PathLike) -> list[str]:
    """A path, or the files a glob matches (the pattern itself when it matches nothing)."""
    text = os.fspath(item)
    if GLOB_CHARS & set(text):
        return sorted(glob.glob(text)) or [text]
    return [text]


def check_apart(output: PathLike, inputs: Iterable[PathLike | None] = ()) -> None:
    """Raise OutputIsInputError if `output` is, lies inside, or holds one of `inputs` (globs
    expanded; None skipped), or holds the working folder. Symlinks are resolved first."""
    if isinstance(inputs, str | os.PathLike):  # one path, not a sequence of characters
        inputs = [inputs]
    out = _real(output)
    shown = os.fspath(output)
    for item in inputs:
        if item is None:
            continue
        for source in _expand(item):
            src = _real(source)
            if out == src:
                raise OutputIsInputError(
                    f"output {shown!r} is the input {source!r}; writing it would destroy the "
                    "input, so choose another output path"
                )
            if out.is_relative_to(src):
                raise OutputIsInputError(
                    f"output {shown!r} lies inside the input {source!r}; writing it would "
                    "change the input, so choose an output path outside it"
                )
            if src.is_relative_to(out):
                raise OutputIsInputError(
                    f"output {shown!r} contains the input {source!r}; replacing it would "
                    "delete the input, so choose another output path"
                )
    try:
        cwd = _real(os.getcwd())
    except OSError:  # the working folder was deleted: nothing to protect
        return
    if cwd.is_relative_to(out):
        raise OutputIsInputError(
            f"output {shown!r} contains the current folder; replacing it would delete the "
            "folder you are working in, so choose another output path"
        )


def check_input(path: PathLike, what: str, *, want: str | None = None, hint: str = "") -> Path:
    """Return `path` as a Path if it exists (and is a file or folder, as `want` says);
    else raise one line saying what it really is: missing, a broken symlink, a symlink
    loop, unreadable, a folder or not a regular file. `hint` is the fix for a missing path."""
    p = Path(path)
    shown = os.fspath(path)
    try:
        st = os.stat(p)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InputNotFoundError(
                f"{what} {shown!r} is a symlink loop (its links point back to each other); "
                "point the link at a real file"
            ) from None
        if os.path.islink(p):
            raise InputNotFoundError(
                f"{what} {shown!r} is a broken symlink to {os.readlink(p)!r}; "
                "fix the link or give the target itself"
            ) from None
        if exc.errno == errno.ENOTDIR:
            raise InputNotFoundError(
                f"{what} {shown!r} does not exist: a part of the path is a file, not a folder"
            ) from None
        if exc.errno in (errno.EACCES, errno.EPERM):
            raise InputNotFoundError(
                f"{what} {shown!r} cannot be read (permission denied); check its permissions"
            ) from None
        raise InputNotFoundError(
            f"{what} {shown!r} does not exist; {hint or 'check the path'}"
        ) from None
    if want == "file":
        if stat.S_ISDIR(st.st_mode):
            raise InvalidParameterError(
                f"{what} {shown!r} is a folder, not a file; give the file itself"
            )
        if not stat.S_ISREG(st.st_mode):
            raise InvalidParameterError(
                f"{what} {shown!r} is not a regular file (a device, pipe or socket); give a file"
            )
    elif want == "dir" and not stat.S_ISDIR(st.st_mode):
        raise InvalidParameterError(f"{what} {shown!r} is a file, not a folder; give a folder")
    return p


def check_output(path: str | os.PathLike, overwrite: bool) -> Path:
    """Return `path` as a Path; raise if it exists and `overwrite` is false."""
    check_writable(path)  # its folder must take new files: probed before any work
    target = Path(path)
    if os.path.lexists(target) and not overwrite:  # (a link to nothing is there too)
        raise OutputExistsError(
            f"output {str(target)!r} already exists; "
            "pass --overwrite (overwrite=True) to replace it"
        )
    return target


def check_target(path: PathLike, overwrite: bool, inputs: Iterable[PathLike | None] = ()) -> Path:
    """Every check of an output before the work: apart from `inputs` (and the working
    folder), not existing unless `overwrite`, and in a folder that can be written."""
    check_apart(path, inputs)
    return check_output(path, overwrite)  # which also probes the folder (check_writable)


def check_distinct(paths: Iterable[PathLike | None]) -> None:
    """Raise if two of the outputs `paths` (None skipped) are the same file."""
    seen: dict[Path, str] = {}
    for p in paths:
        if p is None:
            continue
        real = _real(p)
        if real in seen:
            raise InvalidParameterError(
                f"outputs {seen[real]!r} and {os.fspath(p)!r} are the same path; "
                "give each output its own name"
            )
        seen[real] = os.fspath(p)
