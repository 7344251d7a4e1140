"""Snapshots, the saved viewer state (chronocl/viewer/snapshot.py; a "session file" to users):
the schema (round trip, bad files refused in one line), the server saving and loading one over
the socket, and `chronocl render --state` drawing the viewer's frame."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from chronocl.cli.render_state import render_state
from chronocl.core.errors import ChronoclError
from chronocl.data.series import open_series
from chronocl.viewer.box_axes import draw_axes
from chronocl.viewer.snapshot import (
    SnapshotFileError,
    check_snapshot,
    read_snapshot,
    snapshot_of,
    snapshot_state,
)
from chronocl.viewer.view_state import default_state, describe_state, merge

from .viewer_helpers import Client, full_size_frames, make_stores, start_server  # noqa: F401

pytest.importorskip("starlette")


@pytest.fixture(autouse=True)
def _full_size(full_size_frames):  # noqa: F811
    """Every test here compares frames: all drawn at full size."""


EDITS = {
    "camera": {"azimuth": 75.0, "elevation": -15.0, "zoom": 1.5, "projection": "orthographic"},
    "views": [{"mode": "alpha", "order": "backward"}, {"mode": "max", "order": "forward"}],
    "window": {"t0": 2, "t1": 10, "stride": 2},
    "data_tf": {"points": [[0, 1, 0.5, 0.2, 0], [0.3, 1, 1, 1, 0.05], [1, 0.2, 0.6, 1, 0.9]]},
    "time_tf": {"color": "warm-cool", "alpha": "hat", "center": 0.4, "width": 0.5},
    "enhance": {"kind": "edge"},
    "threshold": 0.1,
    "clip": {"normal": [0, 0, 1], "offset": 0.1},
    "size": [160, 128],
    "background": "white",
    "outline": True,
    "shading": {"enabled": True, "ambient": 0.3},
}


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    return make_stores(tmp_path_factory.mktemp("viewer-state"))


@pytest.fixture(scope="module")
def edited(stores):
    series = open_series(stores[0])
    return series, merge(default_state(0, series), EDITS, series.n_steps)


def test_session_round_trip(stores, edited):
    series, state = edited
    focus = [-0.3, -0.4, -0.25, 0.3, 0.2, 0.5]
    snapshot = snapshot_of(state, "vortex", series, str(stores[0]), focus)
    assert snapshot["chronocl_session"] == 1 and snapshot["shading"]["enabled"] is True
    text = json.dumps(snapshot)
    again = check_snapshot(json.loads(text))
    back = snapshot_state(again, series)
    assert describe_state(back) == describe_state(state)
    assert [back.spec(i) for i in range(2)] == [state.spec(i) for i in range(2)]
    assert back.camera.focus == tuple(focus) and back.shading == state.shading
    # Every field the viewer describes is kept, and a session with only the required fields
    # takes the viewer's defaults for the rest.
    required = {k: snapshot[k] for k in ("chronocl_session", "dataset", "window", "views")}
    required |= {k: snapshot[k] for k in ("camera", "data_tf", "time_tf")}
    partial = snapshot_state(check_snapshot(required), series)
    assert partial.camera.azimuth == state.camera.azimuth and partial.camera.focus is None
    assert partial.size == default_state(0, series).size
    assert partial.shading == default_state(0, series).shading


@pytest.mark.parametrize(
    "change, needle",
    [
        (lambda s: [s], "not a chronocl session"),
        (lambda s: {k: v for k, v in s.items() if k != "chronocl_session"}, "not a chronocl"),
        (lambda s: s | {"chronocl_session": 2}, "reads session files of version 1"),
        (lambda s: s | {"camera": s["camera"] | {"zoom": 50}}, "session.camera.zoom is 50"),
        (lambda s: s | {"views": []}, "session.views has 0 entries"),
        (lambda s: s | {"colour": "red"}, "unknown field 'colour'"),
        (lambda s: {k: v for k, v in s.items() if k != "window"}, "missing the field 'window'"),
        (lambda s: s | {"shading": {"glow": 1}}, "session.shading has unknown field 'glow'"),
        (lambda s: s | {"focus": [0, 0, 0, 1, 1]}, "session.focus has 5 entries"),
    ],
)
def test_bad_sessions_are_refused_in_one_line(edited, change, needle):
    series, state = edited
    snapshot = snapshot_of(state, "vortex", series)
    with pytest.raises(SnapshotFileError, match=needle) as info:
        check_snapshot(change(snapshot))
    assert isinstance(info.value, ChronoclError) and isinstance(info.value, ValueError)
    assert "\n" not in str(info.value)


def test_bad_snapshot_files(tmp_path, edited):
    series, state = edited
    (tmp_path / "a.json").write_text("{not json")
    with pytest.raises(SnapshotFileError, match=r"a\.json is not valid JSON"):
        read_snapshot(tmp_path / "a.json")
    with pytest.raises(ChronoclError, match="not found"):
        read_snapshot(tmp_path / "none.json")
    # A window beyond the series it is applied to: nothing applied, one line.
    snapshot = snapshot_of(state, "vortex", series) | {"window": {"t0": 5, "t1": 40}}
    with pytest.raises(SnapshotFileError, match="does not fit its data set"):
        snapshot_state(check_snapshot(snapshot), series)


def _frame_pixels(jpeg: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(jpeg)).convert("RGB")).astype(np.int16)


def _settled(client: Client, rid: int):
    while True:
        _, header, images = client.frame_for(rid)
        if not header["refining"] and header["quality"] == "full":
            return header, images


def test_server_saves_and_loads_and_render_state_draws_its_frame(stores, tmp_path):
    """The viewer's state saved as a session over the socket, loaded back in one step on a
    fresh socket (same frame), and `chronocl render --state` drawing the same panels."""
    from .test_viewer_server import get

    server = start_server(stores)
    try:
        client = Client(server)
        client.open(0)
        rid = client.send({"type": "update", **EDITS})
        header, images = _settled(client, rid)
        rid = client.send({"type": "save", "what": "session"})
        _, dl = client.wait("download", rid)
        assert dl["filename"] == "vortex-session.json"
        status, body, _ = get(server.base + dl["url"], {"X-Chronocl-Token": server.token})
        assert status == 200
        snapshot = json.loads(body)
        assert snapshot["dataset"]["path"] == str(stores[0].resolve())
        assert snapshot["window"] == EDITS["window"] and snapshot["size"] == EDITS["size"]
        assert len(snapshot["focus"]) == 6  # the box the views framed
        client.close()

        fresh = Client(server)
        fresh.open("jet")  # another data set shown: the load opens the session's
        rid = fresh.send({"type": "load", "session": snapshot})
        _, ds = fresh.wait("dataset", rid)
        assert ds["name"] == "vortex" and ds["state"]["camera"]["azimuth"] == 75.0
        assert ds["opening_camera"]["azimuth"] == 30.0
        loaded_header, loaded = _settled(fresh, rid)
        assert loaded_header["views"][0]["label"] == header["views"][0]["label"]
        for a, b in zip(images, loaded, strict=True):
            assert np.abs(_frame_pixels(a) - _frame_pixels(b)).mean() < 1.0
        # A session that does not fit is answered with one error and changes nothing.
        bad = snapshot | {"window": {"t0": 0, "t1": 99}}
        rid = fresh.send({"type": "load", "session": bad})
        _, error = fresh.wait("error", rid)
        assert "does not fit" in error["message"]
        fresh.close()
    finally:
        server.stop()

    path = tmp_path / "vortex-session.json"
    path.write_bytes(body)
    # The command line in this process (its kernels are built already).
    from typer.testing import CliRunner

    from chronocl.cli.app import app

    result = CliRunner().invoke(app, ["render", "--state", str(path)])
    assert result.exit_code == 0, result.output
    from PIL import Image

    png = Image.open(tmp_path / "vortex-session.png")
    figure = np.asarray(png.convert("RGB"))
    w, h = EDITS["size"]
    # Save PNG's title band, naming the data set and the window, also as the PNG's Title
    assert png.text["Title"] == "vortex: steps 2:9:2 (4 steps)", png.text  # 2:10:2 as shown
    assert "Description" in png.text
    # The captions' band: above the picture and the legend band, which holds the time legend
    # and under it the data colour bar (the session's data TF is coloured; a narrow panel).
    cap = figure.shape[0] - h - 2 * max(36, h // 8)
    assert figure.shape[1] == 2 * w and figure.shape[0] > cap + h  # two panels, legends below
    for k, jpeg in enumerate(images):
        # the frame with the box's labelled axes of its header drawn as the page draws them
        frame = _frame_pixels(jpeg).astype(np.uint8)
        frame = draw_axes(frame, header["axes"][k]).astype(np.int16)
        panel = figure[cap : cap + h, k * w : (k + 1) * w].astype(np.int16)
        diff = np.abs(panel - frame)  # the whole picture: no caption over it
        assert diff.mean() < 2.0 and np.percentile(diff, 99) < 40, (diff.mean(), diff.max())

    # Options on the command line override the session; bad sessions are refused in one line
    # (in this process: the command line's exit 2 for them is `main`'s, tested elsewhere).
    args = ["render", "--state", str(path), "-o", str(tmp_path / "big.png"), "--size", "96x64"]
    assert CliRunner().invoke(app, [*args, "--mode", "max"]).exit_code == 0
    assert Image.open(tmp_path / "big.png").size[0] == 96
    (tmp_path / "old.json").write_text(json.dumps(snapshot | {"chronocl_session": 0}))
    with pytest.raises(SnapshotFileError, match=r"old\.json: session\.chronocl_session is 0"):
        render_state(tmp_path / "old.json", {})
    with pytest.raises(ChronoclError, match="--turntable does not combine with --state"):
        render_state(path, {"turntable": tmp_path / "t.gif"})
    with pytest.raises(ChronoclError, match="--events does not combine with --state"):
        render_state(path, {"events": tmp_path / "e.json"})
