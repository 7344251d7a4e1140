"""`make demo`: generate the built-in data sets and integrate them with every mode.

Until the renderer exists, the demo writes the series stores and one
chronovolume per mode (the selections of the paper's Figure 3), and prints a
summary of each with the time it took.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from .data import synthetic
from .data.series import write_series
from .integrate import integrate

# (name, data set, window, mode, extra integration arguments): after the paper's Figure 3.
CASES = (
    ("alpha-3-spaced", "vortex", "0:20:9", "alpha", {}),
    ("first-hit-10", "vortex", "0:10", "first_hit", {"threshold": 0.05}),
    ("additive-10", "vortex", "0:10", "additive", {}),
    ("max-3-of-10", "vortex", "0:10:4", "max", {}),
    ("silhouette-alpha-3", "vortex", "0:30:14", "alpha", {"enhance": "silhouette"}),
    ("jet-alpha-3", "jet", "0:30:14", "alpha", {}),
    ("jet-additive-3", "jet", "0:30:14", "additive", {}),
    ("jet-max-3", "jet", "0:30:14", "max", {}),
)


def run_demo(out_dir: Path, shape_xyz: tuple[int, int, int] = (64, 64, 64), n_steps: int = 30):
    """Write the demo outputs under `out_dir` and print where they are."""
    console = Console(stderr=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    nx, ny, nz = shape_xyz
    series = {}
    for name, description in synthetic.DATASETS.items():
        t0 = time.perf_counter()
        series[name] = write_series(
            out_dir / f"{name}.zarr",
            synthetic.steps(name, n_steps, (nz, ny, nx)),
            n_steps=n_steps,
            volume_shape=(nz, ny, nx),
            dtype="float32",
            source=f"chronocl built-in '{name}': {description}",
            overwrite=True,
            progress=True,
        )
        console.print(
            f"generated {name} ({nx}x{ny}x{nz}, {n_steps} steps) "
            f"in {time.perf_counter() - t0:.1f} s -> {out_dir / (name + '.zarr')}"
        )

    table = Table(title="chronovolumes (numpy reference engine)")
    for col in ("case", "window", "mode", "covered", "mean α", "time", "file"):
        table.add_column(col)
    for case, data, window, mode, extra in CASES:
        t0 = time.perf_counter()
        cv = integrate(series[data], window, mode, **extra)
        seconds = time.perf_counter() - t0
        path = cv.save(out_dir / f"{case}.zarr", overwrite=True)
        alpha = cv.rgba[..., 3]
        table.add_row(
            case,
            window,
            mode,
            f"{np.mean(alpha > 0.05):.1%}",
            f"{alpha.mean():.3f}",
            f"{seconds:.2f} s",
            path.name,
        )
    Console().print(table)
    console.print(f"demo outputs are in {out_dir.resolve()}")
