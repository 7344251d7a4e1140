"""`chronocl pyramid`: add coarse levels (mean, max, min) to an existing series store."""

from __future__ import annotations

from typing import Annotated

import typer

from chronocl.cli.options import StorageOpt, err, print_summary, series_store


def pyramid(
    store: Annotated[str, typer.Argument(help="A chronocl series store: a path or an s3:// URL.")],
    force: Annotated[
        bool, typer.Option("--force", help="Rebuild the levels when the store has them.")
    ] = False,
    storage_option: StorageOpt = None,
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

      chronocl pyramid s3://bucket/jet.zarr

    An s3:// store gets its levels built locally and uploaded, levels/zarr.json last: until
    then readers find no levels and pool them on the fly.
    """
    import time

    from chronocl.data.level_writer import add_levels
    from chronocl.data.remote import add_remote_levels, is_url
    from chronocl.data.remote_write import split_url

    store, options = series_store(store, False, storage_option)
    if is_url(store):
        split_url(store)  # s3:// only: HTTP servers take no writes
    t0 = time.perf_counter()
    if is_url(store):
        summary = add_remote_levels(store, options, progress=True, force=force)
    else:
        summary = add_levels(store, progress=True, force=force)
    if summary["status"] in ("added", "rebuilt"):
        err.print(f"{summary['status']} levels of {store} in {time.perf_counter() - t0:.1f} s")
    print_summary(summary)
