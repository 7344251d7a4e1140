"""What a viewer client and the log are told of an error: a ChronoclError's own line, else
one line naming the exception's type (never its text, which may hold paths, nor a traceback;
the traceback goes to the debug log only)."""

from __future__ import annotations

import logging

from chronocl.core.errors import ChronoclError

log = logging.getLogger("chronocl.viewer")


def internal_error(exc: BaseException, where: str) -> str:
    """One line for an unexpected error, for the client and the log: the exception's type,
    never its text (which may hold paths) nor a traceback."""
    return (
        f"internal error ({type(exc).__name__}) {where}; the server keeps serving "
        "(please report it)"
    )


def error_text(exc: BaseException, where: str) -> str:
    """What a client is told of an error: a ChronoclError's own line, else `internal_error`
    (then logged in one line, the traceback at debug level only)."""
    if isinstance(exc, ChronoclError):
        return str(exc)
    text = internal_error(exc, where)
    log.error("chronocl viewer: %s", text)
    log.debug("chronocl viewer: %s", where, exc_info=exc)
    return text
