"""What every session of a series is built from, whatever its level: the keywords a `Session`
(and each of its level sessions) takes, resolved once (`settings`).
"""

from __future__ import annotations

from typing import NamedTuple

from chronocl.core.budget import interactive_memory, parse_memory
from chronocl.data.window import WindowManager
from chronocl.engine import get_engine
from chronocl.engine.base import Engine
from chronocl.integration.inmemory import make_spec
from chronocl.integration.interactive.costs import SlideCosts
from chronocl.modes.spec import IntegrationSpec

Managers = dict[tuple[int, str], WindowManager]


class Settings(NamedTuple):
    """What every session of a series is built from, whatever its level (`settings`)."""

    asked: IntegrationSpec  # the spec as asked, its value range not fixed yet
    engine: Engine
    budget: int  # bytes
    prefetch: int | None
    managers: Managers | None
    display: bool = False  # frames in the display format where the engine writes it
    slide_costs: SlideCosts | None = None  # slide only where measured cheaper (None: always)


def settings(
    *,
    memory: str | int | None = None,
    engine: str | Engine = "opencl",
    device: str | None = None,
    spec: IntegrationSpec | None = None,
    prefetch: int | None = None,
    managers: Managers | None = None,
    display: bool = False,
    slide_costs: SlideCosts | None = None,
    **spec_args: object,
) -> Settings:
    """The keywords a `Session` takes at any level (`Session`'s docstring says what each is)."""
    asked = spec if spec is not None else make_spec(**spec_args)  # type: ignore[arg-type]
    eng = get_engine(engine, device) if isinstance(engine, str) else engine
    budget = interactive_memory() if memory is None else parse_memory(memory)
    return Settings(asked, eng, budget, prefetch, managers, display, slide_costs)


def manager_key(level: int, pool: str) -> tuple[int, str]:
    """The key of a level's window manager among shared `managers`: level 0 is one series
    whatever the pooling (a mode pooling by max must not read the window again)."""
    return (level, pool if level else "")
