"""Orientation of pictures: `up` turns the view as turning the data would (Python API and
`chronocl render --up`), the axis triad and the box outline are drawn by default on the
command line (also in turntables) and left out with --no-axes / --no-outline, and a bad --up
is one line with exit 2."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import chronocl
from chronocl.render import Camera, render
from chronocl.render.triad import AXIS_COLOURS, triad_size

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")  # visibility notes: not tested here

SHAPE = (20, 16, 12)  # Z, Y, X: every axis a different length


def blobs(n_steps: int = 3) -> np.ndarray:
    """Two blobs that move along different axes, in a box of three different sides: no turn
    of it looks like another."""
    z, y, x = np.meshgrid(*(np.arange(n) for n in SHAPE), indexing="ij")
    return np.stack(
        [
            np.exp(-((x - 3 - t) ** 2 + (y - 4) ** 2 + (z - 14) ** 2) / 8.0)
            + 0.6 * np.exp(-((x - 8) ** 2 + (y - 11) ** 2 + (z - 3 - 2 * t) ** 2) / 6.0)
            for t in range(n_steps)
        ]
    ).astype(np.float32)


def turned(data: np.ndarray, up: str) -> np.ndarray:
    """The (T, Z, Y, X) data turned so that axis `up` becomes y, as `Camera(up=up)` turns the
    view (render/camera.py UP_BASES): up z puts x right, z up, -y towards the viewer; up x puts
    y right, x up, -z towards the viewer."""
    if up == "z":  # new x = x, new y = z, new z = -y
        return np.ascontiguousarray(data.transpose(0, 2, 1, 3)[:, ::-1])
    if up == "x":  # new x = y, new y = x, new z = -z
        return np.ascontiguousarray(data[:, ::-1].transpose(0, 1, 3, 2))
    return data


def run(monkeypatch, capsys, *args) -> tuple[int, str]:
    """`chronocl ARGS` in this process: (exit code, stderr)."""
    from chronocl.cli import main

    monkeypatch.setattr(sys, "argv", ["chronocl", *map(str, args)])
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        main()
    return info.value.code or 0, capsys.readouterr().err


def png(path) -> np.ndarray:
    from PIL import Image as PILImage

    return np.asarray(PILImage.open(path).convert("RGB")).astype(int)


@pytest.mark.parametrize("up", ["x", "z"])
def test_up_draws_the_data_turned_so_that_axis_up(up):
    data = blobs()
    cv = chronocl.integrate(chronocl.TimeSeries.from_array(data), "0:3", engine="numpy")
    cv_turned = chronocl.integrate(
        chronocl.TimeSeries.from_array(turned(data, up)), "0:3", engine="numpy"
    )
    for azimuth, elevation in ((30, 20), (0, 0), (130, -50)):
        a = render(cv, Camera(azimuth, elevation, up=up), (96, 96), jitter=False).array
        b = render(cv_turned, Camera(azimuth, elevation), (96, 96), jitter=False).array
        plain = render(cv, Camera(azimuth, elevation), (96, 96), jitter=False).array
        diff = np.abs(a.astype(int) - b.astype(int))
        assert diff.mean() < 0.2 and np.percentile(diff, 99.5) <= 2, (diff.mean(), diff.max())
        assert np.abs(a.astype(int) - plain.astype(int)).mean() > 3  # up changed the picture


def test_the_camera_basis_per_up_axis():
    # Rows: right, up, towards the eye, in data axes.
    np.testing.assert_allclose(Camera(0, 0).screen_axes(), np.eye(3), atol=1e-12)
    np.testing.assert_allclose(
        Camera(0, 0, up="z").screen_axes(), [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-12
    )
    np.testing.assert_allclose(
        Camera(0, 0, up="x").screen_axes(), [[0, 1, 0], [1, 0, 0], [0, 0, -1]], atol=1e-12
    )
    # Azimuth turns around the up axis: it stays up on the screen.
    for up, axis in (("x", 0), ("y", 1), ("z", 2)):
        for azimuth in (0, 45, 200):
            assert Camera(azimuth, 0, up=up).screen_axes()[1][axis] == pytest.approx(1)
    # Straight down the up axis the frame is still a rotation (no degenerate basis).
    basis = Camera(10, 89.95, up="z").screen_axes()
    np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-9)
    with pytest.raises(chronocl.ChronoclError, match="unknown up axis 'w'; choose x, y or z"):
        Camera(up="w")


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """The blobs as stored, and turned so that z becomes y."""
    root = tmp_path_factory.mktemp("orientation")
    data = blobs()
    chronocl.TimeSeries.from_array(data).save(root / "b.zarr")
    chronocl.TimeSeries.from_array(turned(data, "z")).save(root / "turned.zarr")
    return root / "b.zarr", root / "turned.zarr"


COMMON = ("--engine", "numpy", "--window", "0:3", "--size", "128x128")


def test_cli_up_z_is_the_data_turned(stores, tmp_path, monkeypatch, capsys):
    store, turned_store = stores
    # Box outline on (the default): it turns with the data. No triad, whose letters differ.
    args = (*COMMON, "--no-axes", "--azimuth", "40", "--elevation", "25")
    assert (
        run(monkeypatch, capsys, "render", store, "-o", tmp_path / "z.png", "--up", "z", *args)[0]
        == 0
    )
    assert run(monkeypatch, capsys, "render", turned_store, "-o", tmp_path / "t.png", *args)[0] == 0
    assert run(monkeypatch, capsys, "render", store, "-o", tmp_path / "y.png", *args)[0] == 0
    up_z, turned_y, up_y = (png(tmp_path / f"{n}.png") for n in ("z", "t", "y"))
    diff = np.abs(up_z - turned_y)
    assert diff.mean() < 0.3 and np.percentile(diff, 99.5) <= 3, (diff.mean(), diff.max())
    assert np.abs(up_z - up_y)[:128].mean() > 3


def near(pixels: np.ndarray, colour, tolerance: float = 45.0) -> int:
    """How many pixels lie within `tolerance` of `colour`."""
    return int((np.linalg.norm(pixels - np.array(colour), axis=-1) < tolerance).sum())


@pytest.mark.parametrize("background", ["black", "white"])
def test_cli_draws_the_triad_and_outline_by_default(
    stores, tmp_path, monkeypatch, capsys, background
):
    import imageio.v3 as iio

    store, _ = stores
    size = 320
    side = triad_size(size, size)
    assert side == round(0.12 * size)
    out = {}
    for name, flags in {
        "default": ("--turntable", tmp_path / "turn.gif", "--frames", "2"),
        "no-axes": ("--no-axes",),
        "bare": ("--no-axes", "--no-outline"),
    }.items():
        path = tmp_path / f"{name}.png"
        # A view with every arm of the triad across the screen (none end-on, drawn faint).
        view = ("--azimuth", "30", "--elevation", "20")
        argv = (*COMMON[:4], *view, "--size", f"{size}x{size}", "--background", background, *flags)
        code, err = run(monkeypatch, capsys, "render", store, "-o", path, *argv)
        assert code == 0, err
        out[name] = png(path)[:size]  # the picture, without the legend below it

    # The triad: only the bottom-right corner changes, and it holds each axis's colour.
    changed = np.abs(out["default"] - out["no-axes"]).sum(axis=-1) > 0
    rows, cols = np.nonzero(changed)
    assert rows.min() >= size - side - side // 8 and cols.min() >= size - side - side // 8
    assert changed.mean() < 0.02  # a corner mark, not a cover
    corner = out["default"][size - side :, size - side :]
    for colour in AXIS_COLOURS:
        assert near(corner, colour) >= 8, (colour, background)
    assert sum(near(out["no-axes"][size - side :, size - side :], c) for c in AXIS_COLOURS) == 0
    # The turntable's frames carry it too: its first frame (the same camera, in the GIF's
    # palette) is nearer the picture with the triad than the one without, in the corner.
    frame = iio.imread(tmp_path / "turn.gif", index=0)[:size, :, :3].astype(int)
    at = (slice(size - side, size), slice(size - side, size))
    with_axes, without = (np.abs(frame[at] - out[k][at]).mean() for k in ("default", "no-axes"))
    assert with_axes < without / 2, (with_axes, without)

    # The outline: grey lines (darker on white) that --no-outline leaves out.
    grey = 0.35 if background == "white" else 0.65
    lines = np.abs(out["no-axes"] - out["bare"]).sum(axis=-1) > 0
    assert lines.sum() > 3 * size  # the box's edges
    drawn = out["no-axes"][lines]
    assert (np.abs(drawn - round(grey * 255)).max(axis=-1) <= 1).mean() > 0.9


def test_small_panels_get_no_triad():
    assert triad_size(512, 512) == 61 and triad_size(128, 300) == 32
    assert triad_size(127, 127) == 0  # 32 px would cover more than a quarter of the side


def test_bad_up_is_one_line(stores, tmp_path, monkeypatch, capsys):
    store, _ = stores
    code, err = run(monkeypatch, capsys, "render", store, "-o", tmp_path / "o.png", "--up", "w")
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1, err
    assert "unknown up axis 'w'; choose x, y or z" in lines[0] and "Traceback" not in err
    assert not (tmp_path / "o.png").exists()


def test_viewer_state_session_and_render_state_keep_up(stores, tmp_path, monkeypatch, capsys):
    """The viewer's camera carries `up` (checked by the protocol), a session file keeps it,
    and `chronocl render --state` draws it, or the --up given on its command line."""
    import json

    from chronocl.data.series import open_series
    from chronocl.viewer.protocol import ProtocolError, choices, parse_message
    from chronocl.viewer.snapshot import check_snapshot, snapshot_of, snapshot_state
    from chronocl.viewer.view_state import default_state, describe_state, merge

    store, _ = stores
    series = open_series(store)
    base = default_state(0, series)
    assert describe_state(base)["camera"]["up"] == "y" and choices()["up_axes"] == ["x", "y", "z"]
    msg = parse_message(json.dumps({"type": "update", "camera": {"up": "z"}}))
    state = merge(base, msg, series.n_steps)
    assert state.camera.up == "z" and state.camera.azimuth == base.camera.azimuth
    with pytest.raises(ProtocolError, match=r"update\.camera\.up"):
        parse_message(json.dumps({"type": "update", "camera": {"up": "w"}}))
    snapshot = snapshot_of(state, "b", series, str(store))
    assert snapshot["camera"]["up"] == "z"
    assert snapshot_state(check_snapshot(json.loads(json.dumps(snapshot))), series).camera.up == "z"

    path = tmp_path / "s.json"
    path.write_text(json.dumps(snapshot))
    pictures = {}
    for name, flags in {"z": (), "y": ("--up", "y"), "z-axes": ("--axes",)}.items():
        out = tmp_path / f"{name}.png"
        code, err = run(monkeypatch, capsys, "render", "--state", path, "-o", out, *flags)
        assert code == 0, err
        pictures[name] = png(out)
    assert np.abs(pictures["z"] - pictures["y"]).mean() > 1  # --up overrides the session's
    # No triad unless asked (as the viewer's Save PNG); --axes adds it, only in the corners.
    changed = np.abs(pictures["z"] - pictures["z-axes"]).sum(axis=-1) > 0
    assert 0 < changed.mean() < 0.02
    code, err = run(
        monkeypatch, capsys, "render", "--state", path, "-o", tmp_path / "w.png", "--up", "w"
    )
    assert code == 2 and len(err.strip().splitlines()) == 1 and "unknown up axis" in err
