"""Time labels where a store has them: legends, panel captions, probe plots and the viewer's
data set message show them instead of step numbers, and step numbers on request."""

from __future__ import annotations

import itertools
import json
import math
import sys

import numpy as np
import pytest

import chronocl
from chronocl import render, render_views
from chronocl.core.errors import UnknownNameError
from chronocl.core.time_labels import compact, display_labels, span_text
from chronocl.data.probe import probe
from chronocl.data.probe_plot import time_axis
from chronocl.render.views import describe

TIMES = [f"2024-01-01T{h:02d}:00:00.000000000" for h in range(0, 24, 3)]  # NetCDF-style


@pytest.fixture(scope="module")
def series():
    data = np.random.default_rng(1).random((8, 6, 7, 8)).astype(np.float32)
    return chronocl.TimeSeries.from_array(data, times=TIMES, source="labelled")


@pytest.fixture(scope="module")
def cv(series):
    return chronocl.integrate(series, "1:8:3", "alpha", engine="numpy")


def nice_numbers(texts: list[str]) -> list[float]:
    """The numbers of the first legend among the drawn texts (each panel draws its own),
    checked to be evenly spaced by 1, 2 or 5 times a power of ten (nice-number ticks)."""
    numbers: list[float] = []
    for t in texts:
        try:
            value = float(t)
        except ValueError:
            continue
        if numbers and value <= numbers[-1]:
            break  # the next panel's legend
        numbers.append(value)
    gaps = {round(b - a, 9) for a, b in itertools.pairwise(numbers)}
    assert len(gaps) <= 1, numbers
    for gap in gaps:
        mantissa = gap / 10 ** math.floor(math.log10(gap))
        assert round(mantissa, 6) in (1, 2, 5), numbers
        assert all(abs(n / gap - round(n / gap)) < 1e-6 for n in numbers), numbers
    return numbers


def test_display_labels():
    assert display_labels([0, 1], TIMES[:2]) == ["2024-01-01 00:00", "2024-01-01 03:00"]
    midnights = ["2024-01-01T00:00:00", "2024-01-02T00:00:00"]
    assert display_labels([0, 1], midnights) == ["2024-01-01", "2024-01-02"]
    assert display_labels([4, 5], [0.25, 1.0]) == ["0.25", "1"]  # physical times
    assert display_labels([0, 1], [0, 1]) == ["0", "1"]  # a store without labels
    assert display_labels([2, 5], TIMES[2:6:3], "steps") == ["2", "5"]
    assert display_labels([0, 1], ["2024-01-01T06:00:30.500", "spin-up"]) == [
        "2024-01-01 06:00:30.5",
        "spin-up",
    ]
    texts = display_labels([1, 2, 7], [TIMES[1], TIMES[2], "2024-01-02T03:00"])
    assert compact(texts) == ["2024-01-01 03:00", "06:00", "2024-01-02 03:00"]
    assert span_text(texts[:2]) == "2024-01-01 03:00 .. 06:00"
    with pytest.raises(UnknownNameError, match=r"choose labels .* or steps"):
        display_labels([0], [0], "dates")


def test_the_legend_and_captions_show_the_time_labels(cv, drawn_text):
    render(cv, size=(240, 96), legend=True)
    assert "2024-01-01 03:00" in drawn_text and "06:00" not in drawn_text  # steps 1, 4, 7
    assert "12:00" in drawn_text and "21:00" in drawn_text
    assert not {"1", "4", "7"} & set(drawn_text)
    drawn_text.clear()
    render_views([cv, cv], size=(240, 96))
    caption = "alpha, forward, 2024-01-01 03:00 .. 21:00 (3 steps)"
    drawn = [" ".join(t.split("\n")) for t in drawn_text]  # wrapped onto lines in a narrow panel
    assert drawn.count(caption) == 2 and describe(cv) == caption


def test_step_numbers_on_request(cv, drawn_text):
    render_views([cv, cv], size=(240, 96), time_labels="steps")
    assert nice_numbers(drawn_text) == [2, 4, 6]  # steps 1, 4, 7: 1-2-5 ticks
    assert "alpha, forward, steps 1:8:3" in drawn_text
    assert not any("2024" in t for t in drawn_text)
    with pytest.raises(UnknownNameError, match="time labels 'dates'"):
        render(cv, time_labels="dates")


