"""The private names the next two modules borrow and reach into; its own reaches are fine."""

from __future__ import annotations

from typing import NamedTuple


def _secret() -> int:
    return 42


class Owner:
    __slots__ = ("_slot",)

    def __init__(self) -> None:
        self._slot = _secret()

    def same(self, other: Owner) -> bool:
        return self._slot == other._slot  # another Owner: this module's own private name


class Base:
    def __init__(self) -> None:
        self._hidden = 1

    def _step(self) -> int:
        return self._hidden


class Point(NamedTuple):
    x: int
