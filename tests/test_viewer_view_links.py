"""Views set apart (issue 49): each view's camera, data TF and time TF linked to the shared
ones or its own. The state and its schema (an own one given, described, validated, dropped when
linked again), the server drawing each view with its own, and the target: two views with
unlinked cameras and TFs saved to a session file and restored, on a fresh socket and by
`chronocl render --state`, give the same pictures bit for bit."""

from __future__ import annotations

import dataclasses
import io
import json

import numpy as np
import pytest

from chronocl.core.errors import ChronoclError
from chronocl.data.series import open_series
from chronocl.viewer.movie import movie_states
from chronocl.viewer.protocol import LIMITS, parse_message
from chronocl.viewer.schema import ProtocolError
from chronocl.viewer.snapshot import check_snapshot, snapshot_of, snapshot_state
from chronocl.viewer.view_state import default_state, describe_state, merge

from .viewer_helpers import Client, full_size_frames, make_stores, start_server  # noqa: F401

pytest.importorskip("starlette")

# Two alpha views: the second with its own camera, data TF and time TF; the first linked.
OWN_CAMERA = {"azimuth": 160.0, "elevation": -35.0, "zoom": 1.6, "projection": "orthographic"}
OWN_DATA_TF = {"points": [[0, 1, 0.3, 0.1, 0], [0.4, 1, 0.8, 0.2, 0.2], [1, 1, 1, 0.6, 0.9]]}
OWN_TIME_TF = {"color": "warm-cool", "alpha": "hat", "center": 0.3, "width": 0.4}
UNLINKED = {
    "camera": {"azimuth": 20.0, "elevation": 25.0, "zoom": 1.3},
    "window": {"t0": 2, "t1": 10},
    "data_tf": {"points": [[0, 1, 1, 1, 0], [1, 1, 1, 1, 0.8]]},
    "size": [128, 112],
    "views": [
        {"mode": "alpha", "order": "forward"},
        {
            "mode": "alpha",
            "order": "forward",
            "camera": OWN_CAMERA,
            "data_tf": OWN_DATA_TF,
            "time_tf": OWN_TIME_TF,
        },
    ],
}


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    return make_stores(tmp_path_factory.mktemp("view-links"))


@pytest.fixture(scope="module")
def series(stores):
    return open_series(stores[0])


# ------------------------------------------------------------------ state and schema
def test_a_view_unlinked_has_its_own_camera_and_tfs(series):
    n = series.n_steps
    state = merge(
        default_state(0, series), parse_message(json.dumps(UNLINKED | {"type": "update"})), n
    )
    # View 0 follows the shared camera and TFs; view 1 has its own.
    assert state.camera_of(0) == state.camera and state.camera_of(1).azimuth == 160.0
    assert state.camera_of(1).projection == "orthographic"
    assert state.camera_of(1).fov == state.camera.fov  # given in part: the rest the shared one's
    assert state.spec(0).data_tf == state.data_tf
    assert state.spec(1).data_tf.points != state.data_tf.points
    assert (
        state.spec(1).time_tf.alpha.shape == "hat"
        and state.spec(0).time_tf.alpha.shape == "constant"
    )
    assert state.panel_camera(1).azimuth == 160.0 and state.panel_camera().azimuth == 20.0
    # Described: null where linked, the own one where not (the page and sessions read it).
    views = describe_state(state)["views"]
    assert (
        views[0]["camera"] is None and views[0]["data_tf"] is None and views[0]["time_tf"] is None
    )
    assert views[1]["camera"]["azimuth"] == 160.0 and views[1]["camera"]["up"] == "y"
    assert views[1]["data_tf"]["points"] == OWN_DATA_TF["points"]
    assert views[1]["time_tf"]["alpha"] == "hat" and views[1]["time_tf"]["floor"] == 0.1
    # The shared camera or TFs changed: the unlinked view keeps its own; a frame's focus is
    # the shared camera's for every view (an own camera frames what the shared one frames).
    moved = merge(state, {"camera": {"azimuth": 90.0}, "time_tf": {"alpha": "inverted-hat"}}, n)
    assert moved.camera_of(1).azimuth == 160.0 and moved.spec(1).time_tf.alpha.shape == "hat"
    assert moved.spec(0).time_tf.alpha.shape == "inverted-hat"
    box = (-0.5, -0.4, -0.3, 0.5, 0.4, 0.3)
    framed = dataclasses.replace(moved, camera=dataclasses.replace(moved.camera, focus=box))
    assert framed.camera_of(1).focus == box
    # The described state given back is the same state (the page's round trip).
    again = merge(default_state(0, series), describe_state(state), n)
    assert describe_state(again) == describe_state(state)
    assert [again.spec(i) for i in range(2)] == [state.spec(i) for i in range(2)]
    # Linked again (its own one left out, or null): the own copy is dropped.
    linked = merge(state, {"views": [{"mode": "alpha"}, {"mode": "alpha", "camera": None}]}, n)
    assert linked.view_cameras == (None, None) and linked.view_data_tfs == (None, None)
    assert linked.spec(1) == linked.spec(0) and linked.camera_of(1) == linked.camera
    # An orbit movie turns each view's own camera with the shared one.
    states = movie_states(state, "orbit", 4, n)
    assert [s.camera_of(1).azimuth for s in states] == [160.0, 250.0, 340.0, 430.0]


