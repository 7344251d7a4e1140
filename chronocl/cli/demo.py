"""`chronocl demo`: generate the built-in data sets and integrate every mode (chronocl.demo)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import EngineOpt, check_engine


def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for the demo outputs.")] = Path(
        "demo-out"
    ),
    engine: EngineOpt = "opencl",
) -> None:
    """Generate the built-in data sets, integrate every mode, and print summaries.

    Example: chronocl demo --out demo-out

    Without an OpenCL device: chronocl demo --out demo-out --engine numpy
    """
    check_engine(engine)
    from chronocl.demo import run_demo

    run_demo(out_dir, engine=engine)
