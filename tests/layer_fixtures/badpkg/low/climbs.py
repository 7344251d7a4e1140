"""Upward import: a low module imports a high one."""

from badpkg.high.top import above


def climb() -> str:
    return above()
