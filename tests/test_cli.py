"""The command line: help with examples, the commands end to end, one-line errors with exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import chronocl
from chronocl import modes

from . import cli_process


def cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    """`python -m chronocl *args`, its output captured (tests/cli_process.py)."""
    return cli_process.run(list(args), cwd=cwd)


def assert_one_line_error(result: subprocess.CompletedProcess, needle: str) -> None:
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("chronocl: error:") and needle in lines[0], lines[0]
    assert "Traceback" not in result.stderr


def test_help_has_examples():
    """`chronocl --help` from a fresh process; the commands' helps in this one (each fresh
    process costs seconds of imports)."""
    from typer.testing import CliRunner

    from chronocl.cli import app

    result = cli_process.run(["--help"], own_process=True)
    assert result.returncode == 0 and "Examples" in result.stdout
    for command in ("generate", "ingest", "info", "integrate"):
        sub = CliRunner().invoke(app, [command, "--help"])
        assert sub.exit_code == 0 and "chronocl " + command in sub.output


def test_generate_info_integrate(tmp_path):
    store = tmp_path / "v.zarr"
    result = cli("generate", "vortex", store, "--shape", "12x10x8", "--steps", "6")
    assert result.returncode == 0, result.stderr
    series = chronocl.open(store)
    assert series.shape == (6, 8, 10, 12)
    info = cli("info", store, "--json")
    assert info.returncode == 0
    assert json.loads(info.stdout)["shape (T, Z, Y, X)"] == [6, 8, 10, 12]
    out = tmp_path / "cv.zarr"
    result = cli("integrate", store, out, "--mode", "max", "--window", "0:6:2", "--order", "4,0,2")
    assert result.returncode == 0, result.stderr
    cv = chronocl.Chronovolume.load(out)
    expected = chronocl.integrate(series, "0:6:2", "max", order=(4, 0, 2))
    np.testing.assert_array_equal(cv.rgba, expected.rgba)
    np.testing.assert_array_equal(cv.t_index, expected.t_index)
    assert cli("info", out).returncode == 0


def test_ingest_command(tmp_path):
    data = np.arange(2 * 60, dtype=np.uint8).reshape(2, 5, 4, 3)
    for t in range(2):
        data[t].tofile(tmp_path / f"s{t}.raw")
    result = cli(
        "ingest",
        tmp_path / "s*.raw",
        "-o",
        tmp_path / "s.zarr",
        "--dims",
        3,
        4,
        5,
        "--dtype",
        "uint8",
        "--spacing",
        1,
        1,
        2,
    )
    assert result.returncode == 0, result.stderr
    series = chronocl.open(tmp_path / "s.zarr")
    np.testing.assert_array_equal(series.read([0, 1]), data)
    assert series.spacing == (1, 1, 2)  # --spacing DX DY DZ, x first


@pytest.fixture(scope="module")
def small_store(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "s.zarr"
    chronocl.TimeSeries.from_array(np.random.default_rng(0).random((5, 3, 4, 5))).save(path)
    return path


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["integrate", "{s}", "{tmp}/o.zarr", "--window", "0:9"], "outside the series"),
        (["integrate", "{s}", "{tmp}/o.zarr", "--window", "0:5:0"], "stride must be at least 1"),
        (["integrate", "{s}", "{tmp}/o.zarr", "--mode", "sum"], "unknown mode 'sum'"),
        (["integrate", "{s}", "{tmp}/o.zarr", "--order", "sideways"], "unknown order"),
        (["integrate", "{s}", "{tmp}/o.zarr", "--time-tf", "rainbow"], "unknown time TF preset"),
        (["integrate", "{s}", "{tmp}/o.zarr", "--tf", "{tmp}/bad.json"], "sorted"),
        (["integrate", "{s}", "{s}"], "is the input"),
        (["integrate", "{s}", "{tmp}/bad.json"], "cannot tell the chronovolume format"),
        (["integrate", "{tmp}/none.zarr", "{tmp}/o.zarr"], "does not exist"),
        (["generate", "tornado", "{tmp}/o.zarr"], "tornado"),
        (["generate", "jet", "{tmp}/o.zarr", "--shape", "8x8"], "NXxNYxNZ"),
        (
            ["ingest", "{tmp}/*.nothing", "-o", "{tmp}/o.zarr", "--dims", "2", "2", "2"],
            "no files match",
        ),
        (["ingest", "{tmp}/bad.json", "-o", "{tmp}/o.zarr", "--dims", "2", "2", "2"], "needs 32"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, small_store, args, needle):
    (tmp_path / "bad.json").write_text(
        '{"data_tf": {"points": [[0.5, 1, 1, 1, 0], [0.2, 1, 1, 1, 1]]}}'
    )
    argv = [a.format(s=small_store, tmp=tmp_path) for a in args]
    assert_one_line_error(cli(*argv), needle)
    assert not (tmp_path / "o.zarr").exists()
    assert not [p for p in tmp_path.iterdir() if ".partial-" in p.name]


def test_usage_errors_exit_2():
    result = cli("integrate")
    assert result.returncode == 2 and "Traceback" not in result.stderr


def test_verbose_flag_sets_the_environment(monkeypatch, small_store, capsys):
    import os

    from chronocl.cli import main

    monkeypatch.delenv("CHRONOCL_VERBOSE", raising=False)
    monkeypatch.setattr(sys, "argv", ["chronocl", "--verbose", "info", str(small_store)])
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code == 0
    assert os.environ.get("CHRONOCL_VERBOSE") == "1"
    assert "shape" in capsys.readouterr().out


def test_an_os_error_past_the_checks_is_one_line(monkeypatch, small_store, tmp_path, capsys):
    """A folder that stops taking files after the checks (simulated by skipping them)."""
    import chronocl.core.paths
    from chronocl.cli import main

    monkeypatch.setattr(chronocl.core.paths, "check_writable", lambda path: None)
    (tmp_path / "f").write_text("a file, not a folder")
    out = tmp_path / "f" / "o.zarr"
    argv = ["chronocl", "integrate", str(small_store), str(out), "--engine", "numpy"]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code == 2
    stderr = capsys.readouterr().err  # the finished progress bar, then the error
    errors = [line for line in stderr.splitlines() if line.startswith("chronocl: error: ")]
    assert len(errors) == 1 and stderr.rstrip().endswith(errors[0]), stderr
    assert str(tmp_path / "f") in errors[0] and "Traceback" not in stderr


def test_the_mode_lists_come_from_the_registry():
    from typer.testing import CliRunner

    from chronocl.cli import app

    names = modes.names()
    helps = {}
    for command in ("integrate", "render"):
        result = CliRunner().invoke(app, [command, "--help"])
        assert result.exit_code == 0, result.output
        helps[command] = " ".join(result.output.split()).replace("- ", "-")
        assert f"{', '.join(names[:-1])} or {names[-1]}" in helps[command]
    for name in names:  # the integrate help's Modes section: each name with its summary
        assert f"{name} {' '.join(modes.get(name).summary.split())}" in helps["integrate"]
    assert "Examples:" in helps["integrate"]


@pytest.mark.parametrize("mode", modes.names())
def test_every_registered_mode_integrates(monkeypatch, small_store, tmp_path, mode):
    from chronocl.cli import main

    out = tmp_path / f"{mode}.zarr"
    argv = ["chronocl", "integrate", str(small_store), str(out), "--mode", mode]
    monkeypatch.setattr(sys, "argv", [*argv, "--window", "0:5:2", "--engine", "numpy"])
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code in (0, None)
    cv = chronocl.Chronovolume.load(out)
    expected = chronocl.integrate(chronocl.open(small_store), "0:5:2", mode, engine="numpy")
    np.testing.assert_array_equal(cv.rgba, expected.rgba)


def test_plan_run_picks_where_the_integration_runs(small_store, tmp_path):
    from chronocl.core.errors import InvalidParameterError
    from chronocl.integration.runs.auto import DASK, IN_MEMORY, STREAMED, plan_run

    series = chronocl.open(small_store)
    assert plan_run(series, None, tmp_path / "a.vti").where == IN_MEMORY
    tight = plan_run(series, None, tmp_path / "a.zarr", memory=1000)
    assert tight.where == STREAMED and tight.streamed
    with pytest.raises(InvalidParameterError, match="needs more than --memory 1000"):
        plan_run(series, None, tmp_path / "a.vti", memory=1000)
    assert plan_run(series, None, tmp_path / "a.zarr", workers=2).where == DASK
    assert not list(tmp_path.iterdir())  # planning writes nothing
