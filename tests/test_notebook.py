"""The notebook widget's synced state, driving the real worker (OpenCL, EGL): each attribute set
from code changes the worker's state and the picture; each changed by the page's own message
(as the comm delivers it: `Widget._handle_msg`) shows in the attribute and its observers. Then
what `show` accepts, the kernel's requests (screenshot, chronovolume, snapshot), bad values,
closing, the front end's bundle, and a process without OpenGL. Then remote stores (a real HTTP
server and moto's S3 on loopback: the same frames as the local copy; a bad URL in one line),
and views set apart (a view's own camera and TFs in `w.views`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("anywidget")

import chronocl
from chronocl.core.errors import ChronoclError, RendererUnavailableError
from chronocl.data import synthetic
from chronocl.notebook import bundle
from chronocl.notebook import state as synced
from chronocl.notebook.widget import FrameFailedError
from chronocl.viewer.snapshot import check_snapshot

STEPS, SHAPE = 12, (24, 24, 24)


def vortex() -> np.ndarray:
    return np.stack(list(synthetic.steps("vortex", STEPS, SHAPE)))


@pytest.fixture(scope="module")
def widget():
    w = chronocl.show(vortex(), name="vortex")
    w.wait_frame()
    yield w
    w.close()


def from_page(w, msg: dict) -> None:
    """A message from the page, as the widget's comm hands it over."""
    content = {"text": json.dumps(msg)}
    w._handle_msg({"content": {"data": {"method": "custom", "content": content}}, "buffers": []})


def changes(w, name: str) -> list:
    seen: list = []
    w.observe(lambda change: seen.append(change["new"]), names=name)
    return seen


def new_picture(w, before: dict) -> dict:
    """The settled frame answering the newest request: its picture differs from `before`'s."""
    frame = w.wait_frame()
    assert frame["seq"] > before["seq"] and frame["digest"] != before["digest"]
    return frame


# -- from code -------------------------------------------------------------------------------


def test_setting_window_moves_the_worker_window_and_the_picture(widget):
    before, seen = widget.wait_frame(), changes(widget, "window")
    widget.window = (2, 6)
    assert widget.window == (2, 6, 1) and seen == [(2, 6, 1)]
    frame = new_picture(widget, before)
    assert "steps 2:6" in frame["views"][0]["label"]
    assert widget.snapshot()["window"] == {"t0": 2, "t1": 6, "stride": 1}


def test_setting_mode_sets_the_first_view_and_the_picture(widget):
    before, seen = widget.wait_frame(), changes(widget, "mode")
    views_seen = changes(widget, "views")
    widget.mode = "max" if widget.mode != "max" else "alpha"
    frame = new_picture(widget, before)
    assert frame["views"][0]["label"].startswith(widget.mode)
    assert seen == [widget.mode] and views_seen[-1][0]["mode"] == widget.mode


def test_setting_views_shows_them_side_by_side(widget):
    before = widget.wait_frame()
    widget.views = ["max", {"mode": "mean", "order": "backward"}]
    assert [(v["mode"], v["order"]) for v in widget.views] == [
        ("max", "forward"),
        ("mean", "backward"),
    ]
    assert widget.mode == "max"
    frame = new_picture(widget, before)
    assert [v["label"].split(",")[0] for v in frame["views"]] == ["max", "mean"]
    widget.views = ["alpha"]
    assert len(widget.wait_frame()["views"]) == 1


def test_setting_data_tf_recolours_the_picture(widget):
    before = widget.wait_frame()
    points = [[0.0, 1.0, 1.0, 1.0, 0.0], [0.3, 1.0, 0.2, 0.0, 0.6], [1.0, 1.0, 1.0, 0.0, 1.0]]
    widget.data_tf = {"points": points, "value_range": [0.0, 1.0]}
    assert widget.data_tf == {"points": points, "value_range": [0.0, 1.0]}
    new_picture(widget, before)
    assert widget.snapshot()["data_tf"]["points"] == points


def test_setting_part_of_time_tf_keeps_the_rest(widget):
    before, alpha = widget.wait_frame(), widget.time_tf["alpha"]
    widget.time_tf = {"color": "lightness"}
    assert widget.time_tf["color"] == "lightness" and widget.time_tf["alpha"] == alpha
    new_picture(widget, before)
    assert widget.snapshot()["time_tf"]["color"] == "lightness"


def test_setting_camera_turns_the_picture(widget):
    before = widget.wait_frame()
    widget.camera = {"azimuth": widget.camera["azimuth"] + 60, "elevation": 10}
    assert widget.camera["elevation"] == 10 and widget.camera["projection"] == "perspective"
    new_picture(widget, before)
    assert widget.snapshot()["camera"]["elevation"] == 10


def test_a_bad_value_raises_and_changes_nothing(widget):
    window, mode, seen = widget.window, widget.mode, changes(widget, "mode")
    with pytest.raises(ChronoclError, match="choose one of"):
        widget.mode = "no-such-mode"
    with pytest.raises(ChronoclError, match="window"):
        widget.window = (5,)
    with pytest.raises(ChronoclError):
        widget.window = (0, 10_000)
    with pytest.raises(ChronoclError, match="zoom"):
        widget.camera = {"zoom": 1e9}
    assert (widget.window, widget.mode, seen) == (window, mode, [])


# -- from the page ---------------------------------------------------------------------------


def test_the_page_window_comes_back(widget):
    seen = changes(widget, "window")
    from_page(widget, {"type": "update", "id": 7, "window": {"t0": 3, "t1": 9, "stride": 2}})
    assert widget.window == (3, 9, 2) and seen == [(3, 9, 2)]
    assert "steps 3:8:2" in widget.wait_frame()["views"][0]["label"]  # its last step + 1


def test_the_page_mode_comes_back(widget):
    seen = changes(widget, "mode")
    views = [dict(widget.views[0], mode="min")]
    from_page(widget, {"type": "update", "id": 8, "views": views})
    assert widget.mode == "min" and seen == ["min"]


def test_the_page_views_come_back(widget):
    seen = changes(widget, "views")
    from_page(widget, {"type": "update", "id": 9, "views": [{"mode": "max"}, {"mode": "count"}]})
    assert [v["mode"] for v in widget.views] == ["max", "count"] and len(seen) == 1
    from_page(widget, {"type": "update", "id": 10, "views": [{"mode": "alpha"}]})
    assert widget.mode == "alpha"


def test_the_page_data_tf_comes_back(widget):
    seen = changes(widget, "data_tf")
    points = [[0.0, 0.0, 0.0, 1.0, 0.0], [1.0, 1.0, 0.0, 0.0, 0.8]]
    from_page(widget, {"type": "update", "id": 11, "data_tf": {"points": points}})
    assert widget.data_tf == {"points": points} and seen == [{"points": points}]


