"""What limits each measurement of the scalability report, with its figure.

A cell is a streamed integration, store to store, on n one-thread workers. Two bounds are
measured where the report runs (`chronocl.report.scaling.roofline_at`), and each cell is held
against both:

- the **store read**: reading and decompressing the window from the store, measured in one
  process; n workers can do it side by side on at most as many cores, so the bound of a cell
  is that rate times min(n, cores);
- the **memory read**: reading the same bytes from memory on every core
  (`chronocl.engine.roofline`), which no integration can beat whatever it reads from.

The lower of the two limits the cell. Scaling has its own bound from the cores: n workers
on c cores run at most min(n, c) times one worker's speed (strong scaling's speed-up), and
weak scaling's efficiency cannot exceed (n0 / n) * min(n, c) / min(n0, c).
"""

from __future__ import annotations

from collections.abc import Sequence

STORE, MEMORY = "store read", "memory read"


def cores(report: dict) -> int:
    """The cores the cells ran on: the machine's (a cluster elsewhere is not known here)."""
    return int(report["machine"].get("cpu_count") or 1)


def cell_bounds(report: dict, cell: dict) -> dict[str, float]:
    """{bound: G voxel-steps/s} for `cell`: the store read on its workers, the memory read."""
    roof = report["roofline"]
    n = min(cell["workers"], cores(report))
    return {
        STORE: roof["store_read_gvox_steps_s"] * n,
        MEMORY: roof["devices"][cell["device"]]["gvox_steps_s"],
    }


def cell_limit(report: dict, cell: dict) -> dict:
    """{"limit": the lower bound's name, "bound_gvox_steps_s", "fraction" of it reached}."""
    bounds = cell_bounds(report, cell)
    name = min(bounds, key=bounds.get)
    return {
        "limit": name,
        "bound_gvox_steps_s": bounds[name],
        "fraction": cell["gvox_steps_s"] / bounds[name],
    }


def best_cells(report: dict) -> dict[str, dict]:
    """Per device, its fastest cell with what limits it: {device: {"workers", "window",
    "gvox_steps_s", "limit", "bound_gvox_steps_s", "fraction", "memory_read_fraction"}}."""
    out = {}
    for d in report["parameters"]["devices"]:
        cells = [c for c in report["cells"] if c["device"] == d]
        best = max(cells, key=lambda c: c["gvox_steps_s"])
        memory = report["roofline"]["devices"][d]["gvox_steps_s"]
        out[d] = {
            "workers": best["workers"],
            "window": best["window"],
            "gvox_steps_s": best["gvox_steps_s"],
            **cell_limit(report, best),
            "memory_read_fraction": best["gvox_steps_s"] / memory,
        }
    return out


def speedup_bound(workers: Sequence[int], n_cores: int) -> list[float]:
    """Strong scaling's best speed-up over the first count, from the cores alone."""
    base = min(workers[0], n_cores)
    return [workers[0] * min(n, n_cores) / base for n in workers]


def efficiency_bound(workers: Sequence[int], n_cores: int) -> list[float]:
    """Weak scaling's best efficiency against the first count, from the cores alone."""
    n0 = workers[0]
    return [min(1.0, (n0 / n) * min(n, n_cores) / min(n0, n_cores)) for n in workers]


def cores_limited(workers: Sequence[int], n_cores: int) -> bool:
    """Whether some worker count exceeds the cores (then the cores, not the code, limit)."""
    return max(workers) > n_cores
