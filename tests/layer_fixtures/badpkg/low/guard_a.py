"""`if not TYPE_CHECKING:` runs: its import of guard_b makes a runtime cycle with guard_b. Its
`else:` is read by type checkers alone."""

import typing
from typing import TYPE_CHECKING

if not TYPE_CHECKING:
    from badpkg.low import guard_b
else:
    from badpkg.low import typed_b as guard_b

if not typing.TYPE_CHECKING:
    from badpkg.low.typed_b import B
else:
    from badpkg.low.typed_a import A as B


def name() -> str:
    return guard_b.__name__ + B.__name__
