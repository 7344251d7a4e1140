"""`from x import _name`: a private name taken from another module."""

from badpkg.low.owner import _secret


def borrow() -> int:
    return _secret()
