"""`chronocl integrate`: integrate a window into a chronovolume file, in memory, streamed or on
dask as `chronocl.integration.runs.auto` decides."""

from __future__ import annotations

import inspect
import logging
import time
from pathlib import Path
from typing import Annotated

import typer

from chronocl import modes
from chronocl.cli.options import (
    AnonOpt,
    ColormapOpt,
    DeviceFormatOpt,
    DeviceOpt,
    EngineOpt,
    LevelOpt,
    NormalizeOpt,
    OrderOpt,
    StorageOpt,
    StoreArg,
    TfOpt,
    ThresholdOpt,
    TimeTfOpt,
    ValueRangeOpt,
    WindowOpt,
    err,
    local_input,
    mode_choices,
    modes_help,
    range_words,
    series_store,
    spec_args,
)


def integrate(
    store: StoreArg,
    out_path: Annotated[
        str,
        typer.Argument(
            metavar="OUT",
            help="Chronovolume to write: .zarr, .ome.zarr (napari) or .vti (ParaView); a path "
            "or an s3:// URL (written locally, then published whole).",
        ),
    ],
    mode: Annotated[str, typer.Option(help=f"{mode_choices()}.")] = modes.DEFAULT,
    window: WindowOpt = None,
    order: OrderOpt = "forward",
    tf: TfOpt = None,
    time_tf: TimeTfOpt = None,
    colormap: ColormapOpt = None,
    value_range: ValueRangeOpt = None,
    enhance: Annotated[str, typer.Option(help="none, edge or silhouette.")] = "none",
    threshold: ThresholdOpt = None,
    normalize: NormalizeOpt = "time",
    engine: EngineOpt = "opencl",
    device: DeviceOpt = None,
    device_format: DeviceFormatOpt = "auto",
    level: LevelOpt = 0,
    memory: Annotated[
        str,
        typer.Option(help="Memory budget; larger windows stream z-slabs into a .zarr OUT."),
    ] = "2GB",
    scheduler: Annotated[
        str | None,
        typer.Option(help="dask scheduler address (tcp://host:8786): one task per z-slab."),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(help="Start a local dask cluster of N worker processes (spawned)."),
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
) -> None:
    """Integrate a window of time steps into a chronovolume store.

    A window too large for --memory is streamed slab by slab into a .zarr OUT; with
    --scheduler or --workers the slabs run on a dask cluster. An interrupted streamed run
    resumes when run again with the same arguments.

    Examples:

      chronocl integrate vortex.zarr a.zarr --mode alpha --window 0:30:10

      chronocl integrate jet.zarr m.zarr --mode max --window 0:10 --order backward

      chronocl integrate big.zarr a.zarr --memory 4GB --workers 2

      chronocl integrate big.zarr quick.zarr --mode max --level 2

      chronocl integrate s3://bucket/run.zarr m.zarr --mode max --window 0:10 --anon

      chronocl integrate run.zarr s3://bucket/m.zarr --mode max --window 0:10
    """
    from chronocl.core.paths import check_target
    from chronocl.data.remote import is_url
    from chronocl.data.remote_write import (
        check_remote_output,
        output_path,
        split_storage_options,
    )
    from chronocl.data.series import open_series
    from chronocl.engine.device_formats import check_format_name
    from chronocl.integration.inmemory import check_level
    from chronocl.integration.runs.auto import check_run_options

    t0 = time.perf_counter()

    # Everything is checked before any work: no kernel built, no brick read, nothing written.
    check_run_options(out_path, memory, engine, scheduler, workers)
    check_format_name(device_format)
    reading, out_options = split_storage_options(store, out_path, anon, storage_option)
    store, storage_options = series_store(store, *reading)
    args = spec_args(tf, time_tf, order, enhance, threshold, normalize, colormap, value_range)
    if is_url(out_path):
        check_remote_output(out_path, overwrite, out_options, (store,))
    else:
        check_target(Path(out_path), overwrite, [local_input(store), tf])
    series = open_series(store, storage_options=storage_options)
    check_level(series, level)
    with output_path(out_path, overwrite, out_options) as out:
        what = _run(series, window, out, mode, level, overwrite, args, memory, engine, device,
                    scheduler, workers, device_format)  # fmt: skip
    took = time.perf_counter() - t0
    err.print(f"wrote {out_path} ({mode}, {what}) in {took:.2f} s")


def _run(series, window, out_path, mode, level, overwrite, args, memory, engine, device,
         scheduler, workers, device_format) -> str:  # fmt: skip
    """Plan and run the integration into the local `out_path`; what was written, in words."""
    from chronocl.integration.runs.auto import plan_run

    run = plan_run(
        series,
        window,
        out_path,
        mode=mode,
        memory=memory,
        engine=engine,
        device=device,
        scheduler=scheduler,
        workers=workers,
        level=level,
        device_format=device_format,
        **args,
    )
    if run.streamed:
        _show_run_notes()
    cv = run.execute(
        overwrite=overwrite,
        progress=True,
        on_dashboard=lambda link: err.print(f"dask dashboard: {link}", highlight=False),
    )
    ranged = range_words([run.job])
    return f"streamed, {ranged}" if cv is None else f"steps {cv.steps}, {ranged}"


def _show_run_notes() -> None:
    """Print a streamed run's notes (resumed, discarded partial runs) on stderr."""
    log = logging.getLogger("chronocl")
    if not log.handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter("chronocl: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)


def help_text() -> str:
    """The command's help: its docstring, with the registered modes listed before examples."""
    doc = inspect.cleandoc(integrate.__doc__ or "")
    head, examples, rest = doc.partition("\n\nExamples:")
    return f"{head}\n\n{modes_help()}{examples}{rest}"
