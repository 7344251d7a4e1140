"""`chronocl bench`: a tiny scalability report end to end, and bad input refused in one line.

The end-to-end run is the real command (`chronocl.cli.app.main`, what `python -m chronocl`
runs, in this process to spare the start-up; a LocalCluster of two spawned workers):
report.json's schema, the three plots drawn (not blank), index.html showing them and a
table of every cell, nothing left behind. Bad input must be one line, exit 2, and leave no
output and no partial.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys

import numpy as np
import pytest

from chronocl.cli.app import main
from chronocl.core.errors import OutputExistsError
from chronocl.data.series import write_series
from chronocl.engine.device import get_context
from chronocl.engine.roofline import LIMITS
from chronocl.report.scaling_report import FIGURES, SCHEMA, check_report_target

pytest.importorskip("distributed")


def run_main(*args: str) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of `chronocl *args` run by `main()` in this process."""
    stdout, stderr = io.StringIO(), io.StringIO()
    argv = sys.argv
    sys.argv = ["chronocl", *map(str, args)]
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            main()
        code = 0
    except SystemExit as exc:
        code = exc.code or 0
    finally:
        sys.argv = argv
    return code, stdout.getvalue(), stderr.getvalue()


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bench")
    out = folder / "report"
    args = ("--synthetic", "16", "--windows", "2,3", "--workers", "1,2", "--repeats", "1")
    code, stdout, stderr = run_main("bench", *args, "-o", out)
    assert code == 0, stderr
    return folder, out, stdout


def test_report_json_schema(report):
    _, out, stdout = report
    data = json.loads((out / "report.json").read_text())
    assert data["schema"] == SCHEMA
    for key in ("created", "machine", "cluster", "devices", "parameters", "cells", "roofline"):
        assert key in data
    p = data["parameters"]
    assert p["windows"] == [2, 3] and p["workers"] == [1, 2] and p["repeats"] == 1
    assert p["size_xyz"] == [16, 16, 16] and p["weak_rows_per_worker"] == 8
    assert data["cluster"]["kind"] == "local" and data["cluster"]["workers"] == 2
    (device,) = p["devices"]
    assert [d["index"] for d in data["devices"]] == [device]
    cells = data["cells"]
    strong = {(c["workers"], c["window"]) for c in cells if c["study"] == "strong"}
    assert strong == {(1, 2), (1, 3), (2, 2), (2, 3)}
    weak = {c["workers"]: c["shape_zyx"] for c in cells if c["study"] == "weak"}
    assert weak == {1: [8, 16, 16], 2: [16, 16, 16]}  # the rows per worker stay 8
    for c in cells:
        assert c["device"] == device and len(c["times_s"]) == 1
        nz, ny, nx = c["shape_zyx"]
        assert c["voxel_steps"] == nz * ny * nx * c["window"] and c["bytes"] == 4 * c["voxel_steps"]
        assert c["median_s"] > 0 and c["gvox_steps_s"] > 0 and c["gb_s"] > 0
        assert c["gb_s"] == pytest.approx(4 * c["gvox_steps_s"])
    roof = data["roofline"]
    assert roof["store_read_gb_s"] > 0 and roof["window"] == 3
    r = roof["devices"][device]
    assert r["memory_read_gb_s"] > 0 and r["opencl_read_gb_s"] > 0
    memory = r["memory_read_gb_s"]
    if get_context(device).is_cpu:
        # One bound: the memory read on every core (no copy to a device), numpy's or the OpenCL
        # read kernel's on this CPU device, whichever was faster (both read the host's memory).
        assert r["copy_to_device_gb_s"] is None
        assert r["gb_s"] == max(memory, r["opencl_read_gb_s"])
        assert r["limit"] == LIMITS["read-memory"]
    else:
        # A device apart from host memory (a GPU): the bound is the slower of the memory read
        # and the copy to the device; the OpenCL read (its buffers copied across by the driver
        # first) is reported only.
        copy = r["copy_to_device_gb_s"]
        assert copy is not None and copy > 0
        assert r["gb_s"] == min(memory, copy)
        assert r["limit"] == LIMITS["copy-to-device" if copy < memory else "read-memory"]
    assert r["memory_read_threads"] == data["machine"]["cpu_count"]
    s = data["summary"]
    assert s["strong_speedup"][device]["1"] == 1.0 and s["strong_speedup"][device]["2"] > 0
    assert s["weak_efficiency"][device]["1"] == 1.0 and s["weak_efficiency"][device]["2"] > 0
    # The fastest cell is held against the lower of its two bounds, which it cannot beat.
    best = s["best"][device]
    n = min(best["workers"], data["machine"]["cpu_count"])
    store, memory = roof["store_read_gvox_steps_s"] * n, r["gvox_steps_s"]
    assert best["bound_gvox_steps_s"] == pytest.approx(min(store, memory))
    assert best["limit"] == ("store read" if store < memory else "memory read")
    assert 0 < best["fraction"] and 0 < best["memory_read_fraction"] <= 1
    assert "strong speed-up" in stdout and "weak efficiency" in stdout  # the summary
    assert f"of its bound, the {best['limit']}" in stdout


