"""`chronocl demo`: generate the built-in data sets and integrate every mode (chronocl.demo)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for the demo outputs.")] = Path(
        "demo-out"
    ),
) -> None:
    """Generate the built-in data sets, integrate every mode, and print summaries.

    Example: chronocl demo --out demo-out
    """
    from chronocl.demo import run_demo

    run_demo(out_dir)
