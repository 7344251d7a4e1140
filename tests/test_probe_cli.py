"""Probes outside the viewer: `probe(series, ...)` (a voxel, a box) and `chronocl probe`.

Values equal numpy on the series (points and boxes, odd shapes, boxes at the edges, stores
chunked along z and arrays in memory); only the probed chunks are read; damaged chunks are
StoreCorruptError; the time labels reach the curve, the CSV and the plot's axis; the PNG is
not blank; and every refusal of the CLI is one line, exit 2, before anything is written.
"""

from __future__ import annotations

import csv
import io
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from chronocl.core.errors import InvalidParameterError, InvalidSelectionError, StoreCorruptError
from chronocl.core.tuning import TUNING
from chronocl.data.integrity import CheckedStore
from chronocl.data.probe import probe
from chronocl.data.series import TimeSeries, open_series, write_series

from .bad_input import digest
from .strategies import examples

SHAPE = (9, 10, 11)  # Z, Y, X: three stored chunks of 4, 4 and 1 rows per step
STEPS = 7
TIMES = tuple(f"2024-05-0{1 + i // 4}T{6 * (i % 4):02d}:00" for i in range(STEPS))


def _values() -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.normal(size=(STEPS, *SHAPE)).astype(np.float32)


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("probe") / "s.zarr"
    write_series(
        path,
        iter(_values()),
        n_steps=STEPS,
        volume_shape=SHAPE,
        dtype="float32",
        times=TIMES,
        chunk_bytes=4 * SHAPE[1] * SHAPE[2] * 4,
    )
    return path


@pytest.fixture(scope="module")
def series(base) -> TimeSeries:
    return open_series(base)


@pytest.fixture
def store(base, tmp_path) -> Path:
    """A private copy of the store in its own folder."""
    import shutil

    copy = tmp_path / "in" / "s.zarr"
    shutil.copytree(base, copy)
    return copy


def _box_stats(a: np.ndarray, box) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    (x0, x1), (y0, y1), (z0, z1) = box
    block = a[:, z0:z1, y0:y1, x0:x1].astype(np.float64)
    return block.mean(axis=(1, 2, 3)), block.min(axis=(1, 2, 3)), block.max(axis=(1, 2, 3))