def test_a_store_without_labels_shows_step_numbers(series, drawn_text):
    plain = chronocl.TimeSeries.from_array(np.asarray(series.data), source="plain")
    render(chronocl.integrate(plain, "1:8:3", "alpha", engine="numpy"), legend=True)
    assert nice_numbers(drawn_text) == [2, 4, 6]  # steps 1, 4, 7: 1-2-5 ticks


def test_probe_plots_and_the_viewer_use_the_labels(series):
    from chronocl.viewer.datasets import Dataset

    steps = np.arange(8)
    odd = ["spin-up", *TIMES[1:]]  # not all dates: ticks named by the display labels
    _, title, names = time_axis(odd, steps)
    assert title == "time" and names[:2] == ["spin-up", "2024-01-01 03:00"]
    assert time_axis(odd, steps, "steps")[1:] == ("step", None)
    assert time_axis(TIMES, steps)[0].dtype.kind == "M"  # dates: a date axis
    curve = probe(series, 1, 2, 3)
    assert curve.figure(time_labels="steps").axes[0].get_xlabel() == "step"
    assert curve.figure().axes[0].get_xlabel() == "time"
    info = Dataset("labelled", series).info(0)
    assert info["time_labels"] == display_labels(range(8), TIMES)
    assert (
        Dataset("p", chronocl.TimeSeries.from_array(np.zeros((2, 2, 2, 2)))).info(0)["time_labels"]
        is None
    )


def test_cli_time_labels(tmp_path, series, monkeypatch, capsys, drawn_text):
    from chronocl.cli import main

    store = tmp_path / "l.zarr"
    series.save(store)

    def run(*args: str) -> int:
        argv = ["chronocl", "render", str(store), "--engine", "numpy", "--size", "160x64"]
        monkeypatch.setattr(sys, "argv", [*argv, "--window", "1:8:3", *args])
        with pytest.raises(SystemExit) as info:
            main()
        return info.value.code or 0

    assert run("-o", str(tmp_path / "a.png")) == 0
    assert "2024-01-01 03:00" in drawn_text
    drawn_text.clear()
    assert run("-o", str(tmp_path / "b.png"), "--time-labels", "steps") == 0
    assert nice_numbers(drawn_text) == [2, 4, 6]  # steps 1, 4, 7: 1-2-5 ticks
    capsys.readouterr()
    assert run("-o", str(tmp_path / "c.png"), "--time-labels", "dates") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "choose labels" in err[0] and not (tmp_path / "c.png").exists()


def _cli(monkeypatch, *argv: str) -> int:
    from chronocl.cli import main

    monkeypatch.setattr(sys, "argv", ["chronocl", *argv])
    with pytest.raises(SystemExit) as info:
        main()
    return info.value.code or 0


@pytest.mark.parametrize("form", ["list", "lines", "json", "json-key"])
def test_ingest_times_reach_the_store_and_the_legend(tmp_path, monkeypatch, drawn_text, form):
    """`ingest --times` in each form gives raw steps their physical times, which the store
    keeps and the rendered legend shows instead of step numbers."""
    data = np.random.default_rng(2).random((4, 5, 6, 7)).astype(np.float32)
    files = []
    for t, step in enumerate(data):
        files.append(tmp_path / f"s{t}.raw")
        step.tofile(files[-1])
    times = [0, 0.25, 0.5, 1.75]
    value = {
        "list": "0,0.25,0.5,1.75",
        "lines": tmp_path / "times.txt",
        "json": tmp_path / "times.json",
        "json-key": f"{tmp_path / 'meta.json'}:run.times",
    }[form]
    (tmp_path / "times.txt").write_text("# time in s\n0\n0.25\n\n0.5\n1.75\n")
    (tmp_path / "times.json").write_text(json.dumps(times))
    (tmp_path / "meta.json").write_text(json.dumps({"run": {"times": times, "dt": 0.25}}))
    store = tmp_path / "s.zarr"
    args = ["ingest", *map(str, files), "-o", str(store), "--dims", "7", "6", "5"]
    assert _cli(monkeypatch, *args, "--times", str(value)) == 0
    series = chronocl.open(store)
    assert list(series.times) == times and isinstance(series.times[0], int)
    drawn_text.clear()
    render(chronocl.integrate(series, "0:4", "alpha", engine="numpy"), size=(240, 96), legend=True)
    assert nice_numbers(drawn_text) == [0, 0.5, 1, 1.5]  # times 0 .. 1.75, not step numbers


