"""Runtime cycle, half one: ring_a imports ring_b at the top."""

from badpkg.low import ring_b


def a() -> str:
    return ring_b.b()
