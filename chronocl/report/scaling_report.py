"""The scalability report's folder: report.json, three plots and index.html.

`write_report(folder, report)` writes what `chronocl.report.scaling` measured:

- report.json: the schema version, machine and devices, parameters, every cell, the roofline
  and a summary (strong-scaling speed-ups, weak-scaling efficiencies);
- throughput_vs_window.png: G voxel-steps/s (and GB/s) against the window, one line per
  device and worker count, with the bounds (`chronocl.report.bounds`): the memory read
  roofline and the store read on as many workers as there are cores;
- strong_scaling.png: speed-up against workers on the whole volume, with the ideal line and,
  where there are more workers than cores, the cores' bound;
- weak_scaling.png: efficiency against workers with the rows per worker fixed, likewise;
- index.html: the figures and a table of the cells, plain HTML without external assets.

The plots are drawn with matplotlib's Agg canvas (no display, no pyplot state).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

from chronocl.core.errors import OutputExistsError
from chronocl.report import bounds
from chronocl.report.scaling_page import FIGURES, page

SCHEMA = "chronocl-bench/1"
REPORT = "report.json"


# -- the output folder ------------------------------------------------------------------------
def is_report(path: Path) -> bool:
    """Whether `path` is a folder holding an earlier report (a report.json of this kind)."""
    try:
        data = json.loads((path / REPORT).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and str(data.get("schema", "")).startswith("chronocl-bench/")


def check_report_target(path: str | os.PathLike) -> bool:
    """Whether the report may replace `path` (absent, an empty folder or an earlier report);
    raises OutputExistsError otherwise. True when something is there to replace."""
    p = Path(path)
    if not os.path.lexists(p):
        return False
    if p.is_dir() and not p.is_symlink() and (not any(p.iterdir()) or is_report(p)):
        return True
    raise OutputExistsError(
        f"-o {os.fspath(path)!r} exists and is not an earlier chronocl bench report; "
        "choose a new folder (an earlier report there is replaced)"
    )


# -- summary ----------------------------------------------------------------------------------
def _series(cells: Sequence[dict], study: str, device: str, window: int | None = None):
    rows = [
        c
        for c in cells
        if c["study"] == study and c["device"] == device and window in (None, c["window"])
    ]
    return sorted(rows, key=lambda c: c["workers"])


def speedups(rows: Sequence[dict]) -> dict[int, float]:
    """Strong scaling: n0·t(n0)/t(n) against the fewest workers n0 (ideal: n)."""
    if not rows:
        return {}
    n0, t0 = rows[0]["workers"], rows[0]["median_s"]
    return {c["workers"]: n0 * t0 / c["median_s"] for c in rows}


def efficiencies(rows: Sequence[dict]) -> dict[int, float]:
    """Weak scaling: t(n0)/t(n), the same rows per worker (ideal: 1)."""
    if not rows:
        return {}
    t0 = rows[0]["median_s"]
    return {c["workers"]: t0 / c["median_s"] for c in rows}


def summary(report: dict) -> dict:
    """Speed-ups (largest window) and efficiencies per device, and the best fraction of the
    memory read roofline any cell reached (in voxel-steps/s: the roofline reads stores of
    other types than float32 and uint8 as float32)."""
    cells, p = report["cells"], report["parameters"]
    wmax = p["windows"][-1]
    roof = report["roofline"]["devices"]
    return {
        "strong_speedup": {
            d: {str(n): round(s, 3) for n, s in speedups(_series(cells, "strong", d, wmax)).items()}
            for d in p["devices"]
        },
        "weak_efficiency": {
            d: {str(n): round(e, 3) for n, e in efficiencies(_series(cells, "weak", d)).items()}
            for d in p["devices"]
        },
        "cores": bounds.cores(report),
        "cores_limit_scaling": bounds.cores_limited(p["workers"], bounds.cores(report)),
        "best": bounds.best_cells(report),
        "best_roofline_fraction": {
            d: round(
                max(c["gvox_steps_s"] for c in cells if c["device"] == d) / roof[d]["gvox_steps_s"],
                4,
            )
            for d in p["devices"]
        },
    }


# -- figures ----------------------------------------------------------------------------------
def _figure():
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 5), dpi=100, layout="constrained")
    return fig, fig.add_subplot()


def _device_name(report: dict, index: str) -> str:
    for d in report["devices"]:
        if d["index"] == index:
            return f"{index} {d['name']}"
    return index


def _cores_bound(ax, report: dict, bound) -> None:
    """The line `bound(workers, cores)` where there are more workers than the machine's cores."""
    workers, n_cores = report["parameters"]["workers"], bounds.cores(report)
    if bounds.cores_limited(workers, n_cores):
        ax.plot(
            workers,
            bound(workers, n_cores),
            color="k",
            linewidth=2,
            alpha=0.6,
            label=f"bound from the machine's {n_cores} cores",
        )