def test_the_page_time_tf_comes_back(widget):
    seen = changes(widget, "time_tf")
    from_page(widget, {"type": "update", "id": 12, "time_tf": {"color": "rgb", "width": 0.3}})
    assert widget.time_tf["width"] == 0.3 and seen[-1]["color"] == "rgb"


def test_the_page_camera_comes_back(widget):
    seen = changes(widget, "camera")
    from_page(widget, {"type": "update", "id": 13, "camera": {"azimuth": 123.0, "zoom": 2.0}})
    assert (widget.camera["azimuth"], widget.camera["zoom"]) == (123.0, 2.0) and len(seen) == 1


def test_an_observer_that_sets_an_attribute_sets_the_worker_too(widget):
    """An observer reacting to a change (the page's edit, or a set from code) by setting an
    attribute sends it to the worker as a cell would, once every attribute is set."""
    seen: list = []

    def to_max(change) -> None:
        seen.append((widget.window, widget.mode))  # every attribute is the worker's by now
        if change["new"][0] == 4:
            widget.mode = "max"

    widget.mode = "alpha"
    widget.observe(to_max, names="window")
    try:
        from_page(widget, {"type": "update", "id": 15, "window": {"t0": 4, "t1": 8, "stride": 1}})
        assert widget.mode == "max" and widget._worker.state.views[0][0] == "max"
        widget.window = (1, 5)
        widget.mode = "alpha"
        widget.window = (4, 6)  # from code
        assert widget.mode == "max" and widget._worker.state.views[0][0] == "max"
        assert seen == [((4, 8, 1), "alpha"), ((1, 5, 1), "max"), ((4, 6, 1), "alpha")]
    finally:
        widget.unobserve(to_max, names="window")


def test_sets_held_together_each_reach_the_worker_and_a_bad_one_changes_nothing(widget):
    """Sets in `hold_trait_notifications` are applied and checked at once (as `set_trait`'s):
    both reach the worker, their observers are called after the block; a bad one raises and
    leaves its attribute as it was."""
    seen = changes(widget, "window")
    with widget.hold_trait_notifications():
        widget.mode = "min"
        widget.window = (1, 6)
        assert seen == []  # (held)
    assert seen == [(1, 6, 1)]
    state = widget._worker.state
    assert (state.views[0][0], widget.mode, widget.window) == ("min", "min", (1, 6, 1))
    assert state.window == (1, 6, 1)
    with pytest.raises(ChronoclError):
        with widget.hold_trait_notifications():
            widget.mode = "no such mode"
    assert widget.mode == "min" and widget._worker.state.views[0][0] == "min"
    widget.set_trait("mode", "max")
    widget.set_trait("window", (2, 5))
    state = widget._worker.state
    assert (widget.mode, widget.window) == ("max", (2, 5, 1))
    assert (state.views[0][0], state.window) == ("max", (2, 5, 1))


def test_observers_are_called_with_the_widget_free(widget):
    """Every observer runs once its change is done, with the widget's lock let go (another
    thread may take it): after a page's edit, a set from code, and the front end's own sync of
    `height` (ipywidgets' `set_state`)."""
    free: list = []

    def probe(change) -> None:
        def take() -> None:
            got = widget._sync.acquire(timeout=0)
            free.append((change["name"], got))
            if got:
                widget._sync.release()

        t = threading.Thread(target=take)
        t.start()
        t.join()

    widget.observe(probe, names=["height", "window"])
    try:
        from_page(widget, {"type": "update", "id": 16, "window": {"t0": 2, "t1": 7, "stride": 1}})
        widget.window = (3, 8)
        state = {"method": "update", "state": {"height": 444}, "buffer_paths": []}
        widget._handle_msg({"content": {"data": state}, "buffers": []})
        assert widget.height == 444
        assert free == [("window", True), ("window", True), ("height", True)]
    finally:
        widget.unobserve(probe, names=["height", "window"])


def test_widgets_whose_observers_set_each_other_never_wait_for_each_other():
    """Two widgets whose camera observers set the other's camera, one turned from code while the
    other is turned on the page (on another thread): both finish, each observer called after
    the lock is let go, and the cameras end as one."""
    w1, w2 = chronocl.show(vortex()[:4], name="one"), chronocl.show(vortex()[:4], name="two")

    def follow(other):
        def observer(change) -> None:
            time.sleep(0.002)  # (a user's takes its time)
            other.camera = {"azimuth": change["new"]["azimuth"]}

        return observer

    w1.observe(follow(w2), names="camera")
    w2.observe(follow(w1), names="camera")
    try:

        def code() -> None:
            for i in range(20):
                w1.camera = {"azimuth": float(i)}

        def page() -> None:
            for i in range(20):
                from_page(w2, {"type": "update", "id": i + 1, "camera": {"azimuth": 100.0 + i}})

        threads = [threading.Thread(target=f, daemon=True) for f in (code, page)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        assert not any(t.is_alive() for t in threads), "the widgets waited for each other"
        assert w1.camera["azimuth"] == w2.camera["azimuth"]
        assert w1._worker.state.camera.azimuth == w1.camera["azimuth"]
    finally:
        w1.close()
        w2.close()


def test_the_page_edits_on_another_thread_never_lose_a_set_from_code():
    """JupyterLab 4 sends comm messages over subshells (`commsOverSubshells`), so ipykernel 7
    may hand the page's edits to the widget on another thread while a cell sets attributes:
    every set from code still reaches the worker, each page edit comes back whole, and the
    attributes end as the worker's state."""
    w = chronocl.show(vortex(), name="vortex")
    stop, errors = threading.Event(), []
    # an observer that takes its time, as a user's may: the page's edit is being applied then
    w.observe(lambda change: time.sleep(0.002), names="window")

    def page() -> None:
        i = 0
        while not stop.is_set():
            i += 1
            t0 = i % 6
            window = {"t0": t0, "t1": t0 + 4, "stride": 1}
            try:
                from_page(w, {"type": "update", "id": i, "window": window})
            except Exception as exc:  # (a failure here would leave the test blind)
                errors.append(exc)
                return

    edits = threading.Thread(target=page)
    edits.start()
    try:
        for i in range(300):
            mode = ("max", "min", "alpha")[i % 3]
            w.mode = mode
            assert w._worker.state.views[0][0] == mode, f"set {i} never reached the worker"
        stop.set()
        edits.join(30)
        assert errors == []
        worker = synced.from_state(w._described())
        assert {k: getattr(w, k) for k in worker} == worker
    finally:
        stop.set()
        edits.join(30)
        w.close()


def test_a_bad_page_message_changes_nothing(widget):
    window = widget.window
    from_page(widget, {"type": "update", "id": 14, "window": {"t0": 5, "t1": 2}})
    from_page(widget, {"type": "nonsense"})
    assert widget.window == window
    # the refused update is answered by no frame: the kernel waits for the one before it
    assert widget.wait_frame(timeout=60)["id"] != 14


# -- the kernel's requests -------------------------------------------------------------------


def test_screenshot_chronovolume_and_snapshot(widget):
    widget.views = ["max"]
    widget.window = (0, 8, 1)
    image = widget.screenshot()
    assert image.data[:8] == b"\x89PNG\r\n\x1a\n" and image.format == "png"
    cv = widget.chronovolume()
    assert cv.spec.mode == "max" and cv.steps == tuple(range(8)) and cv.rgba.dtype == np.float32
    snapshot = check_snapshot(widget.snapshot())
    assert snapshot["dataset"]["name"] == "vortex" and snapshot["views"][0]["mode"] == "max"
    # each chronovolume is loaded whole: nothing of it stays on disk
    assert widget.chronovolume(view=np.int64(0)).steps == cv.steps
    assert not [p for p in Path(widget._downloads.dir).iterdir() if p.is_dir()]


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda w: w.screenshot(columns=-1), "columns"),
        (lambda w: w.screenshot(columns="a"), "columns"),
        (lambda w: w.screenshot(columns=object()), "not plain data"),
        (lambda w: w.screenshot(columns=np.array([1, 2])), "columns"),
        (lambda w: w.chronovolume(view=-1), "view"),
        (lambda w: w.chronovolume(view=True), "view"),
    ],
)
def test_the_kernel_s_requests_are_checked_as_the_page_s(widget, call, field):
    """A bad argument to a request from code gets the protocol's one line naming it, as the
    page's would: once a worker's internal error (a traceback on stderr), or another view's
    chronovolume (view -1: the last one)."""
    with pytest.raises(ChronoclError, match=field) as got:
        call(widget)
    assert "\n" not in str(got.value)


