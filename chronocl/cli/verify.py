"""`chronocl verify`: read a whole store back and report the first damage, if any."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import STORE_HINT, print_summary


def verify(
    store: Annotated[Path, typer.Argument(help="A chronocl series or chronovolume store.")],
) -> None:
    """Read a whole store back: every chunk must decode and every step match its statistics.

    Exits 0 when the store is sound, 2 with one line naming the first damage otherwise.

    Example: chronocl verify vortex.zarr
    """
    from chronocl.core.paths import check_input
    from chronocl.data.verify import verify as run_verify

    check_input(store, "store", hint=STORE_HINT)
    print_summary(run_verify(store, progress=True))
