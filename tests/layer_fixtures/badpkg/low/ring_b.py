"""Runtime cycle, half two: ring_b imports ring_a inside a function (that import counts too)."""


def b() -> str:
    from badpkg.low import ring_a

    return ring_a.__name__
