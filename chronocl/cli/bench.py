"""`chronocl bench`: the scalability report (throughput against window, size, workers and
device, with the read roofline) as report.json, plots and index.html."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import err, print_summary


def bench(
    out_path: Annotated[
        Path,
        typer.Option(
            "--out", "-o", metavar="DIR", help="Report folder to write (new, or an earlier report)."
        ),
    ],
    store: Annotated[
        Path | None, typer.Argument(help="Series store to measure (or use --synthetic).")
    ] = None,
    synthetic: Annotated[
        str | None,
        typer.Option(
            metavar="SIZE",
            help="Measure the built-in vortex data at N³ or NXxNYxNZ, e.g. 128 or 128x128x64.",
        ),
    ] = None,
    windows: Annotated[
        str, typer.Option(help="Window lengths (time steps), e.g. 8,16,32,64.")
    ] = "8,16,32,64",
    workers: Annotated[
        str | None,
        typer.Option(
            help="dask worker counts, e.g. 1,2,4 (default: 1, 2, 4, ... up to the cores, "
            "or the scheduler's workers)."
        ),
    ] = None,
    devices: Annotated[
        str | None,
        typer.Option(
            help="OpenCL devices: all, or indices / name parts 0:0,0:1 (default: the chosen one; "
            "see 'chronocl devices')."
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="dask scheduler address (tcp://host:8786) of a real cluster; -o must then be "
            "on a file system its workers share."
        ),
    ] = None,
    repeats: Annotated[int, typer.Option(help="Timed runs per cell (median) after a warm-up.")] = 3,
    mode: Annotated[str, typer.Option(help="Integration mode measured.")] = "alpha",
) -> None:
    """Scalability report: integration throughput (G voxel-steps/s, GB/s) against window length,
    volume size, worker count and device, each beside the bound that limits it (the store read
    with decompression on its workers, or the memory read on every core) on the same machine.

    Each cell is a streamed integration of the window 0:W, store to store, on the first n
    workers of one dask cluster (a local one of the largest count, or --scheduler); strong
    scaling keeps the volume, weak scaling gives every worker the same z-rows. Writes
    DIR/report.json, throughput_vs_window.png, strong_scaling.png, weak_scaling.png and
    index.html (docs/scaling.md).

    Examples:

    \b
      chronocl bench --synthetic 128 --windows 4,8,16 --workers 1,2 -o report/
      chronocl bench vortex.zarr --devices all --repeats 5 -o report/
      chronocl bench big.zarr --scheduler tcp://head:8786 --workers 1,4,16 -o /shared/report/
    """
    from chronocl.report.scaling import parse_counts, parse_size
    from chronocl.report.scaling_run import run_report

    size = parse_size(synthetic) if synthetic is not None else None
    report = run_report(
        out_path,
        store=store,
        size_xyz=size,
        windows=parse_counts(windows, "--windows", "8,16,32"),
        workers=parse_counts(workers, "--workers", "1,2,4") if workers is not None else None,
        devices=devices,
        scheduler=scheduler,
        repeats=repeats,
        mode=mode,
        progress=True,
    )
    err.print(f"wrote {out_path}/index.html and report.json", highlight=False)
    summary = report["summary"]
    lines = {}
    for device in report["parameters"]["devices"]:
        strong = summary["strong_speedup"][device]
        weak = summary["weak_efficiency"][device]
        lines[f"{device} strong speed-up"] = ", ".join(f"{n}: {s:.2f}×" for n, s in strong.items())
        lines[f"{device} weak efficiency"] = ", ".join(f"{n}: {e:.2f}" for n, e in weak.items())
        best = summary["best"][device]
        lines[f"{device} fastest cell"] = (
            f"{best['gvox_steps_s']:.3g} G voxel-steps/s ({best['workers']} worker"
            f"{'s' if best['workers'] > 1 else ''}, "
            f"W = {best['window']}): {100 * best['fraction']:.0f} % of its bound, the "
            f"{best['limit']} ({best['bound_gvox_steps_s']:.3g}); "
            f"{100 * best['memory_read_fraction']:.2g} % of the memory read"
        )
    if summary["cores_limit_scaling"]:
        lines["cores"] = (
            f"more workers than this machine's {summary['cores']} cores: beyond them the "
            "cores, not the code, limit scaling"
        )
    print_summary(lines)
