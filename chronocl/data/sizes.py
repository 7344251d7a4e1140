"""Sizes for people, as `TimeSeries.describe` (`chronocl info`) shows them: '1.5 MB'."""

from __future__ import annotations

from pathlib import Path


def disk_usage(path: Path) -> int:
    """Bytes of the files under `path`."""
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def human_size(n: float) -> str:
    """`n` bytes in B, KB, MB, GB or TB (powers of 1024), one decimal above bytes."""
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if n < 1024 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"
