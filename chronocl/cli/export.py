"""`chronocl export`: write time steps of a series as .vti files with a .pvd, a .npy, or raw."""

from __future__ import annotations

from typing import Annotated

import typer

from chronocl.cli.options import AnonOpt, StorageOpt, StoreArg, WindowOpt, err, series_store


def export(
    store: StoreArg,
    out_path: Annotated[
        str,
        typer.Option(
            "--out",
            "-o",
            metavar="OUT",
            help="Folder (vti, raw) or .npy file: a path or an s3:// URL (published whole).",
        ),
    ],
    fmt: Annotated[str, typer.Option("--format", help="vti, npy or raw.")] = "vti",
    window: WindowOpt = None,
    z: Annotated[str | None, typer.Option(help="Only rows z0:z1 of every step.")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
) -> None:
    """Export time steps of a series: .vti per step with a .pvd (ParaView), .npy, or raw files.

    Examples:

      chronocl export vortex.zarr -o vortex-vti --format vti --window 0:30:5

      chronocl export vortex.zarr -o slab.npy --format npy --window 0:10 --z 40:60

      chronocl export vortex.zarr -o raw-steps --format raw

      chronocl export vortex.zarr -o s3://bucket/slab.npy --format npy --window 0:10
    """
    from chronocl.data.formats.export import export_series
    from chronocl.data.remote import is_url
    from chronocl.data.remote_write import (
        check_remote_output,
        output_path,
        split_storage_options,
    )
    from chronocl.data.series import open_series

    reading, out_options = split_storage_options(store, out_path, anon, storage_option)
    store, storage_options = series_store(store, *reading)
    if is_url(out_path):
        check_remote_output(out_path, overwrite, out_options, (store,))  # before any work
    series = open_series(store, storage_options=storage_options)
    with output_path(out_path, overwrite, out_options) as out:
        paths = export_series(  # which refuses an output onto, into or around the store
            series, out, fmt=fmt, window=window, z=z, overwrite=overwrite, progress=True
        )
    err.print(f"wrote {len(paths)} file(s) under {out_path}")