def test_a_failed_frame_raises_at_once_naming_the_error(tmp_path):
    """The worker fails to make the frame waited for (its store rewritten underneath: a real
    read error, which the page is told of): wait_frame and screenshot raise at once with the
    worker's error in one line, for a request from code as for one from the page."""
    path = tmp_path / "v.zarr"
    chronocl.TimeSeries.from_array(vortex()[:8]).save(path)
    w = chronocl.show(str(path), window=(0, 2))
    try:
        w.wait_frame()
        chronocl.TimeSeries.from_array(vortex()[:3]).save(path, overwrite=True)
        started = time.monotonic()
        w.window = (0, 8)  # reads steps no frame read before
        with pytest.raises(FrameFailedError, match="changed underneath") as got:
            w.wait_frame(timeout=90)
        assert "\n" not in str(got.value) and str(path) in str(got.value)
        with pytest.raises(FrameFailedError, match="changed underneath"):
            w.screenshot()
        from_page(w, {"type": "update", "id": 60, "window": {"t0": 1, "t1": 7, "stride": 1}})
        with pytest.raises(FrameFailedError, match="changed underneath"):
            w.wait_frame(timeout=90)
        assert time.monotonic() - started < 60  # not the timeout: at once
        # The store as it was, and the page shown again (its requests numbered afresh): the
        # same id's frame is made and waited for; the old failure is not raised.
        chronocl.TimeSeries.from_array(vortex()[:8]).save(path, overwrite=True)
        from_page(w, {"type": "update", "id": 60, "window": {"t0": 2, "t1": 7, "stride": 1}})
        assert w.wait_frame(timeout=90)["id"] == 60
    finally:
        w.close()


def test_show_opens_a_store_and_a_labelled_array(tmp_path):
    xarray = pytest.importorskip("xarray")
    store = chronocl.TimeSeries.from_array(vortex()[:4], source="vortex").save(tmp_path / "v.zarr")
    w = chronocl.show(str(store.path), window=(0, 3), mode="max")
    try:
        assert w.window == (0, 3, 1) and w.mode == "max"
        assert w.snapshot()["dataset"]["name"] == "v"
        assert "max" in w.wait_frame()["views"][0]["label"]
    finally:
        w.close()
    da = xarray.DataArray(vortex()[:4], dims=("time", "z", "y", "x"))
    w = chronocl.show(da)
    try:
        assert w.snapshot()["dataset"]["shape"] == [4, *SHAPE]
    finally:
        w.close()


def test_show_refuses_what_it_cannot_show():
    with pytest.raises(ChronoclError, match="cannot show a dict"):
        chronocl.show({"a": 1})
    with pytest.raises(ChronoclError, match="height"):
        chronocl.show(vortex(), height=5)
    with pytest.raises(ChronoclError):
        chronocl.show(np.zeros((4, 4)))
    # the viewer's options, checked as `chronocl view` checks them, before any data is read
    with pytest.raises(ChronoclError, match="unknown engine 'nope'"):
        chronocl.show(vortex(), engine="nope")
    with pytest.raises(ChronoclError, match="banana"):
        chronocl.show(vortex(), memory="banana")


def test_numpy_numbers_set_attributes_as_plain_ones(widget):
    widget.window = (np.int64(2), np.int64(6))
    assert widget.window[:2] == (2, 6) or list(widget.window[:2]) == [2, 6]
    tf = dict(widget.data_tf)
    lo, hi = np.float32(0.0), np.float32(0.5)
    widget.data_tf = {**tf, "value_range": [lo, hi]}
    assert widget.data_tf["value_range"] == [0.0, 0.5]
    with pytest.raises(ChronoclError, match="not plain data"):
        widget.camera = {"zoom": object()}


def test_close_ends_the_worker_and_refuses_more():
    w = chronocl.show(vortex()[:3])
    w.wait_frame()
    thread = w._worker.thread
    w.close()
    assert w.closed and not thread.is_alive()
    with pytest.raises(ChronoclError, match="closed"):
        w.mode = "max"
    with pytest.raises(ChronoclError, match="closed"):
        w.snapshot()


# -- the front end and a process without OpenGL ----------------------------------------------


def test_the_bundle_ships_every_viewer_module_after_its_imports():
    b = bundle.bundle()
    order = b["order"]
    assert order[-1] == "app.js" and "main.js" not in order  # the page's start is not shipped
    static = {p.name for p in bundle._static().iterdir() if p.name.endswith(".js")}
    assert set(order) == static - {"main.js"}
    for i, name in enumerate(order):
        assert set(bundle.IMPORT.findall(b["modules"][name])) <= set(order[:i]), name
    assert 'id="views"' in b["markup"] and "<script" not in b["markup"]
    esm = bundle.esm()
    assert "/* BUNDLE */ null" not in esm and "export default { render }" in esm


