"""`chronocl verify`: read a whole store back and report the first damage, if any."""

from __future__ import annotations

from typing import Annotated

import typer

from chronocl.cli.options import AnonOpt, StorageOpt, print_summary, series_store


def verify(
    store: Annotated[
        str,
        typer.Argument(
            help="A chronocl series or chronovolume store: a path, or an http(s):// or s3:// URL."
        ),
    ],
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
) -> None:
    """Read a whole store back: every chunk must decode and every step match its statistics.

    Exits 0 when the store is sound, 2 with one line naming the first damage otherwise.

    Examples:

      chronocl verify vortex.zarr

      chronocl verify s3://bucket/vortex.zarr
    """
    from chronocl.data.verify import verify as run_verify

    store, storage_options = series_store(store, anon, storage_option)
    print_summary(run_verify(store, progress=True, storage_options=storage_options))
