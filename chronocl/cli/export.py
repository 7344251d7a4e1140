"""`chronocl export`: write time steps of a series as .vti files with a .pvd, a .npy, or raw."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import STORE_HINT, WindowOpt, err


def export(
    store: Annotated[Path, typer.Argument(help="Series store.")],
    out_path: Annotated[
        Path, typer.Option("--out", "-o", metavar="OUT", help="Folder (vti, raw) or .npy file.")
    ],
    fmt: Annotated[str, typer.Option("--format", help="vti, npy or raw.")] = "vti",
    window: WindowOpt = None,
    z: Annotated[str | None, typer.Option(help="Only rows z0:z1 of every step.")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Export time steps of a series: .vti per step with a .pvd (ParaView), .npy, or raw files.

    Examples:

      chronocl export vortex.zarr -o vortex-vti --format vti --window 0:30:5

      chronocl export vortex.zarr -o slab.npy --format npy --window 0:10 --z 40:60

      chronocl export vortex.zarr -o raw-steps --format raw
    """
    from chronocl.core.paths import check_input
    from chronocl.data.formats.export import export_series
    from chronocl.data.series import open_series

    check_input(store, "store", hint=STORE_HINT)
    paths = export_series(  # which refuses an output onto, into or around the store
        open_series(store),
        out_path,
        fmt=fmt,
        window=window,
        z=z,
        overwrite=overwrite,
        progress=True,
    )
    err.print(f"wrote {len(paths)} file(s) under {out_path}")
