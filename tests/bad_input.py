"""What every bad-input case checks: one clear line, exit 2, input untouched, nothing left."""

from __future__ import annotations

import hashlib
from pathlib import Path

from .test_cli import assert_one_line_error, cli


def digest(path: Path) -> dict[str, str]:
    """sha256 of every file under `path` (or of the file itself), by relative path."""
    path = Path(path)
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    return {
        str(f.relative_to(path.parent)): hashlib.sha256(f.read_bytes()).hexdigest() for f in files
    }


def partials(folder: Path) -> list[str]:
    """Hidden partial outputs (.NAME.partial-*) anywhere under `folder`."""
    return sorted(str(p) for p in Path(folder).rglob(".*partial*"))


def assert_rejected(args, needle: str, inputs, outputs=(), folder: Path | None = None) -> None:
    """Run the CLI with `args` and check it refuses them cleanly.

    Exit code 2, one line on stderr holding `needle`, no traceback, every input byte-identical,
    no output written and no hidden partial left in `folder`.
    """
    before = {str(p): digest(p) for p in inputs}
    result = cli(*args)
    assert_one_line_error(result, needle)
    for p in inputs:
        assert digest(p) == before[str(p)], f"input {p} changed"
    for p in outputs:
        assert not Path(p).exists(), f"output {p} was written"
    if folder is not None:
        assert partials(folder) == []
