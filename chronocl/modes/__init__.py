"""Integration modes: one module per way of integrating a window through time, and their registry.

Every part of chronocl that depends on the mode (the numpy reference, both engines, sliding
sessions, streaming, the CLI help, the viewer's mode list) asks this registry; adding a mode
is one module here, one kernel file in kernels/opencl/ and a line in `_MODES` below
(docs/architecture.md, "How to add a mode").
"""

from __future__ import annotations

from chronocl.core.errors import UnknownNameError
from chronocl.modes import additive, alpha, change, count, extreme, first_hit, mean
from chronocl.modes.base import Mode

_MODES: tuple[Mode, ...] = (
    alpha.MODE,
    first_hit.MODE,
    additive.MODE,
    extreme.MAX,
    extreme.MIN,
    mean.MODE,
    change.MODE,
    count.MODE,
)
REGISTRY: dict[str, Mode] = {m.name: m for m in _MODES}
DEFAULT = alpha.MODE.name  # the mode used when none is named

__all__ = ["DEFAULT", "REGISTRY", "Mode", "get", "names"]


def names() -> tuple[str, ...]:
    """The registered modes' names, in the order they are listed to users."""
    return tuple(REGISTRY)


def get(name: str) -> Mode:
    """The mode called `name`; UnknownNameError (a KeyError) naming the choices otherwise."""
    try:
        return REGISTRY[name]
    except (KeyError, TypeError):
        raise UnknownNameError(
            f"unknown mode {name!r}; choose one of {', '.join(REGISTRY)}"
        ) from None
