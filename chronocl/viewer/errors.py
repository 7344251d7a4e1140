"""What a viewer client and the log are told of an error: a ChronoclError's own line, else
one line naming what failed (the exception's type and the first line of its message, and
where: the views' modes, windows and data sizes), with the traceback in the server's log, so
that an internal error can be found from the log alone (issue 45)."""

from __future__ import annotations

import logging

from chronocl.core.errors import ChronoclError
from chronocl.viewer.protocol import LIMITS

log = logging.getLogger("chronocl.viewer")


def internal_error(exc: BaseException, where: str) -> str:
    """One line for an unexpected error, for the client and the log: the exception's type and
    the first line of its message."""
    lines = str(exc).strip().splitlines()
    said = f": {lines[0][: LIMITS.error_chars]}" if lines else ""
    return (
        f"internal error ({type(exc).__name__}{said}) {where}; the server keeps serving "
        "(please report it with the server's log)"
    )


def error_text(exc: BaseException, where: str) -> str:
    """What a client is told of an error: a ChronoclError's own line, else `internal_error`
    (then logged, with its traceback)."""
    if isinstance(exc, ChronoclError):
        return str(exc)
    text = internal_error(exc, where)
    log.error("chronocl viewer: %s", text, exc_info=exc)
    return text
