"""Attribute reaches into another module's private names (lines 11, 12, 16), beside the forms
that are fine: `self`, `cls`, `super()`, `type(self)`, this module's own class and names,
dunders, namedtuple's API."""

from badpkg.low import owner
from badpkg.low.owner import Base, Point


def reach(thing: owner.Owner) -> int:
    """Both reaches count: the module's `_secret` and the object's `_slot`."""
    value = owner._secret()
    return value + thing._slot


def write(thing: Base) -> None:
    thing._hidden = 2


class Child(Base):
    _count = 0

    def step(self) -> int:
        type(self)._count += 1
        return super()._step() + self._hidden + Child._count + self._own()

    def _own(self) -> int:
        return len(self.__class__.__name__)

    def twin(self, other: "Child") -> int:
        return other._own() + Point(1)._replace(x=2).x
