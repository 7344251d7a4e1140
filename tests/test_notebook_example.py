"""docs/examples/explore.ipynb runs top to bottom in a real kernel (nbclient, ipykernel), as
a reader would run it: the widget shows (its view in the output), the scrub and max mode reach
the worker, the probe, the PNG, the chronovolume and the session come out. The notebook is kept
without outputs."""

from __future__ import annotations

import base64
import json
import shutil
import time
from pathlib import Path

import pytest

pytest.importorskip("anywidget")
nbclient = pytest.importorskip("nbclient")
nbformat = pytest.importorskip("nbformat")

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "explore.ipynb"
WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"


def outputs(cell) -> list[dict]:
    return [o for o in cell.get("outputs", []) if o.get("output_type") != "stream"]


def test_the_example_is_kept_without_outputs():
    nb = nbformat.read(EXAMPLE, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(not c.outputs and c.execution_count is None for c in code)


def test_the_example_runs_top_to_bottom(tmp_path):
    path = tmp_path / EXAMPLE.name
    shutil.copy(EXAMPLE, path)
    nb = nbformat.read(path, as_version=4)
    started = time.monotonic()
    nbclient.NotebookClient(
        nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    ).execute()
    took = time.monotonic() - started
    code = [c for c in nb.cells if c.cell_type == "code"]
    errors = [o for c in code for o in c.outputs if o.get("output_type") == "error"]
    assert not errors, errors
    by_source = {c.source.splitlines()[0]: outputs(c) for c in code}

    (shown,) = by_source["w = chronocl.show(series, window=(0, 6))"]
    assert WIDGET_VIEW in shown["data"]  # the widget's view, which a front end renders
    (window,) = by_source["for t0 in range(0, 7, 2):"]
    assert window["data"]["text/plain"] == "(6, 12, 1)"
    (label,) = by_source['w.mode = "max"']
    assert label["data"]["text/plain"].startswith("'max, forward, steps 6:12")
    (curve,) = by_source[
        "p = w.probe((24, 24, 24))  # voxel x, y, z; world=True for physical coordinates"
    ]
    assert len(json.loads(curve["data"]["text/plain"].replace("'", '"'))) == 12
    (png,) = by_source["w.screenshot()"]
    assert base64.b64decode(png["data"]["image/png"])[:8] == b"\x89PNG\r\n\x1a\n"
    (cv,) = by_source["cv = w.chronovolume()"]
    assert "mode=max" in cv["data"]["text/plain"]
    assert "Chronovolume" in cv["data"]["text/html"] and "data:image/png" in cv["data"]["text/html"]
    (summary,) = by_source["import json"]  # the series' summary, as a notebook shows it
    assert "48×48×48 (x, y, z) × 12 steps" in summary["data"]["text/html"]
    session = json.loads((tmp_path / "vortex-session.json").read_text())
    assert session["chronocl_session"] == 1 and session["views"][0]["mode"] == "max"
    assert took < 60, f"the example took {took:.0f} s"
