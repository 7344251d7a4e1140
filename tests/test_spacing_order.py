"""One axis order, x first, in every public triple: spacing, dims, probe points and boxes.

A simulation's [dx, dy, dz] goes into `TimeSeries.from_array(spacing=...)` as it is and into
`chronocl ingest --spacing DX DY DZ` as it is; both give the same store, the same `info` and
the same picture. Arrays alone keep numpy's (T, Z, Y, X) order.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
import zarr
from PIL import Image as PILImage

import chronocl
from chronocl import Camera, render
from chronocl.core.errors import ChronoclError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.probe import probe

T, Z, Y, X = 4, 6, 10, 14  # every axis its own size, so no transposition goes unseen
SPACING = (1.0, 2.0, 4.0)  # (dx, dy, dz)
DIMS = (X, Y, Z)


def blob() -> np.ndarray:
    """(T, Z, Y, X) float32: a blob off every axis' centre (x 3/4, y 1/3, z 1/4) growing over
    time, so that a swapped axis or spacing changes the picture."""
    z, y, x = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in (Z, Y, X)), indexing="ij")
    steps = []
    for t in range(T):
        r2 = (
            ((x - 0.75 * X) / (2 + t)) ** 2
            + ((y - Y / 3) / (1.5 + t / 2)) ** 2
            + ((z - Z / 4) / (1 + t / 3)) ** 2
        )
        steps.append(np.exp(-r2))
    return np.stack(steps).astype(np.float32)


def run_cli(monkeypatch, capsys, *args) -> str:
    """`chronocl ARGS` in this process; its stdout (it must succeed)."""
    from chronocl.cli import main

    monkeypatch.setattr(sys, "argv", ["chronocl", *map(str, args)])
    with pytest.raises(SystemExit) as info:
        main()
    captured = capsys.readouterr()
    assert (info.value.code or 0) == 0, captured.err
    return captured.out


def pixels(path) -> np.ndarray:
    with PILImage.open(path) as im:
        return np.asarray(im.convert("RGBA"))


@pytest.fixture
def stores(tmp_path, monkeypatch, capsys):
    """The same steps with spacing (1, 2, 4) through the API and through the command line,
    and with that triple reversed (4, 2, 1) through the API; each store named s.zarr."""
    data = blob()
    npy = tmp_path / "steps.npy"
    np.save(npy, data)
    source = f"npy: {npy}"  # what ingest records, so that `info` can match in full
    api = chronocl.TimeSeries.from_array(data, spacing=SPACING, source=source)
    api.save(tmp_path / "api" / "s.zarr")
    out = tmp_path / "cli" / "s.zarr"
    run_cli(monkeypatch, capsys, "ingest", npy, "-o", out, "--spacing", *SPACING)
    reversed_ = chronocl.TimeSeries.from_array(data, spacing=SPACING[::-1], source=source)
    reversed_.save(tmp_path / "reversed" / "s.zarr")
    return {name: tmp_path / name / "s.zarr" for name in ("api", "cli", "reversed")}


def test_api_and_cli_spacing_give_the_same_store_info_and_picture(stores, monkeypatch, capsys):
    # The same stored spacing, by axis name.
    for name in ("api", "cli"):
        attrs = zarr.open_group(str(stores[name]), mode="r").attrs["chronocl"]
        assert attrs["spacing"] == {"x": 1.0, "y": 2.0, "z": 4.0}, name
        series = chronocl.open(stores[name])
        assert series.spacing == SPACING and series.dims == DIMS
    # The same `info`, in JSON and as text (the stores' folders aside).
    infos = {
        n: json.loads(run_cli(monkeypatch, capsys, "info", stores[n], "--json")) for n in stores
    }
    for info in infos.values():
        info.pop("path")
    assert infos["api"] == infos["cli"]
    assert infos["api"]["spacing (x, y, z)"] == list(SPACING)
    assert infos["api"]["dims (x, y, z)"] == list(DIMS)
    assert infos["reversed"]["spacing (x, y, z)"] == list(SPACING[::-1])
    texts = {
        n: run_cli(monkeypatch, capsys, "info", stores[n]).replace(str(stores[n].parent), "DIR")
        for n in ("api", "cli")
    }
    assert texts["api"] == texts["cli"]
    line = next(s for s in texts["api"].splitlines() if s.startswith("spacing (x, y, z)"))
    assert line.split(None, 4)[-1] == "[1.0, 2.0, 4.0]"
    # The same picture; the reversed spacing draws another (the spacing reaches the picture).
    shots = {}
    for name, store in stores.items():
        png = store.parent / "s.png"
        run_cli(monkeypatch, capsys, "render", store, "-o", png, "--engine", "numpy")
        shots[name] = pixels(png)
    np.testing.assert_array_equal(shots["api"], shots["cli"])
    assert shots["api"].shape == shots["reversed"].shape
    assert (shots["api"] != shots["reversed"]).any(axis=-1).mean() > 0.01


def test_an_in_memory_series_draws_what_its_ingested_store_draws(stores):
    memory = chronocl.TimeSeries.from_array(blob(), spacing=SPACING)
    stored = chronocl.open(stores["cli"])
    pictures = [
        render(chronocl.integrate(s, "0:4", "alpha", engine="numpy"), size=(80, 80), jitter=False)
        for s in (memory, stored)
    ]
    np.testing.assert_array_equal(pictures[0].array, pictures[1].array)


def drawn_aspect(cv: Chronovolume, azimuth: float) -> float:
    """Width / height of the drawn box of an opaque `cv`, seen orthographically along an axis."""
    camera = Camera(azimuth=azimuth, elevation=0.0, projection="orthographic", frame="box")
    image = render(cv, camera, (240, 240), jitter=False, nearest=True).array
    ys, xs = np.nonzero(image[..., :3].max(axis=2) > 64)
    return (xs.max() - xs.min() + 1) / (ys.max() - ys.min() + 1)


def test_the_spacing_given_x_first_is_the_shape_drawn():
    """An opaque box of 14 x 10 x 6 voxels with spacing (1, 2, 4) is 14 x 20 x 24 units: seen
    along z it is 14 wide and 20 high, along x 24 wide and 20 high."""
    series = chronocl.TimeSeries.from_array(blob(), spacing=SPACING)
    cv = chronocl.integrate(series, "0:4", "max", engine="numpy")
    assert cv.metadata["spacing"] == {"x": 1.0, "y": 2.0, "z": 4.0}
    assert cv.spacing == SPACING and cv.dims == DIMS and cv.spacing_zyx == SPACING[::-1]
    solid = Chronovolume(np.ones((Z, Y, X, 4), np.float32), None, dict(cv.metadata))
    assert drawn_aspect(solid, 0.0) == pytest.approx(14 / 20, rel=0.04)
    assert drawn_aspect(solid, 90.0) == pytest.approx(24 / 20, rel=0.04)


def test_every_public_triple_of_a_series_is_x_first(tmp_path):
    data = np.random.default_rng(0).random((T, Z, Y, X), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data, spacing=SPACING)
    assert series.spacing == SPACING and series.spacing_zyx == SPACING[::-1]
    assert series.dims == DIMS and series.volume_shape == (Z, Y, X)  # the array's own order
    summary = series.describe()
    assert summary["spacing (x, y, z)"] == list(SPACING)
    assert summary["dims (x, y, z)"] == list(DIMS)
    assert summary["shape (T, Z, Y, X)"] == [T, Z, Y, X]
    # A coarse level keeps the physical extent axis by axis (65, 9, 3 voxels pool unevenly).
    long = chronocl.TimeSeries.from_array(np.zeros((1, 3, 9, 65), np.float32), spacing=SPACING)
    level = long.level(1)
    assert level.dims == (33, 5, 2)
    np.testing.assert_allclose(
        np.multiply(level.dims, level.spacing), np.multiply((65, 9, 3), SPACING)
    )
    # Probes: a point (x, y, z) and a box x0:x1,y0:y1,z0:z1.
    curve = probe(series, 11, 7, 2)
    assert curve.point == (11, 7, 2)
    np.testing.assert_array_equal(curve.values, data[:, 2, 7, 11])
    box = probe(series, region="9:13,1:4,3:5")
    assert box.box == ((9, 13), (1, 4), (3, 5))
    np.testing.assert_allclose(
        box.values, data[:, 3:5, 1:4, 9:13].mean(axis=(1, 2, 3), dtype=np.float64)
    )
    # A bad spacing is named in that order.
    with pytest.raises(ChronoclError, match=r"dx, dy, dz \(x first\)"):
        chronocl.TimeSeries.from_array(data, spacing=(1.0, 0.0, 4.0))


def test_the_readers_take_spacing_x_first(tmp_path):
    from chronocl.data.formats.npy import ingest_npy
    from chronocl.data.formats.raw import ingest_raw

    data = blob()
    for t, step in enumerate(data):
        step.tofile(tmp_path / f"s_{t}.raw")
    raw = ingest_raw([str(tmp_path / "s_*.raw")], tmp_path / "raw.zarr", dims=DIMS, spacing=SPACING)
    np.save(tmp_path / "s.npy", data)
    npy = ingest_npy(tmp_path / "s.npy", tmp_path / "npy.zarr", spacing=SPACING)
    for series in (raw, npy):
        assert series.spacing == SPACING and series.dims == DIMS
        np.testing.assert_array_equal(series.read(range(T)), data)


def test_labelled_coordinates_give_spacing_x_first():
    xr = pytest.importorskip("xarray")
    array = xr.DataArray(
        blob(),
        dims=("time", "z", "y", "x"),
        coords={"z": np.arange(Z) * 4.0, "y": np.arange(Y) * 2.0, "x": np.arange(X) * 1.0},
    )
    assert chronocl.TimeSeries.from_array(array).spacing == SPACING


def test_exports_write_spacing_and_origin_x_first(tmp_path, monkeypatch, capsys):
    from chronocl.data.formats.export import export_series
    from chronocl.data.formats.vti import write_vti

    head = write_vti(
        tmp_path / "a.vti", {"v": np.zeros((Z, Y, X), np.float32)}, SPACING, (0.5, 0.0, 8.0)
    ).read_bytes()[:600]
    assert b'Origin="0.5 0.0 8.0" Spacing="1.0 2.0 4.0"' in head
    assert f'WholeExtent="0 {X - 1} 0 {Y - 1} 0 {Z - 1}"'.encode() in head
    # A raw export's sidecar says x, y, z, and its ingest line reads the steps back alike.
    series = chronocl.TimeSeries.from_array(blob(), spacing=SPACING)
    paths = export_series(series, tmp_path / "r", fmt="raw", z="2:6")
    meta = json.loads(paths[0].read_text())
    assert meta["dims"] == [X, Y, 4] and meta["spacing"] == {"x": 1.0, "y": 2.0, "z": 4.0}
    assert meta["origin"] == {"x": 0.0, "y": 0.0, "z": 8.0}
    assert "--spacing 1.0 2.0 4.0" in meta["ingest"]
    files = [str(p) for p in paths[1:]]
    run_cli(monkeypatch, capsys, "ingest", *files, "-o", tmp_path / "back.zarr",
            "--dims", *meta["dims"], "--spacing", *SPACING)  # fmt: skip
    back = chronocl.open(tmp_path / "back.zarr")
    assert back.spacing == SPACING and back.dims == (X, Y, 4)
    np.testing.assert_array_equal(back.read(range(T)), series.read(range(T), 2, 6))


def test_the_viewer_probe_answers_x_first():
    """The voxel a ray meets and the curve there, on a volume whose axes all differ."""
    from chronocl.viewer.datasets import Dataset
    from chronocl.viewer.probe import box_fractions, probe_ray, project

    rgba = np.zeros((Z, Y, X, 4), np.float32)
    rgba[1:4, 3:7, 9:13] = 0.9  # x 9..12, y 3..6, z 1..3
    cv = Chronovolume(rgba, None, {"spacing": dict(zip("xyz", SPACING, strict=True))})
    camera = Camera(azimuth=0.0, elevation=0.0, projection="orthographic", frame="box")
    # The ray through the block's middle on screen, from +z: it meets the block's front face.
    at = project(cv, camera, (240, 240), box_fractions(cv, (10.5, 4.5, 2.0)))
    assert at is not None
    hit = probe_ray(cv, camera, (240, 240), *at)
    x, y, z = hit["voxel"]
    assert hit["reached"] and 9 <= x < 13 and 3 <= y < 7 and z == 3, hit
    assert box_fractions(cv, (x, y, z)) == ((x + 0.5) / X, (y + 0.5) / Y, (z + 0.5) / Z)
    data = np.random.default_rng(1).random((T, Z, Y, X), dtype=np.float32)
    ds = Dataset("d", chronocl.TimeSeries.from_array(data, spacing=SPACING))
    np.testing.assert_array_equal(ds.curve((x, y, z)).values, data[:, z, y, x])
