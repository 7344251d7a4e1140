"""`ingest --time-unit` and `--times-from-meta`: a run's times read from the metadata its
simulation wrote, with their unit, reach the store, `info`, legends, captions, probe plots
and the viewer's data set message."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import chronocl
from chronocl import render
from chronocl.core.errors import ChronoclError, InvalidParameterError
from chronocl.core.times_meta import Cadence, times_from_meta
from chronocl.data.probe import probe
from chronocl.data.probe_plot import time_axis
from chronocl.render.views import describe


def _cli(monkeypatch, *argv: str) -> int:
    from chronocl.cli import main

    monkeypatch.setattr(sys, "argv", ["chronocl", *argv])
    with pytest.raises(SystemExit) as info:
        main()
    return info.value.code or 0


def _npy(tmp_path, n_steps=5):
    data = np.random.default_rng(3).random((n_steps, 4, 5, 6)).astype(np.float32)
    path = tmp_path / "run.npy"
    np.save(path, data)
    return path


def _meta(tmp_path, content) -> str:
    path = tmp_path / "run.json"
    path.write_text(json.dumps(content))
    return str(path)


def test_a_list_of_times_is_found_at_any_depth_with_its_unit(tmp_path):
    got = times_from_meta(
        _meta(tmp_path, {"grid": [4, 5, 6], "output": {"times": [0, 0.5, 2], "time_unit": "ms"}})
    )
    assert got.times == [0, 0.5, 2] and got.unit == "ms"
    assert got.found.endswith("run.json:output.times")


def test_a_time_step_and_an_output_interval_count_the_steps(tmp_path):
    meta = {"solver": {"dt": 0.05, "save_every": 4, "t0": 1.0}, "units": {"time": "s"}}
    got = times_from_meta(_meta(tmp_path, meta))
    assert (got.times.start, got.times.interval) == (1.0, 0.2)
    assert isinstance(got.times, Cadence) and got.unit is None  # units beside, not above
    assert got.times.times(4) == [1.0, 1.2, 1.4, 1.6]  # no 1.2000000000000002
    meta = {"dt": 0.1, "units": {"time": "s"}}
    got = times_from_meta(_meta(tmp_path, meta))
    assert got.times.times(3) == [0.0, 0.1, 0.2] and got.unit == "s"


@pytest.mark.parametrize(
    "content, message",
    [
        ({"a": {"times": [0, 1]}, "b": {"t": [0, 2]}}, "holds 2 lists of times"),
        ({"a": {"dt": 1}, "b": {"dt": 2}}, "holds 2 time steps (a.dt, b.dt)"),
        ({"grid": [4, 5, 6], "name": "smoke"}, "names no times"),
        ({"dt": 0.0}, "output interval of 0; it must be > 0"),
    ],
)
def test_metadata_that_names_no_times_or_several_is_refused(tmp_path, content, message):
    with pytest.raises(InvalidParameterError) as info:
        times_from_meta(_meta(tmp_path, content))
    assert message in str(info.value), info.value
    assert isinstance(info.value, ChronoclError | ValueError)


def test_times_from_meta_end_to_end(tmp_path, monkeypatch, capsys, drawn_text):
    """Ingest with the simulation's metadata: the store keeps the counted times and the unit,
    `info` and the ingest summary say them, and the legend, caption and probe plot show them."""
    store = tmp_path / "s.zarr"
    meta = _meta(tmp_path, {"solver": {"dt": 0.25, "save_every": 2, "time_unit": "s"}})
    args = ["ingest", str(_npy(tmp_path)), "-o", str(store), "--times-from-meta", meta]
    assert _cli(monkeypatch, *args) == 0
    assert "times: 0.0 .. 2.0 s, from " in capsys.readouterr().err
    series = chronocl.open(store)
    assert list(series.times) == [0.0, 0.5, 1.0, 1.5, 2.0] and series.time_unit == "s"
    assert _cli(monkeypatch, "info", str(store)) == 0
    assert "0.0 .. 2.0 s" in capsys.readouterr().out
    cv = chronocl.integrate(series, "1:5", "alpha", engine="numpy")
    assert "0.5 s .. 2 s (4 steps)" in describe(cv)
    drawn_text.clear()
    render(cv, size=(320, 96), legend=True)
    assert {"0.5 s", "1.0 s", "1.5 s", "2.0 s"} <= set(drawn_text), drawn_text
    curve = probe(series, 1, 1, 1)
    assert curve.time_unit == "s"
    assert time_axis(curve.times, curve.steps, unit=curve.time_unit)[1] == "time (s)"


def test_a_unit_makes_times_equal_to_the_step_numbers_times(tmp_path, monkeypatch, drawn_text):
    """Times 0, 1, 2 ... in days are times, not step numbers: the legend says 'days'."""
    store = tmp_path / "s.zarr"
    args = ["ingest", str(_npy(tmp_path, 3)), "-o", str(store), "--times", "0,1,2"]
    assert _cli(monkeypatch, *args, "--time-unit", "days") == 0
    series = chronocl.open(store)
    assert series.time_unit == "days"
    drawn_text.clear()
    render(chronocl.integrate(series, "0:3", "alpha", engine="numpy"), size=(320, 96), legend=True)
    assert {"0 days", "1 days", "2 days"} <= set(drawn_text), drawn_text


def test_the_viewer_and_the_api_carry_the_unit():
    from chronocl.viewer.datasets import Dataset

    data = np.random.default_rng(4).random((3, 4, 4, 4)).astype(np.float32)
    series = chronocl.TimeSeries.from_array(data, times=[0, 0.5, 1], time_unit="h")
    assert Dataset("d", series).info(0)["time_labels"] == ["0 h", "0.5 h", "1 h"]
    with pytest.raises(InvalidParameterError, match="needs the steps' times"):
        chronocl.TimeSeries.from_array(data, time_unit="h")


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--time-unit", "s"], "--time-unit names the unit of the steps' times; give them"),
        (["--times", "0,1,2", "--times-from-meta", "META"], "give --times or --times-from-meta"),
        (["--times-from-meta", "missing.json"], "metadata file 'missing.json' does not exist"),
        (["--times", "0,1,2", "--time-unit", ""], "is not a short unit name"),
        (["--times-from-meta", "META"], "got 2 times for 3 steps; give one time per step ("),
        (["--times-from-meta", "BADUNIT"], "run2.json:times gives the time unit 'seconds, "),
    ],
)
def test_bad_time_options_get_one_line_and_exit_2(tmp_path, monkeypatch, capsys, extra, message):
    store = tmp_path / "s.zarr"
    meta = _meta(tmp_path, {"times": [0, 1]})
    bad_unit = tmp_path / "run2.json"
    bad_unit.write_text(json.dumps({"times": [0, 1, 2], "time_unit": "seconds, roughly"}))
    names = {"META": meta, "BADUNIT": str(bad_unit)}
    extra = [names.get(e, e) for e in extra]
    monkeypatch.chdir(tmp_path)
    code = _cli(monkeypatch, "ingest", str(_npy(tmp_path, 3)), "-o", str(store), *extra)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
    assert not store.exists()


def test_the_metadata_file_and_key_are_named_when_the_count_is_wrong(tmp_path, monkeypatch, capsys):
    store = tmp_path / "s.zarr"
    meta = _meta(tmp_path, {"out": {"t": [0, 1]}})
    args = ["ingest", str(_npy(tmp_path, 3)), "-o", str(store), "--times-from-meta", meta]
    assert _cli(monkeypatch, *args) == 2
    assert "(" + meta + ":out.t)" in capsys.readouterr().err


def test_time_unit_overrides_a_unit_the_metadata_writes_its_own_way(tmp_path, monkeypatch):
    """CF-style 'seconds since ...' is not a unit legends can write after a number; --time-unit
    replaces it, so the file is still usable."""
    store = tmp_path / "s.zarr"
    meta = _meta(tmp_path, {"dt": 0.5, "time_units": "seconds since 2000-01-01 00:00"})
    args = ["ingest", str(_npy(tmp_path, 3)), "-o", str(store), "--times-from-meta", meta]
    assert _cli(monkeypatch, *args, "--time-unit", "s") == 0
    series = chronocl.open(store)
    assert list(series.times) == [0.0, 0.5, 1.0] and series.time_unit == "s"


def test_times_from_meta_is_refused_by_name_for_a_format_with_its_own(
    tmp_path, monkeypatch, capsys
):
    xr = pytest.importorskip("xarray")
    path = tmp_path / "o.nc"
    xr.Dataset({"v": (("time", "z", "y", "x"), np.zeros((2, 2, 2, 2), np.float32))}).to_netcdf(
        path, engine="h5netcdf"
    )
    meta = _meta(tmp_path, {"times": [0, 1], "time_unit": "s"})
    out = tmp_path / "o.zarr"
    code = _cli(monkeypatch, "ingest", str(path), "-o", str(out), "--times-from-meta", meta)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--times-from-meta applies to" in err[0], err


def test_numpy_times_with_a_unit_through_the_python_ingest(tmp_path):
    from chronocl.data.formats.npy import ingest_npy

    series = ingest_npy(
        _npy(tmp_path, 3), tmp_path / "o.zarr", times=np.array([0.0, 0.5, 1.0]), time_unit="s"
    )
    assert list(series.times) == [0.0, 0.5, 1.0] and series.time_unit == "s"
