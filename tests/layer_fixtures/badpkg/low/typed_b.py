"""Type-only cycle, half two: typed_b imports typed_a for annotations only; still a cycle."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from badpkg.low.typed_a import A


class B:
    def maker(self) -> A | None:
        return None