def test_a_kernel_without_opengl_is_told_why():
    """A process whose EGL finds no driver: show raises one clear error, nothing else."""
    code = (
        "import numpy as np, chronocl\n"
        "try:\n"
        "    chronocl.show(np.zeros((3, 8, 8, 8), np.float32))\n"
        "except chronocl.ChronoclError as exc:\n"
        "    print(type(exc).__name__ + ': ' + str(exc))\n"
    )
    env = os.environ | {"__EGL_VENDOR_LIBRARY_FILENAMES": os.devnull}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.stdout.startswith(RendererUnavailableError.__name__), out.stdout + out.stderr
    assert "no OpenGL context" in out.stdout and "libegl1" in out.stdout
    assert out.stderr == ""


# -- a Chronovolume, the probe ---------------------------------------------------------------


def test_show_names_what_to_pass_for_a_chronovolume(tmp_path):
    series = chronocl.TimeSeries.from_array(vortex()[:8], source="vortex")
    store = series.save(tmp_path / "v.zarr")
    cv = chronocl.integrate(store, window="2:8:2", mode="max")
    with pytest.raises(ChronoclError) as got:
        chronocl.show(cv)
    where = str((tmp_path / "v.zarr").resolve())
    assert f"chronocl.show({where!r}, window=(2, 7, 2), mode='max')" in str(got.value)
    assert "chronocl.render(cv)" in str(got.value) and "\n" not in str(got.value)


def sent_to_page(w, monkeypatch) -> list[dict]:
    """The text messages the widget sends its page from now on."""
    sent: list[dict] = []
    send = w.send

    def record(content, buffers=None):
        if "text" in content:
            sent.append(json.loads(content["text"]))
        return send(content, buffers)

    monkeypatch.setattr(w, "send", record)
    return sent


def test_probe_gives_what_the_page_probe_shows(widget, monkeypatch):
    widget.views = ["alpha"]
    widget.window = (2, 9, 1)
    widget.wait_frame()
    sent = sent_to_page(widget, monkeypatch)
    from_page(widget, {"type": "probe", "id": 40, "view": 0, "x": 0.5, "y": 0.5})
    end = time.monotonic() + 60
    while not any(m.get("type") == "probe" for m in sent) and time.monotonic() < end:
        time.sleep(0.05)
    page = next(m for m in sent if m.get("type") == "probe")
    assert page["voxel"] is not None, "the centre ray met nothing"
    v = page["voxel"]
    mine = widget.probe((v["x"], v["y"], v["z"]))
    for key in ("voxel", "box", "values", "min", "max", "window", "csv"):
        assert mine[key] == page[key], key
    assert mine["mark"] == pytest.approx(page["mark"], abs=1e-4)
    assert mine["window"] == list(range(2, 9)) and len(mine["values"]) == STEPS
    series = chronocl.TimeSeries.from_array(vortex())
    assert mine["values"] == pytest.approx(chronocl.probe(series, v["x"], v["y"], v["z"]).values)
    # The page's probe panel was given the code's probe too ("probed from code"), as its own
    shown = [m for m in sent if m.get("type") == "probe"][-1]
    assert shown["pinned"] == "code" and shown["voxel"] == page["voxel"]
    assert shown["values"] == page["values"] and shown["csv"] == page["csv"]
    assert shown["mark"] == pytest.approx(page["mark"], abs=1e-4)
    # Another voxel probed from code is the one the next frames mark (the page's pinned v),
    # where it lies after a turn; show=False sends nothing and moves no mark
    other = tuple((c + 4) % n for c, n in zip((v["x"], v["y"], v["z"]), SHAPE[::-1], strict=True))
    widget.probe(other)
    widget.camera = {"azimuth": 80}
    header = widget.wait_frame()
    before = len(sent)
    there = widget.probe(other, show=False)["mark"]  # where it is in that frame
    assert not [m for m in sent[before:] if m.get("type") == "probe"]
    assert header["probe"]["view"] == 0 and there is not None
    assert (header["probe"]["x"], header["probe"]["y"]) == pytest.approx(tuple(there), abs=1e-4)


def test_probe_takes_a_world_point_and_a_box(widget):
    sp = widget._datasets[0].series.spacing  # (1, 1, 1) here: world x is index + fraction
    at = widget.probe((3.7 * sp[0], 10.2 * sp[1], 0.0), world=True)
    assert at["voxel"] == {"x": 3, "y": 10, "z": 0}
    assert at["world"] == pytest.approx([3.5, 10.5, 0.5])
    assert at["values"] == widget.probe((3, 10, 0))["values"]
    box = widget.probe(box=((4, 8), (4, 8), (10, 12)))
    assert box["voxel"] is None and box["box"] == {"x": [4, 8], "y": [4, 8], "z": [10, 12]}
    assert len(box["min"]) == len(box["max"]) == STEPS
    assert all(
        lo <= m <= hi for lo, m, hi in zip(box["min"], box["values"], box["max"], strict=True)
    )
    with pytest.raises(ChronoclError, match="outside"):
        widget.probe((0, 0, SHAPE[0]))
    with pytest.raises(ChronoclError, match="outside the box"):
        widget.probe((0.0, 0.0, 24.5), world=True)
    with pytest.raises(ChronoclError, match="view 3"):
        widget.probe((1, 1, 1), view=3)
    with pytest.raises(ChronoclError, match="not both"):
        widget.probe((1, 1, 1), box=((0, 1), (0, 1), (0, 1)))


# -- the first picture, the kernel's shares, the front end closing --------------------------


def test_no_frame_is_made_before_one_is_wanted():
    w = chronocl.show(vortex()[:6], window=(0, 4), mode="max")
    try:
        time.sleep(1.0)
        assert w.frames == 0 and w.window == (0, 4, 1) and w.mode == "max"
        frame = w.wait_frame()  # the kernel wants one (a screenshot would): it is made
        assert (
            frame["views"][0]["label"].startswith("max")
            and "steps 0:4" in frame["views"][0]["label"]
        )
    finally:
        w.close()