def test_a_long_comma_list_of_times_is_read_as_times():
    """A list longer than a file name may be (255 bytes) is still a list, not an OS error."""
    from chronocl.core.times_input import read_times

    times = [round(0.123456 * t, 6) for t in range(200)]
    assert read_times(",".join(map(str, times))) == times


@pytest.mark.parametrize(
    "value, message",
    [
        ("0,0.5,1", "got 3 times for 4 steps; give one time per step"),
        ("0,,1,2", "empty time"),
        ("0,nan,1,2", "must be finite"),
        ("missing/times.txt", "times file 'missing/times.txt' does not exist"),
        ("META:nope", "has no key 'nope' (keys: run)"),
        ("META", "is a JSON object; name the list of times in it"),
        ("META:run.dt", "is not a list of times"),
    ],
)
def test_bad_ingest_times_get_one_line_and_exit_2(tmp_path, monkeypatch, capsys, value, message):
    step = np.zeros((2, 2, 2), np.float32)
    files = [tmp_path / f"s{t}.raw" for t in range(4)]
    for f in files:
        step.tofile(f)
    meta = tmp_path / "meta.json"
    meta.write_text(json.dumps({"run": {"times": [0, 1, 2, 3], "dt": 1}}))
    store = tmp_path / "s.zarr"
    args = ["ingest", *map(str, files), "-o", str(store), "--dims", "2", "2", "2"]
    code = _cli(monkeypatch, *args, "--times", value.replace("META", str(meta)))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
    assert not store.exists()


def test_times_are_refused_for_a_format_with_its_own(tmp_path, monkeypatch, capsys):
    xr = pytest.importorskip("xarray")
    path = tmp_path / "o.nc"
    xr.Dataset({"v": (("time", "z", "y", "x"), np.zeros((2, 2, 2, 2), np.float32))}).to_netcdf(
        path, engine="h5netcdf"
    )
    code = _cli(monkeypatch, "ingest", str(path), "-o", str(tmp_path / "o.zarr"), "--times", "0,1")
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--times applies to" in err[0], err


@pytest.mark.parametrize(
    "lo, hi, most, integer, ticks",
    [
        (3, 27, 6, True, [5, 10, 15, 20, 25]),  # not 2 8 16 26
        (0, 0.83, 6, False, [0, 0.2, 0.4, 0.6, 0.8]),
        (100, 1000, 5, False, [200, 400, 600, 800, 1000]),  # not 100 300 500 700 1000
        (0, 1.75, 4, False, [0, 0.5, 1, 1.5]),
        (0, 2, 10, True, [0, 1, 2]),  # steps: never 0.5
        (5, 5, 3, True, [5]),
        (-0.3, 0.3, 4, False, [-0.2, 0, 0.2]),
    ],
)
def test_nice_number_ticks(lo, hi, most, integer, ticks):
    from chronocl.core.ticks import nice_step, nice_ticks, tick_text

    got = nice_ticks(lo, hi, most, integer)
    assert got == pytest.approx(ticks) and len(got) <= most
    step = nice_step(lo, hi, most, integer)
    assert [float(tick_text(t, step)) for t in got] == pytest.approx(ticks)


@pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")  # random data
def test_a_long_window_gets_regular_ticks(drawn_text):
    data = np.random.default_rng(3).random((300, 4, 5, 6)).astype(np.float32)
    cv = chronocl.integrate(chronocl.TimeSeries.from_array(data), "7:293", "max", engine="numpy")
    render(cv, size=(640, 96), legend=True)
    numbers = nice_numbers(drawn_text)
    assert 3 <= len(numbers) <= 20 and 7 <= numbers[0] and numbers[-1] <= 292