# -- values ------------------------------------------------------------------------------------
@settings(max_examples=examples(20))
@given(st.data())
def test_store_probe_equals_numpy(series, data):
    a = _values()
    nz, ny, nx = SHAPE
    x = data.draw(st.integers(0, nx - 1))
    y = data.draw(st.integers(0, ny - 1))
    z = data.draw(st.integers(0, nz - 1))
    curve = probe(series, x, y, z)
    np.testing.assert_array_equal(curve.values, a[:, z, y, x].astype(np.float64))
    assert curve.point == (x, y, z) and curve.min is None and curve.mean is None

    box = []
    for n in (nx, ny, nz):
        lo = data.draw(st.integers(0, n - 1))
        box.append((lo, data.draw(st.integers(lo + 1, n))))
    curve = probe(series, region=box)
    mean, lo, hi = _box_stats(a, box)
    np.testing.assert_allclose(curve.values, mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(curve.min, lo)
    np.testing.assert_array_equal(curve.max, hi)
    assert curve.box == tuple(box) and curve.mean is curve.values


@settings(max_examples=examples(15))
@given(
    shape=st.tuples(*(st.integers(1, 6) for _ in range(4))),
    dtype=st.sampled_from(["uint8", "int16", "float32", "float64"]),
    data=st.data(),
)
def test_in_memory_probe_equals_numpy(shape, dtype, data):
    rng = np.random.default_rng(sum(shape))
    a = (rng.random(shape) * 100).astype(dtype)
    s = TimeSeries.from_array(a)
    _, nz, ny, nx = shape
    x, y, z = (data.draw(st.integers(0, n - 1)) for n in (nx, ny, nz))
    np.testing.assert_array_equal(probe(s, x, y, z).values, a[:, z, y, x].astype(np.float64))
    box = [(data.draw(st.integers(0, n - 1)), None) for n in (nx, ny, nz)]  # to the far edges
    curve = probe(s, region=[slice(lo, hi) for lo, hi in box])
    mean, lo, hi = _box_stats(a, [(lo, n) for (lo, _), n in zip(box, (nx, ny, nz), strict=True)])
    np.testing.assert_allclose(curve.values, mean, rtol=1e-12)
    np.testing.assert_array_equal(curve.min, lo)
    np.testing.assert_array_equal(curve.max, hi)
    assert list(curve.steps) == list(range(shape[0])) and curve.times == tuple(range(shape[0]))


def test_box_forms_and_edges(series):
    a = _values()
    whole = probe(series, region=":,:,:")
    np.testing.assert_allclose(whole.values, a.mean(axis=(1, 2, 3), dtype=np.float64), rtol=1e-12)
    np.testing.assert_array_equal(whole.max, a.max(axis=(1, 2, 3)))
    corner = probe(series, region="10:11,9:,8:9")  # the last voxel alone
    np.testing.assert_array_equal(corner.values, a[:, 8, 9, 10])
    np.testing.assert_array_equal(corner.min, corner.max)
    plane = probe(series, region=(slice(None), (2, 5), 0))  # slice, pair, one index
    mean, _, _ = _box_stats(a, [(0, 11), (2, 5), (0, 1)])
    np.testing.assert_allclose(plane.values, mean, rtol=1e-12)
    assert plane.describe() == "box x 0:11, y 2:5, z 0:1 (33 voxels)"


def test_time_labels_reach_the_curve(series):
    curve = probe(series, 1, 2, 3)
    assert curve.times == TIMES
    assert list(curve.steps) == list(range(STEPS))
    assert len(curve) == STEPS


def test_only_the_probed_chunks_are_read(series, monkeypatch):
    """A voxel in the last z chunk reads that chunk of each step, never the others."""
    keys: list[str] = []
    get = CheckedStore.get

    async def spy(self, key, *args, **kwargs):
        keys.append(key)
        return await get(self, key, *args, **kwargs)

    monkeypatch.setattr(CheckedStore, "get", spy)
    probe(series, 4, 5, 8)
    chunks = sorted(k for k in keys if k.startswith("data/c/"))
    assert chunks == [f"data/c/{t}/2/0/0" for t in range(STEPS)]
    keys.clear()
    probe(series, region="0:3,0:3,3:5")  # rows 3 and 4: chunks 0 and 1 of each step
    chunks = sorted(k for k in keys if k.startswith("data/c/"))
    assert chunks == sorted(f"data/c/{t}/{c}/0/0" for t in range(STEPS) for c in (0, 1))


def test_damaged_chunk_is_an_error_not_zeros(store):
    (store / "data" / "c" / "3" / "2" / "0" / "0").write_bytes(b"\x00garbage" * 40)
    s = open_series(store)
    with pytest.raises(StoreCorruptError, match="step 3"):
        probe(s, 0, 0, 8)
    with pytest.raises(StoreCorruptError, match="step 3"):
        probe(s, region=":,:,7:9")
    np.testing.assert_array_equal(probe(s, 0, 0, 0).values, _values()[:, 0, 0, 0])  # elsewhere


def test_missing_chunk_is_an_error(store):
    (store / "data" / "c" / "5" / "0" / "0" / "0").unlink()
    with pytest.raises(StoreCorruptError, match="missing"):
        probe(open_series(store), 1, 1, 1)


@pytest.mark.parametrize(
    ("args", "kwargs", "needle"),
    [
        ((11, 0, 0), {}, "x=11 is outside the volume's 11 voxels along x"),
        ((0, -1, 0), {}, "y=-1 is outside"),
        ((0, 0, 9), {}, "choose 0 <= z <= 8"),
        ((0, 0), {}, "lacks z"),
        ((1.5, 0, 0), {}, "is not a voxel index"),
        ((True, 0, 0), {}, "is not a voxel index"),
        ((1, 2, 3), {"region": ":,:,:"}, "not both"),
        ((), {"region": "0:12,:,:"}, "x range 0:12 does not fit"),
        ((), {"region": "3:3,:,:"}, "x range 3:3 does not fit"),
        ((), {"region": ":,:,-1:2"}, "z range -1:2"),
        ((), {"region": "0:2,0:2"}, "must be three ranges"),
        ((), {"region": "a:b,:,:"}, "must be three ranges"),
        ((), {"region": [slice(0, 4, 2), 0, 0]}, "has a step"),
        ((), {"region": [0, 0]}, "must give x, y and z"),
        ((), {"region": [0.5, 0, 0]}, "must be a slice"),
    ],
)
def test_bad_probes_are_refused(series, args, kwargs, needle):
    with pytest.raises(InvalidParameterError, match=None) as info:
        probe(series, *args, **kwargs)
    assert needle in str(info.value) and "\n" not in str(info.value)
    assert isinstance(info.value, ValueError)


# -- CSV and plot ------------------------------------------------------------------------------
def _rows(text: str) -> list[dict]:
    return list(csv.DictReader(io.StringIO(text)))


def test_csv_of_a_voxel_and_a_box(series, tmp_path):
    a = _values()
    rows = _rows(probe(series, 2, 3, 4).csv_text())
    assert list(rows[0]) == ["step", "time", "value"]
    assert [r["step"] for r in rows] == [str(t) for t in range(STEPS)]
    assert tuple(r["time"] for r in rows) == TIMES
    assert [float(r["value"]) for r in rows] == [float(v) for v in a[:, 4, 3, 2]]  # exact

    curve = probe(series, region="0:5,1:2,6:9")
    path = curve.to_csv(tmp_path / "box.csv", window="2:5")
    rows = _rows(path.read_text())
    assert list(rows[0]) == ["step", "time", "mean", "min", "max", "in_window"]
    mean, lo, hi = _box_stats(a, [(0, 5), (1, 2), (6, 9)])
    assert [float(r["mean"]) for r in rows] == list(curve.values)
    np.testing.assert_allclose([float(r["mean"]) for r in rows], mean, rtol=1e-12)
    assert [float(r["min"]) for r in rows] == list(lo)
    assert [float(r["max"]) for r in rows] == list(hi)
    assert [r["in_window"] for r in rows] == ["0", "0", "1", "1", "1", "0", "0"]
    with pytest.raises(FileExistsError):
        curve.to_csv(path)
    curve.to_csv(path, overwrite=True)


def _pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)