def test_the_page_first_request_makes_the_first_frame():
    w = chronocl.show(vortex()[:6])
    try:
        # Meanwhile the worker integrates the state's chronovolume, ready for the first frame.
        slots = w._worker.views.slots
        end = time.monotonic() + 60
        while not (slots and slots[0].cv is not None) and time.monotonic() < end:
            time.sleep(0.02)
        from_page(w, {"type": "open", "id": 1, "dataset": 0})
        time.sleep(0.3)
        assert w.frames == 0  # the open is answered with the state, not a frame
        from_page(w, {"type": "update", "id": 2, "size": [320, 240]})
        frame = w.wait_frame()
        assert frame["id"] == 2 and w.frames >= 1
        assert frame["timings"]["integrate_ms"] == 0.0  # it drew what was integrated ahead
    finally:
        w.close()


def test_widgets_of_one_store_share_its_steps_and_the_kernel_one_limit(tmp_path):
    from chronocl.core import process_memory
    from chronocl.notebook.kernel import KERNEL

    path = chronocl.TimeSeries.from_array(vortex()[:6]).save(tmp_path / "v.zarr").path
    before = process_memory.current()
    a = chronocl.show(str(path), memory="3GB")
    b = chronocl.show(path, name="again")
    c = chronocl.show(vortex()[:6])
    try:
        sa, sb, sc = (w._datasets[0].series for w in (a, b, c))
        assert sa is sb and sc is not sa
        assert a._shared is b._shared is KERNEL.held_steps(sa) and c._shared is not a._shared
        assert a._worker.views._shared is a._shared  # the worker's views read the shared steps
        limit = process_memory.current()
        # the kernel's (made by the first widget, here or the module's), its total a's
        assert limit is KERNEL.limit and limit.total == 3 * 10**9
        assert b._worker.memory == c._worker.memory == "3GB"  # one budget for all
        for w in (a, b):
            w.window = (0, 4)
            w.wait_frame()
        managers = a._shared.of(0)
        assert managers and all(m in limit._holders for m in managers.values())
        a.close()
        assert not a._shared._closed and process_memory.current() is limit  # b shows it still
        b.close()
        assert a._shared._closed and KERNEL.held_steps(sa) is None  # its steps let go
        assert process_memory.current() is limit  # c is open: the kernel's limit stays
    finally:
        for w in (a, b, c):
            w.close()
    # The kernel's limit goes with its last widget (the module's `widget` may be open still).
    assert process_memory.current() is (before if KERNEL.widgets() == 0 else limit)


def test_the_kernel_limit_and_steps_go_with_their_last_widget():
    from chronocl.core import process_memory
    from chronocl.notebook.kernel import Kernel

    kernel, before = Kernel(), process_memory.current()
    s1 = chronocl.TimeSeries.from_array(vortex()[:3])
    s2 = chronocl.TimeSeries.from_array(vortex()[:3])
    steps_a, memory = kernel.join(1, s1, memory="2GB")
    limit = process_memory.current()
    assert memory == "2GB" and limit is kernel.limit and limit.total == 2 * 10**9
    steps_b, memory = kernel.join(2, s1)
    assert steps_b is steps_a and memory == "2GB"  # one series: one set of steps
    steps_c, _ = kernel.join(3, s2, memory="1GB")
    assert steps_c is not steps_a and limit.total == 10**9  # the newest memory is the kernel's
    with pytest.raises(ChronoclError):
        kernel.join(4, s2, memory="lots")  # a bad one changes nothing
    assert limit.total == 10**9 and kernel.widgets() == 3
    kernel.leave(1, s1)
    assert not steps_a._closed
    kernel.leave(2, s1)
    assert steps_a._closed and process_memory.current() is limit
    kernel.leave(3, s2)
    assert steps_c._closed and process_memory.current() is before and kernel.limit is None


def test_the_front_end_closing_the_comm_frees_the_worker():
    w = chronocl.show(vortex()[:4])
    w.wait_frame()
    thread, series = w._worker.thread, w._datasets[0].series
    comm = w.comm
    comm.handle_close({"content": {"comm_id": comm.comm_id, "data": {}}})  # as the kernel does
    assert w.closed and not thread.is_alive() and w.comm is None
    from chronocl.notebook.kernel import KERNEL

    assert KERNEL.held_steps(series) is None


def test_show_integrates_only_the_window_and_mode_asked_for(monkeypatch):
    """`show(window=, mode=)` warms the state asked for, not the default one first (the page's
    first frame waited behind an integration nobody wanted)."""
    from chronocl.viewer.view_sessions import Views

    integrated: list = []
    real = Views.chronovolumes

    def noting(self, state):
        integrated.append((tuple(state.window), state.views[0][0]))
        return real(self, state)

    monkeypatch.setattr(Views, "chronovolumes", noting)
    w = chronocl.show(vortex()[:6], window=(1, 5), mode="max")
    try:
        slots = w._worker.views.slots
        end = time.monotonic() + 60
        while not (slots and slots[0].cv is not None) and time.monotonic() < end:
            time.sleep(0.02)
        assert integrated == [((1, 5, 1), "max")], integrated
    finally:
        w.close()


def test_the_first_widget_makes_the_default_limit_as_chronocl_view_does():
    from chronocl.core import process_memory
    from chronocl.core.budget import interactive_memory
    from chronocl.notebook.kernel import Kernel

    kernel, before = Kernel(), process_memory.current()
    series = chronocl.TimeSeries.from_array(vortex()[:3])
    _, memory = kernel.join(1, series)  # no memory given
    limit = process_memory.current()
    assert limit is kernel.limit and limit is not before
    assert abs(limit.total - interactive_memory()) < 2**30 and memory == limit.total
    kernel.leave(1, series)
    assert process_memory.current() is before


def test_a_rewritten_store_shown_again_is_opened_afresh(tmp_path):
    """A re-run cell (the old widget still open) on a store rewritten meanwhile shows the new
    data, not the old widget's series (whose every frame then failed)."""
    from chronocl.notebook.kernel import KERNEL

    path = tmp_path / "v.zarr"
    chronocl.TimeSeries.from_array(vortex()[:4]).save(path)
    a = chronocl.show(str(path))
    try:
        same = chronocl.show(str(path))
        assert same._datasets[0].series is a._datasets[0].series  # unchanged: shared
        same.close()
        chronocl.TimeSeries.from_array(vortex()[:6]).save(path, overwrite=True)
        b = chronocl.show(str(path))
        try:
            assert b._datasets[0].series.n_steps == 6
            assert KERNEL.held_steps(a._datasets[0].series) is not None  # a's stays its own
        finally:
            b.close()
    finally:
        a.close()


# -- remote stores: HTTP and S3 (moto) on loopback (tests/remote_servers.py) ------------------


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """A folder holding v.zarr, the vortex as a chronocl store."""
    root = tmp_path_factory.mktemp("served")
    chronocl.TimeSeries.from_array(vortex(), source="vortex").save(root / "v.zarr")
    return root


