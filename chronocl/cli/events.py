"""`chronocl events`: the features of each step of a window, their events (merges, splits,
births, deaths, exits) and tracks, as JSON and a picture of the event graph."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import (
    AnonOpt,
    StorageOpt,
    StoreArg,
    TfOpt,
    WindowOpt,
    err,
    local_input,
    series_store,
)
from chronocl.core.errors import InvalidParameterError, OutputNotWritableError


def events(
    store: StoreArg,
    out_path: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="OUT.json",
            help="Events JSON to write (features, edges, events, tracks).",
        ),
    ],
    window: WindowOpt = None,
    threshold: Annotated[
        float | None,
        typer.Option(help="A step shows the voxels whose value is at least this (data units)."),
    ] = None,
    tf: TfOpt = None,
    opacity: Annotated[
        float | None,
        typer.Option(
            help="With --tf: a step shows the voxels whose TF opacity exceeds this, in [0, 1) "
            "(default 0)."
        ),
    ] = None,
    connectivity: Annotated[
        int, typer.Option(help="Voxels touching by faces (6), also edges (18), also corners (26).")
    ] = 26,
    periodic: Annotated[
        str,
        typer.Option(
            metavar="AXES",
            help="Axes whose two faces join (periodic boundaries): none, x, xy, xyz, ...",
        ),
    ] = "none",
    tracks: Annotated[
        str,
        typer.Option(
            help="global (cheapest paths through the window's overlaps: a step of weak overlap "
            "does not break a track) or local (each step pair's largest overlaps)."
        ),
    ] = "global",
    picture: Annotated[
        Path | None,
        typer.Option(metavar="OUT.png", help="Picture of the event graph (default: OUT.png)."),
    ] = None,
    no_picture: Annotated[bool, typer.Option("--no-picture", help="Write no picture.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace the outputs if they exist.")] = False,
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
) -> None:
    """Features through time: the connected components of the voxels each step shows, matched
    by overlap into continuations, merges, splits, births, deaths and exits, and tracks.

    A step shows the voxels whose value is at least --threshold, or whose opacity under the
    data TF of --tf exceeds --opacity. Features of consecutive steps are matched by their
    shared voxels (similarity: the Jaccard index); events are classified per group of
    overlapping features (a death touching the volume's boundary is an exit). Writes the
    JSON and a picture: steps along x, features as bars as tall as their size, overlaps as
    lines, events marked.

    Examples:

    \b
      chronocl events vortex.zarr --window 0:20 --threshold 0.3 -o events.json
      chronocl events vortex.zarr --threshold 0.3 -o events.json --tracks local
      chronocl events run.zarr --tf tf.json --opacity 0.2 -o run-events.json --picture g.png
      chronocl events flow.zarr --threshold 1.5 --periodic xy --connectivity 6 -o flow.json
    """
    from chronocl.core.paths import check_distinct, check_target
    from chronocl.data.series import open_series
    from chronocl.events.features import check_connectivity, parse_periodic
    from chronocl.events.plot import png_bytes, write_png
    from chronocl.events.run import find, prepare
    from chronocl.events.tracking import check_method

    t0 = time.perf_counter()
    # Every option is checked before any step is read: nothing is written on bad input.
    check_connectivity(connectivity)
    parse_periodic(periodic)
    check_method(tracks)
    _suffix(out_path, ".json", "-o")
    pic = None if no_picture else picture if picture is not None else out_path.with_suffix(".png")
    if pic is not None:
        _suffix(pic, ".png", "--picture")
    store, storage_options = series_store(store, anon, storage_option)
    for path in (out_path, pic):
        if path is not None:
            _folder_exists(path)
            check_target(path, overwrite, [local_input(store), tf])
    check_distinct([out_path, pic])
    series = open_series(store, storage_options=storage_options)
    job = prepare(
        series,
        window,
        threshold=threshold,
        tf=tf,
        opacity=opacity,
        connectivity=connectivity,
        periodic=periodic,
        tracks=tracks,
    )

    graph = find(job, progress=True)
    image = png_bytes(graph) if pic is not None else None  # drawn whole before any write
    graph.save(out_path, overwrite=overwrite)
    if pic is not None and image is not None:
        write_png(image, pic, overwrite)
    took = time.perf_counter() - t0
    wrote = f"{out_path} and {pic}" if pic is not None else str(out_path)
    err.print(f"wrote {wrote} in {took:.2f} s: {graph.describe()}", highlight=False, soft_wrap=True)


def _suffix(path: Path, suffix: str, option: str) -> None:
    if path.suffix.lower() != suffix:
        raise InvalidParameterError(
            f"{option} {str(path)!r} must end in {suffix}; e.g. {option} "
            f"{path.with_suffix(suffix).name}"
        )


def _folder_exists(path: Path) -> None:
    """The output's folder must exist: a mistyped folder is caught, not made."""
    folder = path.absolute().parent
    if not folder.is_dir():
        raise OutputNotWritableError(
            f"cannot write {str(path)!r}: folder {str(folder)!r} does not exist; create it "
            "or choose another path"
        )