@pytest.mark.parametrize(
    "view, needle",
    [
        ({"camera": {"zoom": 50}}, r"update\.views\[1\]\.camera\.zoom is 50"),
        ({"camera": {"tilt": 1}}, r"update\.views\[1\]\.camera has unknown field 'tilt'"),
        ({"data_tf": {"value_range": [0, 1]}}, r"update\.views\[1\]\.data_tf is missing"),
        ({"data_tf": {"points": [[0, 1, 1, 1, 2]]}}, r"views\[1\]\.data_tf\.points\[0\]\[4\]"),
        ({"time_tf": {"alpha": "wobble"}}, r"update\.views\[1\]\.time_tf\.alpha is \"wobble\""),
    ],
)
def test_a_bad_own_camera_or_tf_is_named_by_its_path(view, needle):
    msg = {"type": "update", "views": [{"mode": "alpha"}, {"mode": "alpha"} | view]}
    with pytest.raises(ProtocolError, match=needle):
        parse_message(json.dumps(msg))


def test_an_own_tf_that_does_not_fit_changes_nothing(series):
    state = default_state(0, series)
    bad = {
        "views": [{"mode": "alpha", "data_tf": {"points": [[0.5, 1, 1, 1, 0], [0.2, 1, 1, 1, 1]]}}]
    }
    with pytest.raises(ChronoclError):
        merge(state, bad, series.n_steps)
    # The deepest message (an own data TF's point) is within the depth allowed.
    assert LIMITS.depth >= 6


def test_snapshot_keeps_the_links(stores, series):
    state = merge(default_state(0, series), UNLINKED, series.n_steps)
    snapshot = check_snapshot(json.loads(json.dumps(snapshot_of(state, "vortex", series))))
    assert snapshot["views"][0]["camera"] is None
    assert snapshot["views"][1]["camera"]["azimuth"] == 160.0
    back = snapshot_state(snapshot, series)
    assert describe_state(back) == describe_state(state)
    assert back.view_cameras[1] == state.view_cameras[1]
    assert [back.spec(i) for i in range(2)] == [state.spec(i) for i in range(2)]
    # A session saved before views had links (no such fields) loads with every view linked.
    old = dict(snapshot, views=[{"mode": "alpha", "order": "forward", "window": None}] * 2)
    linked = snapshot_state(check_snapshot(old), series)
    assert linked.view_cameras == (None, None) and linked.spec(0) == linked.spec(1)


def test_render_state_options_apply_to_every_views_camera(series):
    from chronocl.cli.render_state import _snapshot_fields

    state = merge(default_state(0, series), UNLINKED, series.n_steps)
    snapshot = snapshot_of(state, "vortex", series)
    fields = _snapshot_fields(snapshot, {"azimuth": 10.0, "zoom": 2.0})
    assert fields["camera"]["azimuth"] == 10.0 and fields["views"][0]["camera"] is None
    assert fields["views"][1]["camera"]["azimuth"] == 10.0
    assert fields["views"][1]["camera"]["projection"] == "orthographic"  # the rest its own
    assert fields["views"][1]["time_tf"]["alpha"] == "hat"  # its TFs kept
    assert snapshot["views"][1]["camera"]["azimuth"] == 160.0  # the session as it was
    # --mode changes each view's mode alone: its own camera and TFs stay; a view more is linked
    fields = _snapshot_fields(snapshot, {"mode": ["max,min", "mean"]})
    assert [v["mode"] for v in fields["views"]] == ["max", "min", "mean"]
    assert fields["views"][1]["camera"] == snapshot["views"][1]["camera"]
    assert fields["views"][1]["time_tf"] == snapshot["views"][1]["time_tf"]
    assert fields["views"][2] == {"mode": "mean", "order": snapshot["views"][0]["order"]}
    # --window is every view's: a view's own window is let go
    fields = _snapshot_fields(snapshot, {"window": "1:5"})
    assert fields["window"] == {"t0": 1, "t1": 5, "stride": 1}
    assert all(v["window"] is None for v in fields["views"])