def throughput_figure(report: dict):
    """G voxel-steps/s against window length, per device and worker count, with rooflines."""
    fig, ax = _figure()
    cells, p = report["cells"], report["parameters"]
    roof = report["roofline"]
    itemsize = p["itemsize"]
    for i, d in enumerate(p["devices"]):
        for j, n in enumerate(p["workers"]):
            rows = sorted(
                (
                    c
                    for c in cells
                    if c["study"] == "strong" and c["device"] == d and c["workers"] == n
                ),
                key=lambda c: c["window"],
            )
            ax.plot(
                [c["window"] for c in rows],
                [c["gvox_steps_s"] for c in rows],
                marker="o",
                color=f"C{(i * len(p['workers']) + j) % 10}",
                label=f"{_device_name(report, d)}, {n} worker{'s' if n > 1 else ''}",
            )
        ax.axhline(
            roof["devices"][d]["gvox_steps_s"],
            color=f"C{i * len(p['workers']) % 10}",
            linestyle="--",
            linewidth=1,
            label=f"memory read bound (every core), {d}",
        )
    n_cores = bounds.cores(report)
    for n in sorted({min(n, n_cores) for n in p["workers"]}):
        ax.axhline(
            roof["store_read_gvox_steps_s"] * n,
            color="0.3",
            linestyle=":",
            linewidth=1 + n / max(p["workers"]),
            label=f"store read bound (decompression included), {n} worker"
            + ("s" if n > 1 else "")
            + (f", all {n_cores} cores" if n == n_cores else ""),
        )
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(p["windows"], [str(w) for w in p["windows"]])
    ax.set_xlabel("window length W (time steps)")
    ax.set_ylabel("throughput (G voxel-steps/s)")
    gb = ax.secondary_yaxis("right", functions=(lambda g: g * itemsize, lambda b: b / itemsize))
    gb.set_ylabel(f"GB/s read ({itemsize}-byte voxels)")
    nx, ny, nz = p["size_xyz"]
    ax.set_title(f"Integration throughput, {nx}×{ny}×{nz}, mode {p['mode']}")
    ax.grid(alpha=0.3, which="both")
    # below the axes (the bounds run along the top, where a legend inside would hide them), in
    # room the layout makes for it, so that long device names are not cut off
    fig.set_figheight(5 + 0.2 * len(ax.get_lines()))
    fig.legend(loc="outside lower center", ncol=1, fontsize="small")
    return fig


def strong_figure(report: dict):
    """Speed-up against workers on the whole volume, per device and window, with the ideal."""
    fig, ax = _figure()
    cells, p = report["cells"], report["parameters"]
    workers = p["workers"]
    ax.plot(workers, workers, color="0.5", linestyle="--", label="ideal (speed-up = workers)")
    _cores_bound(ax, report, bounds.speedup_bound)
    k = 0
    for d in p["devices"]:
        for w in p["windows"]:
            s = speedups(_series(cells, "strong", d, w))
            ax.plot(
                list(s),
                list(s.values()),
                marker="o",
                color=f"C{k % 10}",
                label=f"{_device_name(report, d)}, W = {w}",
            )
            k += 1
    ax.set_xticks(workers, [str(n) for n in workers])
    ax.set_xlabel("workers (dask worker processes, 1 thread each)")
    ax.set_ylabel(f"speed-up (× over {workers[0]} worker{'s' if workers[0] > 1 else ''})")
    nx, ny, nz = p["size_xyz"]
    ax.set_title(f"Strong scaling: fixed volume {nx}×{ny}×{nz}")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def weak_figure(report: dict):
    """Efficiency against workers with the rows per worker fixed, per device."""
    fig, ax = _figure()
    cells, p = report["cells"], report["parameters"]
    workers = p["workers"]
    ax.axhline(1.0, color="0.5", linestyle="--", label="ideal (efficiency 1)")
    _cores_bound(ax, report, bounds.efficiency_bound)
    for i, d in enumerate(p["devices"]):
        rows = _series(cells, "weak", d)
        e = efficiencies(rows)
        ax.plot(
            list(e), list(e.values()), marker="o", color=f"C{i % 10}", label=_device_name(report, d)
        )
        for c in rows:
            z, y, x = c["shape_zyx"]
            ax.annotate(
                f"{x}×{y}×{z}",
                (c["workers"], e[c["workers"]]),
                textcoords="offset points",
                xytext=(0, 7),
                ha="center",
                fontsize="x-small",
                color=f"C{i % 10}",
            )
    ax.set_xticks(workers, [str(n) for n in workers])
    ax.set_xlabel(
        f"workers ({p['weak_rows_per_worker']} z-rows each, window W = {p['windows'][-1]})"
    )
    ax.set_ylabel(f"efficiency t({workers[0]}) / t(n)")
    ax.set_ylim(0, max(1.2, ax.get_ylim()[1] * 1.1))  # room for the size labels
    ax.margins(x=0.12)
    ax.set_title("Weak scaling: volume grows with the workers")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


# -- writing ----------------------------------------------------------------------------------
def write_report(folder: Path, report: dict) -> dict:
    """report.json, the three figures and index.html into the (new, empty) `folder`; returns
    the report with its summary."""
    report = {**report, "summary": summary(report)}
    (folder / REPORT).write_text(json.dumps(report, indent=1) + "\n")
    for name, draw in zip(FIGURES, (throughput_figure, strong_figure, weak_figure), strict=True):
        draw(report).savefig(folder / name, format="png")
    (folder / "index.html").write_text(page(report))
    return report
