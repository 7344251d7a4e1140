"""The other half of guard_a's runtime cycle."""

from badpkg.low import guard_a


def name() -> str:
    return guard_a.__name__