def test_plot_is_a_png_with_the_window_shaded(series, tmp_path):
    curve = probe(series, region="2:9,2:8,1:8")
    path = curve.plot(tmp_path / "box.png", window="1:4")
    px = _pixels(path)
    assert px.shape == (450, 800, 3) and px.std() > 10  # not blank
    shaded = (np.abs(px - [253, 234, 218]) < 6).all(axis=2)  # matplotlib C1 at alpha 0.15
    assert shaded.sum() > 1000
    plain = curve.plot(tmp_path / "plain.png")
    assert not (np.abs(_pixels(plain) - [253, 234, 218]) < 6).all(axis=2).any()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no partial


def _tick_labels(fig) -> list[str]:
    fig.canvas.draw()
    return [t.get_text() for t in fig.axes[0].get_xticklabels() if t.get_text()]


def test_plot_axis_shows_the_time_labels():
    a = np.arange(5 * 2 * 2 * 2, dtype=np.float32).reshape(5, 2, 2, 2)
    named = TimeSeries.from_array(a, times=["spin-up", "t1", "t2", "t3", "end"])
    fig = probe(named, 0, 0, 0).figure(window="1:3")
    assert set(_tick_labels(fig)) <= {"spin-up", "t1", "t2", "t3", "end"}
    assert "spin-up" in _tick_labels(fig) and fig.axes[0].get_xlabel() == "time"
    assert any("window 1:3: t1 to t2" in t.get_text() for t in fig.axes[0].get_legend().get_texts())

    dated = TimeSeries.from_array(a, times=[f"2021-02-0{i + 1}" for i in range(5)])
    fig = probe(dated, region=":,:,:").figure()
    line = fig.axes[0].get_lines()[0]
    assert np.issubdtype(np.asarray(line.get_xdata()).dtype, np.datetime64)
    assert any("Feb" in t or "02" in t for t in _tick_labels(fig))

    numbers = TimeSeries.from_array(a, times=[0.0, 0.5, 2.0, 4.5, 8.0])
    fig = probe(numbers, 1, 1, 1).figure(window="1:4")
    np.testing.assert_array_equal(fig.axes[0].get_lines()[0].get_xdata(), [0, 0.5, 2, 4.5, 8])
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "window 1:4: 0.5 to 4.5" in legend  # the axis's times, not only the steps
    timed = TimeSeries.from_array(a, times=[0.0, 0.5, 2.0, 4.5, 8.0], time_unit="s")
    fig = probe(timed, 1, 1, 1).figure(window="2")
    assert "window 2: 2 s" in [t.get_text() for t in fig.axes[0].get_legend().get_texts()]

    plain = probe(TimeSeries.from_array(a), 1, 1, 1).figure(window="1:3")
    assert plain.axes[0].get_xlabel() == "step"
    assert "window 1:3" in [t.get_text() for t in plain.axes[0].get_legend().get_texts()]


def test_curve_of_one_step_plots(tmp_path):
    s = TimeSeries.from_array(np.ones((1, 2, 3, 4), np.float32))
    path = probe(s, region=":,:,:").plot(tmp_path / "one.png", window="0:1")
    assert _pixels(path).std() > 10


def test_progress_bar_appears_when_slow(series, monkeypatch, capsys):
    monkeypatch.setattr(TUNING, "probe_bar_after_s", -1.0)
    monkeypatch.setattr(TUNING, "probe_steps_per_read", 2)
    curve = probe(series, 3, 3, 3, progress=True)
    assert "probe" in capsys.readouterr().err
    np.testing.assert_array_equal(curve.values, _values()[:, 3, 3, 3])


# -- the command -------------------------------------------------------------------------------
def _run(monkeypatch, capsys, *args) -> tuple[int, str, str]:
    from chronocl.cli import main

    monkeypatch.setattr(sys, "argv", ["chronocl", "probe", *map(str, args)])
    with pytest.raises(SystemExit) as info:
        main()
    captured = capsys.readouterr()
    return info.value.code or 0, captured.out, captured.err