def scrubbed(where, **options) -> tuple[list[str], bytes, dict]:
    """`where` shown, its window scrubbed from code (0:6, then 3:9, then 5:12 by 2): the
    settled frames' digests, the last one's screenshot (PNG bytes) and the snapshot."""
    w = chronocl.show(where, window=(0, 6), **options)
    try:
        digests = [w.wait_frame()["digest"]]
        for window in ((3, 9), (5, 12, 2)):
            w.window = window
            frame = w.wait_frame()
            assert frame["views"][0]["label"].endswith(
                f"steps {window[0]}:{window[1]}" + (f":{window[2]}" if len(window) > 2 else "")
            ), frame["views"][0]["label"]
            digests.append(frame["digest"])
        return digests, w.screenshot().data, w.snapshot()
    finally:
        w.close()


def test_show_opens_a_store_over_http_as_its_local_copy(served):
    """`show(URL)`: the store read in place over HTTP (a real server on loopback) gives the same
    frames while scrubbing and the same screenshot, bit for bit, as its local copy."""
    from .remote_servers import StoreServer

    local = scrubbed(str(served / "v.zarr"))
    with StoreServer(served) as http:
        remote = scrubbed(http.url("v.zarr"))
        assert http.chunk_requests()  # its steps came over HTTP
        assert remote[2]["dataset"]["path"] == http.url("v.zarr")
    assert len(set(local[0])) == 3  # each window its own picture
    assert remote[0] == local[0] and remote[1] == local[1]
    assert remote[1][:8] == b"\x89PNG\r\n\x1a\n"
    assert remote[2]["dataset"]["name"] == local[2]["dataset"]["name"] == "v"


def test_show_opens_an_s3_store_with_storage_options(served):
    """`show("s3://...", storage_options=...)` on moto's S3 server: the same frames and
    screenshot as the local copy; a URL's scheme in capitals is read as the same store."""
    pytest.importorskip("s3fs")
    pytest.importorskip("moto.server")
    import logging

    from .remote_servers import S3Server

    logging.getLogger("werkzeug").setLevel(logging.ERROR)
    local = scrubbed(str(served / "v.zarr"))
    with S3Server() as s3:
        url = s3.put(served / "v.zarr", "chronocl-notebook", "runs/v.zarr")
        remote = scrubbed(url, storage_options=s3.storage_options())
        assert remote[0] == local[0] and remote[1] == local[1]
        assert remote[2]["dataset"]["path"] == url
        w = chronocl.show("S3" + url[2:], storage_options=s3.storage_options())
        try:
            assert w.snapshot()["dataset"]["path"] == url
        finally:
            w.close()
        with pytest.raises(
            ChronoclError, match=r"bucket 'no-such-bucket' .* does not exist"
        ) as got:
            chronocl.show("s3://no-such-bucket/v.zarr", storage_options=s3.storage_options())
        assert "\n" not in str(got.value)


def test_a_bad_url_is_one_line_before_any_work(served, monkeypatch):
    """A URL `show` cannot read is one ChronoclError line: another scheme, no host or bucket, a
    bad port, or storage options for a path or an array before anything is opened; a store
    missing, unreachable or refused before any worker is made."""
    import chronocl.notebook.data as nb_data
    import chronocl.notebook.widget as nb_widget

    from .remote_servers import StoreServer

    monkeypatch.setenv("CHRONOCL_REMOTE_RETRIES", "1")
    monkeypatch.setenv("CHRONOCL_REMOTE_BACKOFF_S", "0.01")

    def no_work(*args, **kwargs):
        raise AssertionError("work was started for a bad URL")

    monkeypatch.setattr(nb_widget, "ClientWorker", no_work)

    def one_line(data, match: str, **options) -> None:
        with pytest.raises(ChronoclError, match=match) as got:
            chronocl.show(data, **options)
        assert "\n" not in str(got.value), str(got.value)

    with monkeypatch.context() as nothing_opened:
        nothing_opened.setattr(nb_data, "open_datasets", no_work)
        one_line("ftp://127.0.0.1/v.zarr", r"cannot read a ftp:// store .* http://, https://")
        one_line("gs://bucket/v.zarr", r"cannot read a gs:// store")
        one_line("http://", r"'http://' names no host")
        one_line("https:///v.zarr", r"names no host")
        one_line("s3://", r"'s3://' names no bucket")
        one_line("http://127.0.0.1:port/v.zarr", r"is not a URL \(Port could not be cast")
        one_line(
            str(served / "v.zarr"),
            r"apply to a store's .* not to the local path",
            storage_options={"anon": True},
        )
        one_line(vortex(), r"not to a ndarray", storage_options={"anon": True})
        one_line("s3://bucket/v.zarr", r"storage_options must be a dict", storage_options="anon")
    with StoreServer(served) as http:
        one_line(http.url("nothing.zarr"), r"no zarr store at http://127\.0\.0\.1")
        assert http.requests  # it looked
    one_line("http://127.0.0.1:9/v.zarr", r"cannot connect")  # the discard port: no one there


# -- views set apart: each view's own camera, data TF and time TF ----------------------------


def panels_of(w, monkeypatch):
    """A function giving the panels' pictures (each view's JPEG bytes) of the settled frame
    answering the newest request, as the page is sent them."""
    from chronocl.viewer.protocol import unpack_frame

    sent: dict[int, list[bytes]] = {}
    send = w.send

    def record(content, buffers=None):
        if content.get("frame"):
            header, images = unpack_frame(buffers[0])
            sent[header["seq"]] = images
        return send(content, buffers)

    monkeypatch.setattr(w, "send", record)
    return lambda: sent[w.wait_frame()["seq"]]


