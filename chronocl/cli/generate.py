"""`chronocl generate`: write a built-in synthetic time-varying data set as a series store."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import err, parse_sizes, print_summary
from chronocl.core.errors import InvalidParameterError

MAX_GENERATED_STEPS = 100_000
MAX_GENERATED_SIDE = 4096
MAX_GENERATED_VOXELS = 2**30  # 4 GiB of float32 per step, computed in memory


def generate(
    name: Annotated[str, typer.Argument(help="Data set: vortex or jet.")],
    out_path: Annotated[Path, typer.Argument(metavar="OUT.zarr", help="Store to write.")],
    shape: Annotated[str, typer.Option(help="Volume size NXxNYxNZ.")] = "64x64x64",
    steps: Annotated[int, typer.Option(help="Number of time steps.")] = 30,
    seed: Annotated[int, typer.Option(help="Seed of the smooth random variations.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Write a built-in synthetic time-varying data set.

    Example: chronocl generate jet jet.zarr --shape 96x64x64 --steps 20
    """
    from chronocl.core.paths import check_target
    from chronocl.data import synthetic
    from chronocl.data.series import write_series

    nx, ny, nz = parse_sizes(shape, 3, "NXxNYxNZ", "64x64x64")
    if name not in synthetic.DATASETS:
        synthetic.step(name, 0, 1, (1, 1, 1))  # raises the unknown-name error
    if not 1 <= steps <= MAX_GENERATED_STEPS:
        raise InvalidParameterError(
            f"--steps is {steps}; generate 1 to {MAX_GENERATED_STEPS} steps"
        )
    if max(nx, ny, nz) > MAX_GENERATED_SIDE or nx * ny * nz > MAX_GENERATED_VOXELS:
        raise InvalidParameterError(
            f"--shape {nx}x{ny}x{nz} is too large to generate; use at most "
            f"{MAX_GENERATED_SIDE} per side and {MAX_GENERATED_VOXELS // 2**20} Mi voxels, "
            "e.g. --shape 256x256x256"
        )
    check_target(out_path, overwrite)
    t0 = time.perf_counter()
    series = write_series(
        out_path,
        synthetic.steps(name, steps, (nz, ny, nx), seed),
        n_steps=steps,
        volume_shape=(nz, ny, nx),
        dtype="float32",
        source=f"chronocl generate {name} --shape {nx}x{ny}x{nz} --steps {steps} --seed {seed}",
        overwrite=overwrite,
        progress=True,
    )
    err.print(f"wrote {out_path} in {time.perf_counter() - t0:.1f} s")
    print_summary(series.describe())
