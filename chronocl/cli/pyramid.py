"""`chronocl pyramid`: add coarse levels (mean, max, min) to an existing series store."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import STORE_HINT, err, print_summary


def pyramid(
    store: Annotated[Path, typer.Argument(help="A chronocl series store.")],
    force: Annotated[
        bool, typer.Option("--force", help="Rebuild the levels when the store has them.")
    ] = False,
) -> None:
    """Add coarse levels to a series store, for drawing a coarse level first.

    Level n halves level n-1 along every axis (2x2x2 blocks pooled by mean, max and min)
    while the largest axis is over 64: 256^3 gets 128^3 and 64^3. The data and the store's
    attributes are only read; the levels are built aside and appear whole, so an
    interrupted build leaves none (run it again). Stores written by 'chronocl ingest' and
    'chronocl generate' have their levels already.

    Examples:

      chronocl pyramid jet.zarr

      chronocl pyramid jet.zarr --force
    """
    import time

    from chronocl.core.paths import check_input
    from chronocl.data.level_writer import add_levels

    check_input(store, "store", hint=STORE_HINT)
    t0 = time.perf_counter()
    summary = add_levels(store, progress=True, force=force)
    if summary["status"] in ("added", "rebuilt"):
        err.print(f"{summary['status']} levels of {store} in {time.perf_counter() - t0:.1f} s")
    print_summary(summary)