def test_a_view_with_its_own_camera_shows_its_own_picture(widget, monkeypatch):
    """`w.views` carries each view's links: a view given its own camera (in part: the rest the
    shared one's) draws its own picture beside the linked one; the shared camera and the mode
    set from code leave it as it is; relinked (`camera: None`), the two panels are equal. An
    own data TF and the page's own edit of a view's links read back the same way."""
    panels = panels_of(widget, monkeypatch)
    widget.camera = {"azimuth": 30, "elevation": 20}
    widget.views = [{"mode": "max"}, {"mode": "max", "camera": {"azimuth": 90}}]
    first, second = widget.views
    assert first["camera"] is None and first["data_tf"] is None and first["time_tf"] is None
    assert second["camera"]["azimuth"] == 90
    assert second["camera"]["elevation"] == widget.camera["elevation"] == 20  # the shared one's
    assert second["data_tf"] is None and second["time_tf"] is None
    a, b = panels()
    assert a != b
    assert widget.snapshot()["views"][1]["camera"]["azimuth"] == 90

    widget.camera = {"azimuth": 45}  # the shared camera turns the linked view only
    widget.mode = "mean"
    assert widget.views[1]["camera"]["azimuth"] == 90 and widget.views[1]["mode"] == "max"
    widget.mode = "max"
    widget.camera = {"azimuth": 90}  # the shared one where the own one is: the same picture
    a, b = panels()
    assert a == b

    relinked = [dict(v) for v in widget.views]
    relinked[1]["camera"] = None
    widget.camera = {"azimuth": 30}
    widget.views = relinked
    assert widget.views[1]["camera"] is None
    a, b = panels()
    assert a == b

    # an own data TF: its own colours
    points = [[0.0, 1.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.0, 0.0, 1.0]]
    own_tf = {"points": points, "value_range": [0.0, 1.0]}
    widget.views = [{"mode": "max"}, {"mode": "max", "data_tf": own_tf}]
    assert widget.views[1]["data_tf"]["points"] == points and widget.views[0]["data_tf"] is None
    a, b = panels()
    assert a != b

    # the page unlinks the second view's time TF (its header's `time` toggle): it comes back
    seen = changes(widget, "views")
    views = [dict(v) for v in widget.views]
    views[1]["time_tf"] = {"color": "lightness"}
    from_page(widget, {"type": "update", "id": 90, "views": views})
    assert widget.views[1]["time_tf"]["color"] == "lightness"
    assert widget.views[0]["time_tf"] is None and seen and seen[-1] == widget.views
    widget.views = ["alpha"]
    linked = {"window": None, "camera": None, "data_tf": None, "time_tf": None}
    assert widget.views == [{"mode": "alpha", "order": "forward", **linked}]


# -- suspended while no view shows it --------------------------------------------------------


def view(w, what: str, view_id: str = "view-1", hidden: bool = False) -> None:
    """widget.js's message: a view of the widget shown on the page ("shown"), alive (its
    heartbeat) or removed ("gone": its output cleared, its cell deleted, its page hidden)."""
    content = {"view": what, "id": view_id, "hidden": hidden}
    w._handle_msg({"content": {"data": {"method": "custom", "content": content}}, "buffers": []})


def suspended_soon(w, timeout: float = 30.0) -> bool:
    end = time.monotonic() + timeout
    while not w.suspended and time.monotonic() < end:
        time.sleep(0.02)
    return w.suspended


def test_a_widget_no_view_shows_is_suspended_and_resumes_as_it_was(monkeypatch):
    """Its last view gone for the grace: the worker's thread ends and the kernel lets its steps
    go; the attributes stay. Any use from code (`wait_frame`, an attribute set) or a view
    shown again resumes it: a new worker with the same window, views, TFs and camera, whose
    frame for that state is the one shown before, pixel for pixel."""
    import chronocl.notebook.widget as nb_widget
    from chronocl.notebook.kernel import KERNEL

    monkeypatch.setattr(nb_widget, "SUSPEND_AFTER_S", 0.3)
    w = chronocl.show(vortex()[:8], window=(1, 7))
    try:
        series = w._datasets[0].series
        view(w, "shown")
        w.camera = {"azimuth": 75, "elevation": -15, "zoom": 1.5}
        w.time_tf = {"color": "lightness"}
        w.views = ["max", {"mode": "mean", "camera": {"azimuth": 10}}]
        points = [[0.0, 1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 0.3, 0.0, 0.9]]
        w.data_tf = {"points": points, "value_range": [0.0, 1.0]}
        before = w.wait_frame()
        png = w.screenshot().data
        attributes = {name: getattr(w, name) for name in synced.SYNCED}
        snapshot = w.snapshot()
        thread, shared = w._worker.thread, w._shared
        assert KERNEL.held_steps(series) is shared and not w.suspended

        # shown again within the grace (an output re-rendered): nothing is let go
        view(w, "gone")
        view(w, "shown")
        time.sleep(0.8)
        assert not w.suspended and thread.is_alive()

        view(w, "gone")
        assert suspended_soon(w)
        assert not thread.is_alive() and shared._closed and KERNEL.held_steps(series) is None
        assert {name: getattr(w, name) for name in synced.SYNCED} == attributes
        assert not w.closed

        # from code: wait_frame resumes it, the same state, the same picture
        assert w.last_frame is None  # (no frame shown now)
        made = w.frames
        frame = w.wait_frame()
        assert not w.suspended and w._worker.thread is not thread and w._worker.thread.is_alive()
        assert KERNEL.held_steps(series) is w._shared and w._shared is not shared
        assert w.frames > made and frame["digest"] == before["digest"]
        assert w.snapshot() == snapshot
        assert w.screenshot().data == png
        assert {name: getattr(w, name) for name in synced.SYNCED} == attributes

        # an attribute set resumes it too, and changes the picture as it would have
        view(w, "shown")
        view(w, "gone")
        assert suspended_soon(w)
        w.mode = "min"
        assert not w.suspended and w.mode == "min" and w.views[1]["mode"] == "mean"
        assert w.views[1]["camera"]["azimuth"] == 10 and w.camera["azimuth"] == 75
        assert w.wait_frame()["views"][0]["label"].startswith("min")

        # a view shown again resumes it at once (its page's requests follow)
        view(w, "shown")
        view(w, "gone")
        assert suspended_soon(w)
        view(w, "shown")
        assert not w.suspended and w._live is not None and KERNEL.held_steps(series) is not None
        from_page(w, {"type": "open", "id": 1, "dataset": 0})
        from_page(w, {"type": "update", "id": 2, "size": [320, 240]})
        assert w.wait_frame()["id"] == 2

        # closed while suspended: nothing is left, and nothing more is done
        view(w, "gone")
        assert suspended_soon(w)
        w.close()
        assert w.closed and not w.suspended and w._live is None
        with pytest.raises(ChronoclError, match="closed"):
            w.wait_frame()
    finally:
        w.close()


