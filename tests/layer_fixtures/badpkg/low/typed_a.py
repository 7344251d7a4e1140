"""Type-only cycle, half one: typed_a imports typed_b at run time."""

from badpkg.low.typed_b import B


class A:
    def b(self) -> B:
        return B()
