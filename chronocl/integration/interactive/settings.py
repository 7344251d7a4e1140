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
from chronocl.integration.interactive.costs import Costs
from chronocl.modes.spec import IntegrationSpec

Managers = dict[tuple[int, str], WindowManager]


class Settings(NamedTuple):
    """What every session of a series is built from, whatever its level (`settings`)."""

    asked: IntegrationSpec  # the spec as asked, its value range not fixed yet
    engine: Engine
    budget: int  # bytes
    prefetch: int | None
    managers: Managers | None
    # The rates measured, which every level records into (the caller's `slide_costs`, shared;
    # else the session's own), and whether a window slides only where they predict it cheaper
    # than integrating (given `slide_costs`: a viewer's sessions) or wherever it can.
    costs: Costs
    display: bool = False  # frames in the display format where the engine writes it
    weighs_slides: bool = False


def settings(
    *,
    memory: str | int | None = None,
    engine: str | Engine = "opencl",
    device: str | None = None,
    spec: IntegrationSpec | None = None,
    prefetch: int | None = None,
    managers: Managers | None = None,
    display: bool = False,
    slide_costs: Costs | None = None,
    **spec_args: object,
) -> Settings:
    """The keywords a `Session` takes at any level (`Session`'s docstring says what each is)."""
    asked = spec if spec is not None else make_spec(**spec_args)  # type: ignore[arg-type]
    eng = get_engine(engine, device) if isinstance(engine, str) else engine
    budget = interactive_memory() if memory is None else parse_memory(memory)
    costs = Costs() if slide_costs is None else slide_costs
    weighs = slide_costs is not None
    return Settings(asked, eng, budget, prefetch, managers, costs, display, weighs)


def manager_key(level: int, pool: str) -> tuple[int, str]:
    """The key of a level's window manager among shared `managers`: level 0 is one series
    whatever the pooling (a mode pooling by max must not read the window again)."""
    return (level, pool if level else "")