def test_render_state_colormap_recolours_each_views_own_curve(stores, series, tmp_path):
    """`chronocl render --state --colormap`: each view's own data TF is recoloured (its own
    opacity kept), not replaced by the shared curve recoloured; the picture equals the
    session's views drawn with those TFs, bit for bit."""
    from PIL import Image

    from chronocl.cli.render_state import _following, render_state
    from chronocl.viewer.snapshot import render_snapshot, write_snapshot

    state = merge(default_state(0, series), UNLINKED, series.n_steps)
    path = tmp_path / "links.json"
    path.write_bytes(write_snapshot(snapshot_of(state, "vortex", series, stores[0])))
    out = tmp_path / "cli.png"
    render_state(path, {"colormap": "viridis", "out_path": out})
    own = state.view_data_tfs[1].with_colormap("viridis")
    assert own.points != state.data_tf.with_colormap("viridis").points  # two curves
    recoloured = [state.data_tf_of(i).with_colormap("viridis") for i in range(2)]
    changes = []
    for i, data_tf in enumerate(recoloured):
        time_tf = _following(state.time_tf_object(i), data_tf)  # as the command line's
        changes.append({"data_tf": data_tf, **({} if time_tf is None else {"time_tf": time_tf})})
    want = render_snapshot(state, series, name="vortex", changes=changes)
    got = np.asarray(Image.open(out).convert("RGB"))
    assert np.array_equal(got, np.asarray(want.to_pil().convert("RGB")))


# ------------------------------------------------------------------ the server and the target
def _pixels(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def _settled(client: Client, rid: int):
    while True:
        _, header, images = client.frame_for(rid)
        if not header["refining"] and header["quality"] == "full":
            return header, images


def _download(server, client: Client, msg: dict) -> bytes:
    from .test_viewer_server import get

    rid = client.send(msg)
    _, dl = client.wait("download", rid)
    status, body, _ = get(server.base + dl["url"], {"X-Chronocl-Token": server.token})
    assert status == 200
    return body


def test_unlinked_views_saved_and_restored_bit_for_bit(stores, tmp_path, full_size_frames):  # noqa: F811
    """The target: two views, the second with its own camera, data TF and time TF, drawn
    each with its own; saved as a session file and loaded on a fresh socket, the frames and the
    saved PNG are the same bytes; `chronocl render --state` of the session and of the session
    saved again after the restore are the same PNG, its panels the viewer's pictures."""
    server = start_server(stores)
    try:
        client = Client(server)
        client.open(0)
        linked = UNLINKED | {"views": [{"mode": "alpha"}, {"mode": "alpha"}]}
        _, linked_images = _settled(client, client.send({"type": "update", **linked}))
        # Linked, the two views are one picture; unlinked, the second is its own.
        assert linked_images[0] == linked_images[1]
        header, images = _settled(client, client.send({"type": "update", **UNLINKED}))
        assert images[0] == linked_images[0]  # the linked view did not change
        assert np.abs(_pixels(images[1]).astype(int) - _pixels(images[0])).mean() > 5.0
        assert header["colorbars"][0] != header["colorbars"][1]  # each view's own data TF
        assert len(header["clip_outlines"]) == 2
        png = _download(server, client, {"type": "save", "what": "image"})
        body = _download(server, client, {"type": "save", "what": "session"})
        snapshot = json.loads(body)
        assert snapshot["views"][0]["camera"] is None
        assert snapshot["views"][1]["camera"]["azimuth"] == 160.0
        assert snapshot["views"][1]["time_tf"]["alpha"] == "hat"
        client.close()

        fresh = Client(server)
        fresh.open("jet")  # another data set shown: the load opens the session's
        rid = fresh.send({"type": "load", "session": snapshot})
        _, ds = fresh.wait("dataset", rid)
        assert (
            ds["state"]["views"]
            == describe_state(snapshot_state(snapshot, open_series(stores[0])))["views"]
        )
        _, restored = _settled(fresh, rid)
        assert restored == images  # the same JPEG bytes, view by view
        assert _download(server, fresh, {"type": "save", "what": "image"}) == png
        again = json.loads(_download(server, fresh, {"type": "save", "what": "session"}))
        assert again == snapshot
        fresh.close()
    finally:
        server.stop()

    from typer.testing import CliRunner

    from chronocl.cli.app import app

    (tmp_path / "a.json").write_bytes(body)
    (tmp_path / "b.json").write_text(json.dumps(again))
    for name in ("a", "b"):
        args = ["render", "--state", str(tmp_path / f"{name}.json")]
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
    a = (tmp_path / "a.png").read_bytes()
    assert a == (tmp_path / "b.png").read_bytes()
    figure = _pixels(a).astype(np.int16)
    w, h = UNLINKED["size"]
    assert figure.shape[1] == 2 * w
    # Each panel is that view's picture (under its own camera and TFs), as the viewer drew it:
    # the CLI integrates in float32 where the viewer keeps RGBA8, so near, not bit for bit.
    cap = figure.shape[0] - h - 2 * max(36, h // 8)
    for k, jpeg in enumerate(images):
        panel = figure[cap : cap + h, k * w : (k + 1) * w]
        assert np.abs(panel - _pixels(jpeg)).mean() < 2.0
        other = _pixels(images[1 - k]).astype(np.int16)
        assert np.abs(panel - other).mean() > 5.0
