"""`chronocl demo`: generate the built-in data sets and integrate every mode (chronocl.demo)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import EngineOpt


def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for the demo outputs.")] = Path(
        "demo-out"
    ),
    engine: EngineOpt = "opencl",
    data: Annotated[
        Path | None,
        typer.Option(
            help="A series store (chronocl ingest): draw every mode's default picture of it "
            "instead, with the fraction of the window's steps each shows."
        ),
    ] = None,
    window: Annotated[
        str | None, typer.Option(help="With --data: the window t0:t1[:stride] (default: all).")
    ] = None,
) -> None:
    """Generate the built-in data sets, integrate every mode, and print summaries; then every
    mode's default picture of a reaction-diffusion run, with the steps each shows.

    Example: chronocl demo --out demo-out

    Your own data, every mode with the defaults: chronocl demo --data run.zarr --window 0:20

    Without an OpenCL device: chronocl demo --out demo-out --engine numpy
    """
    from chronocl.engine import check_engine

    check_engine(engine)
    if data is None:
        from chronocl.demo import run_demo

        run_demo(out_dir, engine=engine)
        return
    from rich.console import Console

    from chronocl.core.selection import parse_selection
    from chronocl.data.series import open_series
    from chronocl.demo import print_shown
    from chronocl.demo_defaults import default_pictures

    series = open_series(data)
    window = window or f"0:{series.n_steps}"
    parse_selection(window, series.n_steps, series.times)  # a bad window: one line before any work
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"defaults-{data.stem}.png"
    print_shown(default_pictures(series, window, path, engine=engine), path, Console(stderr=True))
