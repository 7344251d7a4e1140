"""`chronocl probe`: the values over time at one voxel, or the mean, min and max over a box,
as CSV (stdout or a file) or a plot against the time labels."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import (
    AnonOpt,
    StorageOpt,
    StoreArg,
    TimeLabelsOpt,
    err,
    local_input,
    series_store,
)
from chronocl.core.errors import InvalidParameterError


def probe(
    store: StoreArg,
    at: Annotated[
        str | None,
        typer.Option(metavar="X,Y,Z", help="Voxel indices x,y,z (x the fastest axis)."),
    ] = None,
    box: Annotated[
        str | None,
        typer.Option(
            metavar="X0:X1,Y0:Y1,Z0:Z1",
            help="A box of voxels, ends excluded (an omitted bound is the edge): "
            "mean, min and max per step.",
        ),
    ] = None,
    out_path: Annotated[
        Path | None,
        typer.Option(
            "--out", "-o", metavar="OUT.csv|OUT.png", help="CSV or plot (default: CSV on stdout)."
        ),
    ] = None,
    window: Annotated[
        str | None,
        typer.Option(
            help="Integration window t0:t1[:stride] or a list 2,5,9: shaded on the plot; "
            "in CSV an in_window column."
        ),
    ] = None,
    title: Annotated[
        str | None, typer.Option(help="Plot title (default: what was probed).")
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    time_labels: TimeLabelsOpt = "labels",
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
) -> None:
    """Values over time at a voxel (--at) or over a box (--box: mean, min, max), with time labels.

    Reads only the voxel's or the box's part of each step. CSV columns: step,time,value, or
    for a box step,time,mean,min,max. A .png plots them against the time labels.

    Examples:

    \b
      chronocl probe vortex.zarr --at 32,32,32
      chronocl probe vortex.zarr --at 32,32,32 -o curve.csv
      chronocl probe vortex.zarr --box 24:40,24:40,28:36 -o box.png --window 0:30:10
      chronocl probe era5.zarr --at 10,20,3 -o steps.png --time-labels steps
    """
    from chronocl.core.paths import check_target
    from chronocl.core.time_labels import check_prefer
    from chronocl.data.probe import (
        check_box,
        check_point,
        check_suffix,
        parse_box,
        parse_point,
        probe,
    )
    from chronocl.data.series import open_series

    # Every option is checked before any read: nothing is written on bad input.
    if (at is None) == (box is None):
        raise InvalidParameterError(
            "give --at X,Y,Z (one voxel) or --box X0:X1,Y0:Y1,Z0:Z1 (a box), one of them"
        )
    check_prefer(time_labels)
    point = parse_point(at, "--at") if at is not None else None
    ranges = parse_box(box, "--box") if box is not None else None
    if out_path is not None:
        check_suffix(out_path)
    store, storage_options = series_store(store, anon, storage_option)
    if out_path is not None:
        check_target(out_path, overwrite, [local_input(store)])
    series = open_series(store, storage_options=storage_options)
    if point is not None:
        point = check_point(point, series.volume_shape, "--at")
    else:
        ranges = check_box(ranges, series.volume_shape, "--box")
    if window is not None:
        from chronocl.core.selection import parse_selection

        parse_selection(window, series.n_steps, series.times)

    if point is not None:
        curve = probe(series, *point, progress=True)
    else:
        curve = probe(series, region=ranges, progress=True)
    if out_path is None:
        typer.echo(curve.csv_text(window), nl=False)
        return
    from chronocl.data.probe import write_curve

    write_curve(curve, out_path, window, title, overwrite, time_labels)
    err.print(
        f"wrote {out_path} ({curve.describe()}, {len(curve)} steps)",
        highlight=False,
        soft_wrap=True,
    )
