"""Memory budgets: '2GB', '512MiB' or a byte count, parsed once at the edge."""

from __future__ import annotations

from dask.utils import format_bytes, parse_bytes

from .errors import InvalidParameterError

DEFAULT_MEMORY = "2GB"


def parse_memory(value: str | int | float | None, default: str = DEFAULT_MEMORY) -> int:
    """A byte budget from '2GB', '512MiB', '1e9' or an int; it must be positive."""
    if value is None:
        value = default
    try:
        n = int(value) if isinstance(value, int | float) else int(parse_bytes(str(value)))
    except (ValueError, TypeError):
        raise InvalidParameterError(
            f"memory budget {value!r} is not a size; write it like 512MB, 2GB or 1.5GiB"
        ) from None
    if n <= 0:
        raise InvalidParameterError(f"memory budget {value!r} must be positive, e.g. 2GB")
    return n


def human(n: float) -> str:
    """Bytes for people: '1.50 GiB'."""
    return format_bytes(int(n))
