"""The scalability report's index.html: parameters, machine, figures, bounds and every cell,
plain HTML without external assets (written by `chronocl.report.scaling_report`)."""

from __future__ import annotations

import html
import json
from collections.abc import Sequence

from chronocl.report import bounds

FIGURES = ("throughput_vs_window.png", "strong_scaling.png", "weak_scaling.png")


def _table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in row) + "</tr>" for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def page(report: dict) -> str:
    """index.html: parameters, machine, figures, rooflines and every cell."""
    p, m, roof = report["parameters"], report["machine"], report["roofline"]
    info = [(k, v if isinstance(v, str) else json.dumps(v)) for k, v in (*p.items(), *m.items())]
    info.append(("cluster", json.dumps(report["cluster"])))
    devices = [(d["index"], d["name"], d["kind"], d["platform"]) for d in report["devices"]]
    roofs = [
        (
            d,
            f"{r['memory_read_gb_s']:.2f}",
            f"{r['opencl_read_gb_s']:.2f}",
            "– (host memory)"
            if r["copy_to_device_gb_s"] is None
            else f"{r['copy_to_device_gb_s']:.2f}",
            f"{r['gb_s']:.2f}",
            f"{r['gvox_steps_s']:.3f}",
            r["limit"],
        )
        for d, r in roof["devices"].items()
    ]
    limits = [
        (
            d,
            b["workers"],
            b["window"],
            f"{b['gvox_steps_s']:.4f}",
            b["limit"],
            f"{b['bound_gvox_steps_s']:.4f}",
            f"{100 * b['fraction']:.1f} %",
            f"{100 * b['memory_read_fraction']:.2f} %",
        )
        for d, b in report["summary"]["best"].items()
    ]
    cells = [
        (
            c["study"],
            c["device"],
            c["workers"],
            c["window"],
            "×".join(map(str, c["shape_zyx"][::-1])),
            f"{c['median_s']:.4f}",
            f"{c['min_s']:.4f}",
            f"{c['gvox_steps_s']:.4f}",
            f"{c['gb_s']:.4f}",
            bounds.cell_limit(report, c)["limit"],
            f"{100 * bounds.cell_limit(report, c)['fraction']:.1f} %",
        )
        for c in report["cells"]
    ]
    figures = "".join(f'<p><img src="{name}" alt="{name}"></p>' for name in FIGURES)
    store = (
        f"<p>Store read (decompression included, one process: "
        f"{html.escape(str(roof['where']))}): {roof['store_read_gb_s']:.2f} GB/s = "
        f"{roof['store_read_gvox_steps_s']:.3f} G voxel-steps/s; n workers read at most "
        f"min(n, {bounds.cores(report)} cores) times as fast.</p>"
    )
    cores_note = (
        f"<p>More workers than the machine's {bounds.cores(report)} cores: beyond them the "
        "cores, not the code, limit the scaling (the black line in the scaling plots).</p>"
        if report["summary"]["cores_limit_scaling"]
        else ""
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>chronocl scalability report</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:70em}}table{{border-collapse:collapse;
margin:1em 0}}td,th{{border:1px solid #ccc;padding:2px 8px;text-align:right}}
td:first-child,th:first-child{{text-align:left}}
img{{max-width:100%}}</style></head><body>
<h1>chronocl scalability report</h1>
<p>Schema {html.escape(report["schema"])}, written {html.escape(report["created"])}.
Each cell is the median of {p["repeats"]} runs (after one warm-up) of a streamed integration
of the window 0:W, store to store, on the first n workers of one dask cluster.</p>
{_table(("parameter", "value"), info)}
<h2>Figures</h2>{figures}
<h2>Devices</h2>{_table(("index", "name", "kind", "platform"), devices)}
<h2>Bounds</h2>
<p>Each cell is limited by the lower of two bounds measured here: the store read
(decompression included) on its workers, and the memory read of the same bytes on every core
(the roofline; on a GPU, the copy to the device where that is slower).</p>
{
        _table(
            (
                "device",
                "memory read, every core GB/s",
                "OpenCL read kernel GB/s",
                "copy to device GB/s",
                "roofline GB/s",
                "G voxel-steps/s",
                "roofline is",
            ),
            roofs,
        )
    }
{store}
<h2>What limits the fastest cell</h2>
{
        _table(
            (
                "device",
                "workers",
                "window",
                "G voxel-steps/s",
                "limited by",
                "bound G voxel-steps/s",
                "of the bound",
                "of the memory read",
            ),
            limits,
        )
    }
{cores_note}
<h2>Cells</h2>
{
        _table(
            (
                "study",
                "device",
                "workers",
                "window",
                "size X×Y×Z",
                "median s",
                "min s",
                "G voxel-steps/s",
                "GB/s",
                "limited by",
                "of the bound",
            ),
            cells,
        )
    }
</body></html>
"""