def test_cli_writes_csv_to_stdout_and_files(base, tmp_path, monkeypatch, capsys):
    code, out, _ = _run(monkeypatch, capsys, base, "--at", "2,3,4")
    assert code == 0
    assert _rows(out) == _rows(probe(open_series(base), 2, 3, 4).csv_text())
    code, _, err = _run(monkeypatch, capsys, base, "--box", "0:5,1:2,6:9", "-o", tmp_path / "b.csv")
    assert code == 0 and "wrote" in err
    assert list(_rows((tmp_path / "b.csv").read_text())[0]) == [
        "step",
        "time",
        "mean",
        "min",
        "max",
    ]
    png = tmp_path / "p.png"
    code, _, _ = _run(monkeypatch, capsys, base, "--at", "2,3,4", "-o", png, "--window", "0:7:3")
    assert code == 0 and _pixels(png).std() > 10
    code, _, _ = _run(monkeypatch, capsys, base, "--at", "2,3,4", "-o", png, "--overwrite")
    assert code == 0


BAD = [
    (["--at", "1,2"], "--at '1,2' must be three whole voxel indices"),
    (["--at", "a,b,c"], "must be three whole voxel indices"),
    (["--at", "1.5,2,3"], "must be three whole voxel indices"),
    (["--at", "11,0,0"], "--at x=11 is outside the volume's 11 voxels along x"),
    (["--at", "0,0,-1"], "--at z=-1 is outside"),
    (["--box", "0:5,0:5"], "--box '0:5,0:5' must be three ranges"),
    (["--box", "0:5,0:5,x:y"], "must be three ranges"),
    (["--box", "5:2,0:1,0:1"], "--box x range 5:2 does not fit"),
    (["--box", "0:1,0:11,0:1"], "--box y range 0:11 does not fit"),
    (["--at", "1,1,1", "--box", ":,:,:"], "one of them"),
    ([], "give --at X,Y,Z"),
    (["--at", "1,1,1", "-o", "{o}/curve.txt"], "must end in .csv or .png"),
    (["--at", "1,1,1", "-o", "{o}/curve"], "must end in .csv or .png"),
    (["--at", "1,1,1", "-o", "{o}/old.csv"], "already exists"),
    (["--at", "1,1,1", "-o", "{o}/c.png", "--window", "5:9"], "window 5:9 is outside"),
    (["--at", "1,1,1", "-o", "{o}/c.csv", "--window", "x"], "cannot read time window"),
    (["--at", "1,1,1", "-o", "{o}/old.csv/c.csv"], "not a folder"),
    (["--at", "1,1,1", "-o", "{s}/c.csv"], ""),
]


@pytest.mark.parametrize(("args", "needle"), BAD, ids=[" ".join(a) or "none" for a, _ in BAD])
def test_cli_refusals(store, tmp_path, monkeypatch, capsys, args, needle):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.csv").write_text("kept")
    before = digest(store), digest(out)
    argv = [a.format(o=out, s=store) for a in args]
    code, stdout, err = _run(monkeypatch, capsys, store, *argv)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("chronocl: error:"), err
    assert needle in lines[0] and "Traceback" not in err
    assert stdout == ""
    assert (digest(store), digest(out)) == before


def test_cli_refuses_a_damaged_store_and_writes_nothing(store, tmp_path, monkeypatch, capsys):
    (store / "data" / "c" / "3" / "2" / "0" / "0").write_bytes(b"\x00garbage" * 40)
    for target in ("c.csv", "c.png"):
        code, _, err = _run(monkeypatch, capsys, store, "--at", "0,0,8", "-o", tmp_path / target)
        assert code == 2 and "(step 3) cannot be decoded" in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_cli_missing_store_and_help(tmp_path, monkeypatch, capsys):
    code, _, err = _run(monkeypatch, capsys, tmp_path / "none.zarr", "--at", "1,1,1")
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "none.zarr" in lines[0]
    assert list(tmp_path.iterdir()) == []

    from typer.testing import CliRunner

    from chronocl.cli import app

    help_text = CliRunner().invoke(app, ["probe", "--help"]).output
    assert "Examples:" in help_text and "chronocl probe vortex.zarr --at" in help_text
    assert "--box" in help_text and "--window" in help_text


def test_window_refused_through_the_api(series, tmp_path):
    curve = probe(series, 1, 1, 1)
    with pytest.raises(InvalidSelectionError):
        curve.plot(tmp_path / "c.png", window="3:99")
    with pytest.raises(InvalidParameterError, match=r"must end in \.png"):
        curve.plot(tmp_path / "c.csv")
    assert list(tmp_path.iterdir()) == []