def test_plots_are_drawn_and_shown(report):
    from matplotlib.image import imread

    folder, out, _ = report
    for name in FIGURES:
        pixels = imread(out / name)[..., :3]
        assert pixels.shape[0] > 200 and pixels.shape[1] > 300
        assert float(np.var(pixels)) > 1e-3, f"{name} is blank"
        # lines in colour, not only black text on white
        assert (np.ptp(pixels, axis=2) > 0.3).mean() > 1e-3, f"{name} has no coloured lines"
    page = (out / "index.html").read_text()
    for name in FIGURES:
        assert f'<img src="{name}"' in page
    assert page.count("<tr>") >= 6 + 1  # a row per cell and more
    assert "http" not in page  # no external assets
    # nothing but the report, and no partial or scratch data left beside it
    assert sorted(p.name for p in out.iterdir()) == sorted([*FIGURES, "index.html", "report.json"])
    assert [p.name for p in folder.iterdir()] == ["report"]


def test_an_earlier_report_may_be_replaced(report, tmp_path):
    _, out, _ = report
    assert check_report_target(out) is True
    assert check_report_target(tmp_path / "new") is False
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    with pytest.raises(OutputExistsError, match="not an earlier chronocl bench report"):
        check_report_target(tmp_path / "other")


def test_help_has_an_example():
    code, stdout, _ = run_main("bench", "--help")
    assert code == 0
    assert "chronocl bench --synthetic 128" in stdout and "--scheduler" in stdout


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    path = tmp_path_factory.mktemp("bench-store") / "s.zarr"
    data = np.random.default_rng(1).random((3, 8, 8, 8), dtype=np.float32)
    write_series(path, iter(data), n_steps=3, volume_shape=(8, 8, 8), dtype="float32")
    return path


BAD = {
    "unknown device": (["--synthetic", "16", "--devices", "no-such-device"], "no OpenCL device"),
    "workers below 1": (["--synthetic", "16", "--workers", "0,2"], "--workers '0,2' must be"),
    "missing store": (["{tmp}/missing.zarr"], "does not exist"),
    "output not a report": (["--synthetic", "16"], "is not an earlier chronocl bench report"),
    "window beyond the steps": (["{store}", "--windows", "2,4"], "the series has 3"),
    "too many workers": (["{store}", "--windows", "2", "--workers", "1,16"], "up to 8"),
    "store and synthetic": (["{store}", "--synthetic", "16"], "one of the two"),
    "bad size": (["--synthetic", "16x16"], "must be N or NXxNYxNZ"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_line(case, store, tmp_path):
    args, needle = BAD[case]
    args = [a.format(tmp=tmp_path, store=store) for a in args]
    out = tmp_path / "report"
    if case == "output not a report":
        out.mkdir()
        (out / "mine.txt").write_text("keep")
    code, _, stderr = run_main("bench", *args, "-o", out)
    assert code == 2
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("chronocl: error:"), lines
    assert needle in lines[0]
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == (["report"] if case == "output not a report" else [])
    if case == "output not a report":
        assert [p.name for p in out.iterdir()] == ["mine.txt"]


def test_a_scheduler_cluster(tmp_path):
    """--scheduler: the cluster's workers run the cells, the roofline is measured on one of
    them, and asking for more workers than it has is one line before any work."""
    from distributed import LocalCluster

    from chronocl.core.errors import InvalidParameterError
    from chronocl.report.scaling_run import run_report

    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        address = cluster.scheduler_address
        out = tmp_path / "report"
        with pytest.raises(InvalidParameterError, match="has 1 workers"):
            run_report(out, size_xyz=(16, 16, 8), windows=(2,), workers=(1, 2), scheduler=address)
        assert list(tmp_path.iterdir()) == []
        report = run_report(out, size_xyz=(16, 16, 8), windows=(2,), repeats=1, scheduler=address)
    assert report["cluster"]["kind"] == "scheduler" and report["cluster"]["address"] == address
    assert report["parameters"]["workers"] == [1]  # the default: the cluster's workers
    assert report["roofline"]["where"].startswith("worker ")  # not this process
    assert [c["study"] for c in report["cells"]] == ["strong", "weak"]
    assert all(c["gvox_steps_s"] > 0 for c in report["cells"])
    assert json.loads((out / "report.json").read_text())["cells"] == report["cells"]