def test_a_widget_being_suspended_frees_its_lock_and_resumes_after_its_share_goes(monkeypatch):
    """The suspend takes the worker under the widget's lock and ends it after: while the old
    worker's end is under way (held here at its share's release, KERNEL.leave wrapped with a
    gate before the real one runs) the lock is free and the widget not yet `suspended`; a use
    from code meanwhile resumes only once the old share is let go, so the kernel holds the new
    share (a widget's share is one per widget: joined before the old one left, it would be
    the one let go)."""
    import chronocl.notebook.widget as nb_widget
    from chronocl.notebook.kernel import KERNEL

    monkeypatch.setattr(nb_widget, "SUSPEND_AFTER_S", 0.05)
    order: list[str] = []
    gate = threading.Event()
    leave, join = KERNEL.leave, KERNEL.join

    def gated_leave(widget, series):
        order.append("leave")
        gate.wait(60)
        leave(widget, series)
        order.append("left")

    def joining(*args, **kwargs):
        order.append("join")
        return join(*args, **kwargs)

    w = chronocl.show(vortex()[:6], window=(0, 4))
    try:
        series = w._datasets[0].series
        before = w.wait_frame()
        thread = w._worker.thread
        monkeypatch.setattr(KERNEL, "leave", gated_leave)
        monkeypatch.setattr(KERNEL, "join", joining)
        view(w, "shown")
        view(w, "gone")
        end = time.monotonic() + 30
        while "leave" not in order and time.monotonic() < end:
            time.sleep(0.01)
        assert order == ["leave"]  # the old worker's thread joined; its share not yet let go
        assert not thread.is_alive()
        assert w._life.acquire(timeout=5)  # the widget's lock is free meanwhile
        w._life.release()
        assert not w.suspended and w._live is None

        got: list[dict] = []
        user = threading.Thread(target=lambda: got.append(w.wait_frame()), daemon=True)
        user.start()  # a use from code: it waits for the old share to go
        time.sleep(0.5)
        assert order == ["leave"] and user.is_alive() and not got

        gate.set()
        user.join(60)
        assert order == ["leave", "left", "join"]
        assert got and got[0]["digest"] == before["digest"]
        assert not w.suspended and w._worker.thread is not thread
        assert w._shared is not None and KERNEL.held_steps(series) is w._shared
    finally:
        gate.set()
        w.close()
    assert KERNEL.held_steps(series) is None


def test_a_widget_in_use_is_not_suspended_under_its_waits(monkeypatch):
    """The grace passes while the kernel waits on the worker (a screenshot): the wait ends
    first; a widget never shown (used only from code) is never suspended."""
    import chronocl.notebook.widget as nb_widget

    monkeypatch.setattr(nb_widget, "SUSPEND_AFTER_S", 0.05)
    w = chronocl.show(vortex()[:6])
    try:
        w.wait_frame()
        time.sleep(0.3)
        assert not w.suspended  # never shown: never suspended
        view(w, "shown")
        view(w, "gone")
        for _ in range(3):
            assert w.screenshot().data[:8] == b"\x89PNG\r\n\x1a\n"
        assert suspended_soon(w)
    finally:
        w.close()


# -- views proving they are alive (a page reloaded never says "gone") -------------------------


class Clock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_a_view_silent_past_its_bound_is_gone_and_one_heard_again_is_shown():
    from chronocl.notebook import views as nb_views

    clock = Clock()
    shown = nb_views.Views(clock)
    assert shown.heard("a") and shown.heard("b", hidden=True) and len(shown) == 2
    assert not shown.heard("a")  # a heartbeat of a view counted shown changes nothing
    clock.now += nb_views.LOST_AFTER_S - 1
    assert not shown.heard("a") and shown.expire() == []
    clock.now += 2  # b silent past the visible bound, but its page is hidden: it waits longer
    assert shown.expire() == [] and len(shown) == 2
    clock.now += nb_views.LOST_AFTER_S  # a silent past it (its page reloaded): gone
    assert shown.expire() == ["a"] and len(shown) == 1
    clock.now += nb_views.LOST_HIDDEN_AFTER_S
    assert shown.expire() == ["b"] and len(shown) == 0
    assert shown.heard("a")  # heard again (a page back from the cache): shown anew
    assert shown.gone("a") and not shown.gone("a") and not shown.gone("never")
    assert len(shown) == 0


def test_the_cell_clock_stands_still_while_a_cell_runs():
    """A view's heartbeats wait in the kernel's queue while a cell runs: that silence is not
    counted (the clock stands still from pre_run_cell to post_run_cell, cells run by cells once,
    and an empty cell's end, which IPython sends without a start, ends nothing)."""
    from chronocl.notebook import views as nb_views

    clock = Clock()
    cells = nb_views.CellTime(clock)
    shown = nb_views.Views(cells)
    shown.heard("a")
    t0 = cells()
    clock.now += 5
    outer, inner, empty = object(), object(), object()
    cells.start(outer)
    clock.now += 10 * nb_views.LOST_AFTER_S  # a long cell
    cells.start(inner)  # (a cell running a cell)
    clock.now += 7
    cells.end(inner)
    cells.end(empty)  # an empty cell run inside it: IPython ends it without starting it
    clock.now += 30
    assert cells() == t0 + 5 and shown.expire() == []
    cells.end(outer)
    cells.end(outer)  # (an end without a start: nothing)
    clock.now += 3
    assert cells() == t0 + 8 and shown.expire() == []
    clock.now += nb_views.LOST_AFTER_S
    assert shown.expire() == ["a"]


def test_a_widget_whose_views_stop_beating_is_suspended_and_one_heard_again_resumes(monkeypatch):
    """A page reloaded or crashed sends no "gone": once its view's heartbeats stop for the
    bound (the views' clock moved by hand) the widget is suspended at once, as if the view went;
    while another view beats it is not; the view heard again resumes it as it was."""
    import chronocl.notebook.widget as nb_widget
    from chronocl.notebook import views as nb_views

    monkeypatch.setattr(nb_widget, "SUSPEND_AFTER_S", 0.3)
    w = chronocl.show(vortex()[:6], window=(1, 5))
    try:
        assert w._heartbeat_s == nb_views.HEARTBEAT_S  # the front end's heartbeat
        clock = Clock()
        w._views.clock = clock
        view(w, "shown", "a")
        view(w, "shown", "b")
        w.mode = "max"
        before = w.wait_frame()
        thread = w._worker.thread
        clock.now += nb_views.LOST_AFTER_S / 2
        view(w, "alive", "b")
        clock.now += nb_views.LOST_AFTER_S / 2 + 1  # a is silent past the bound, b beats
        time.sleep(1.0)  # (the widget's poll, every POLL_S, counts a gone)
        assert len(w._views) == 1 and not w.suspended and thread.is_alive()

        clock.now += nb_views.LOST_AFTER_S + 1  # b silent too: no view left
        assert suspended_soon(w, timeout=10)
        assert len(w._views) == 0 and not thread.is_alive() and w.mode == "max"

        view(w, "alive", "b")  # b was alive after all (its kernel busy): shown again
        assert not w.suspended and len(w._views) == 1
        assert w.wait_frame()["digest"] == before["digest"]
    finally:
        w.close()
