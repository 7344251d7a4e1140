"""The viewer's events panel over a real server and socket (`chronocl/viewer/events_panel.py`):
a series of two blobs that merge at a known step, found in the view's window beside the frames
(the merge, its centroid and the box a click frames; the tracks' sizes and values over time),
the markers drawn in the frame and in a saved PNG, progress after a second, a find given up
when the window changes, a find without the ``events`` extra answered with its install line
while the viewer works on, and every bad `events` message refused in one line.
"""

from __future__ import annotations

import io
import time
import urllib.request

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")
pytest.importorskip("cc3d")

from chronocl.data.series import TimeSeries
from chronocl.events import extra
from chronocl.events import run as events_run
from chronocl.render.markers import MARKER_RGB, PATH_RGB
from chronocl.viewer import protocol
from chronocl.viewer.events_panel import focus_box
from chronocl.viewer.protocol import ProtocolError, parse_message

from .viewer_helpers import Client, full_size_frames, serving  # noqa: F401

pytestmark = pytest.mark.usefixtures("full_size_frames")  # frames compared are the same size

SHAPE = (8, 16, 32)  # Z, Y, X
MERGE = 4  # the two blobs are apart up to this step and one blob from the next on


def merging_blobs(steps: int = 8, merge: int = MERGE, shape=SHAPE) -> np.ndarray:
    """Two 4-voxel-wide blobs closing in on the middle of x, a gap of 2 voxels at step
    `merge`, then one blob of 8 overlapping both: a merge between `merge` and `merge` + 1, and
    no other event (nothing touches a face)."""
    a = np.zeros((steps, *shape), np.float32)
    mid = shape[2] // 2
    z, y = slice(2, 6), slice(5, 11)
    for t in range(steps):
        if t <= merge:
            half_gap = merge - t + 1
            a[t, z, y, mid - half_gap - 4 : mid - half_gap] = 1.0
            a[t, z, y, mid + half_gap : mid + half_gap + 4] = 1.0
        else:
            a[t, z, y, mid - 4 : mid + 4] = 1.0
    return a


def yellow(image: np.ndarray, want=MARKER_RGB) -> int:
    """Pixels of the markers' colour (`render.markers.MARKER_RGB`, a warm yellow)."""
    rgb = image[..., :3].astype(int)
    return int((np.abs(rgb - np.asarray(want)).max(axis=-1) < 40).sum())


def cyan(image: np.ndarray) -> int:
    """Pixels of a highlighted track's path (`render.markers.PATH_RGB`)."""
    return yellow(image, PATH_RGB)


def jpeg(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    path = tmp_path_factory.mktemp("viewer-events") / "merge.zarr"
    TimeSeries.from_array(merging_blobs(), source="merge").save(path)
    yield from serving([path])


@pytest.fixture
def client(server):
    c = Client(server)
    yield c
    c.close()


def find(client: Client, **fields) -> tuple[int, dict]:
    rid = client.send({"type": "events", "action": "find", **fields})
    _, reply = client.wait("events", rid, timeout=120)
    return rid, reply


def shown(client: Client) -> int:
    """An update's frame received (every frame before it with it): its id."""
    rid = client.send({"type": "update"})
    client.frame_for(rid)
    return rid


def redrawn(client: Client, newest: int):
    """The next frame, an events message's redraw: it answers `newest`, the newest update
    (a notebook widget waits for its updates' ids only), never the events message's id."""
    got = client._until(lambda g: g[0] == "frame", "no redraw", 60, None, errors_fail=True)
    assert got[1]["id"] == newest
    return got


def test_a_find_lists_the_merge_with_where_it_happened_and_the_tracks(client):
    client.open(0, size=(160, 128))
    _, got = find(client)
    assert got["window"] == [0, 8, 1] and got["dataset"] == 0 and got["view"] == 0
    assert got["mask"].startswith("TF opacity > 0.1")
    assert [(e["kind"], e["step"], e["next_step"]) for e in got["events"]] == [
        ("merge", MERGE, MERGE + 1)
    ]
    merge = got["events"][0]
    assert merge["size"] == 8 * 6 * 4 and merge["at"] == MERGE + 1
    assert merge["centroid"] == [15.5, 7.5, 3.5]  # x, y, z voxels: the middle of the blob
    assert got["counts"]["merge"] == 1 and got["events_total"] == 1
    # The box a click frames holds the merge's centroid (world: the box centred on 0, longest
    # side 1), as a valid focus of the update message.
    box = merge["focus"]
    centre = [(box[k] + box[k + 3]) / 2 for k in range(3)]
    assert centre == pytest.approx([0.0, (8 - 8) / 32, 0.0], abs=1e-3)
    parse_message(f'{{"type": "update", "focus": {box}}}')
    # Two tracks meet at the merge: the global tracks follow one blob through it; each track
    # says its size and mean value at each of its steps.
    assert got["tracks_total"] == len(got["tracks"]) == 2
    longest = got["tracks"][0]
    assert longest["steps"] == list(range(8)) and longest["value"] == [1.0] * 8
    assert longest["size"] == [96] * (MERGE + 1) + [192] * (8 - MERGE - 1)
    other = got["tracks"][1]
    assert other["steps"] == list(range(MERGE + 1)) and other["size"] == [96] * (MERGE + 1)
    assert sorted(merge["tracks"]) == [longest["id"]]
    # A value threshold finds the same, and so does 6-connectivity.
    _, by_value = find(client, by="value", value=0.5, connectivity=6)
    assert by_value["mask"] == "value >= 0.5"
    assert [e["kind"] for e in by_value["events"]] == ["merge"]


def test_markers_are_drawn_in_the_frame_and_the_saved_png_when_shown(server, client):
    client.open(0, size=(192, 160))
    rid = client.send({"type": "update", "camera": {"azimuth": 0, "elevation": 0}})
    _, _, images = client.frame_for(rid)
    before = yellow(jpeg(images[0]))
    find(client)
    client.send({"type": "events", "action": "markers", "show": True})
    _, _, images = redrawn(client, rid)
    marked = jpeg(images[0])
    assert yellow(marked) > before + 15  # the ring and its label "merge 5"
    # Near the middle of the panel: the merge is at the middle of the volume.
    ys, xs = np.nonzero(np.abs(marked.astype(int) - MARKER_RGB).max(axis=-1) < 40)
    h, w = marked.shape[:2]
    assert abs(np.median(xs) - w / 2) < w / 3 and abs(np.median(ys) - h / 2) < h / 3
    # Save PNG draws them too.
    sid = client.send({"type": "save", "what": "image"})
    _, dl = client.wait("download", sid, timeout=120)
    token = {"X-Chronocl-Token": server.token}
    req = urllib.request.Request(server.base + dl["url"], headers=token)
    with urllib.request.urlopen(req, timeout=30) as r:
        png = r.read()
    assert yellow(jpeg(png)) > 15
    # Hidden again, or the events cleared: the frame is as before.
    client.send({"type": "events", "action": "markers", "show": False})
    _, _, images = redrawn(client, rid)
    assert yellow(jpeg(images[0])) <= before + 5
    client.send({"type": "events", "action": "markers", "show": True})
    redrawn(client, rid)
    cid = client.send({"type": "events", "action": "clear"})
    _, cleared = client.wait("events", cid)
    assert cleared["cleared"] is True
    _, _, images = redrawn(client, rid)
    assert yellow(jpeg(images[0])) <= before + 5
    # A window that holds none of the events draws none (the markers of the panel's window).
    client.send({"type": "events", "action": "markers", "show": True})
    find(client)
    rid = client.send({"type": "update", "window": {"t0": 0, "t1": 3}})
    _, _, images = client.frame_for(rid)
    assert yellow(jpeg(images[0])) <= before + 5


def test_a_track_chosen_is_drawn_as_a_path_through_its_centroids(client):
    client.open(0, size=(256, 192))
    rid = client.send({"type": "update", "camera": {"azimuth": 0, "elevation": 0}})
    _, _, images = client.frame_for(rid)
    assert cyan(jpeg(images[0])) == 0
    fid, got = find(client, show=True)
    rid = shown(client)
    moving = got["tracks"][1]  # the blob that ends in the merge: it moves 3 voxels a step
    client.send({"type": "events", "action": "track", "track": moving["id"], "find": fid})
    _, _, images = redrawn(client, rid)
    path = jpeg(images[0])
    assert cyan(path) > 40
    # Seen from the front (azimuth 0: x right), the path runs across: from the right, where
    # the blob started (x 25 of 32), towards the middle (x 19) where it merged.
    ys, xs = np.nonzero(np.abs(path.astype(int) - PATH_RGB).max(axis=-1) < 40)
    assert xs.max() - xs.min() > 25 and ys.max() - ys.min() < xs.max() - xs.min()
    assert xs.max() > path.shape[1] * 0.6
    # No track (null), or the markers hidden: no path.
    client.send({"type": "events", "action": "track", "track": None})
    _, _, images = redrawn(client, rid)
    assert cyan(jpeg(images[0])) < 5
    client.send({"type": "events", "action": "track", "track": moving["id"]})
    redrawn(client, rid)
    client.send({"type": "events", "action": "markers", "show": False})
    _, _, images = redrawn(client, rid)
    assert cyan(jpeg(images[0])) < 5


def test_a_probe_on_a_feature_names_its_track(client):
    client.open(0, size=(256, 192))
    rid = client.send({"type": "probe", "x": 0.5, "y": 0.5})
    _, before = client.wait("probe", rid)
    assert before["voxel"] is not None and "track" not in before  # no events found yet
    fid, got = find(client)
    rid = client.send({"type": "probe", "x": 0.5, "y": 0.5})
    _, probed = client.wait("probe", rid)
    # The middle of the volume: the merged blob, the last step of the window it lies in.
    assert probed["track"] == {"track": got["tracks"][0]["id"], "step": 7, "id": 1, "find": fid}
    # A ray through empty space meets no feature: no track.
    rid = client.send({"type": "probe", "x": 0.02, "y": 0.02})
    _, empty = client.wait("probe", rid)
    assert empty["voxel"] is None and "track" not in empty


@pytest.fixture
def slow_labels(monkeypatch):
    """Each step labelled 0.8 s slower: a find of 8 steps takes 1.6 s or more (steps are
    labelled a few at once)."""
    label = events_run.label_step

    def slow(*args, **kwargs):
        time.sleep(0.8)
        return label(*args, **kwargs)

    monkeypatch.setattr(events_run, "label_step", slow)


def test_a_find_over_a_second_tells_its_progress_and_frames_go_on(client, slow_labels):
    client.open(0, size=(128, 128))
    rid = client.send({"type": "events", "action": "find"})
    # A frame answers input while the find runs (it is on the side thread).
    t0 = time.monotonic()
    moved = client.send({"type": "update", "camera": {"azimuth": 75}})
    client.frame_for(moved)
    assert time.monotonic() - t0 < 2.5
    progress = []
    while True:
        kind, msg = client.recv(60)[:2]
        if kind == "progress" and msg["what"] == "events":
            progress.append(msg)
        if kind == "events" and msg["id"] == rid:
            break
    assert [e["kind"] for e in msg["events"]] == ["merge"] and msg["seconds"] > 1.2
    assert progress and all(p["total"] == 8 and p["id"] == rid for p in progress)
    assert [p["done"] for p in progress] == sorted(p["done"] for p in progress)
    assert progress[-1]["done"] >= 4


def test_a_find_is_given_up_when_the_window_changes(client, slow_labels):
    client.open(0, size=(128, 128))
    rid = client.send({"type": "events", "action": "find"})
    time.sleep(0.8)
    client.send({"type": "update", "window": {"t0": 1, "t1": 7}})
    t0 = time.monotonic()
    _, got = client.wait("events", rid, timeout=30)
    assert got["cancelled"] == "the window changed; find again"
    assert time.monotonic() - t0 < 2.0  # given up at the next step, not at the end
    # A find of the new window runs to its end.
    _, found = find(client)
    assert found["window"] == [1, 7, 1] and [e["kind"] for e in found["events"]] == ["merge"]


def test_without_the_events_extra_the_panel_names_the_install_and_the_viewer_works(
    client, monkeypatch
):
    def missing(module):
        raise extra.MissingExtraError(f"feature tracking needs {module}; {extra.INSTALL}")

    monkeypatch.setattr(extra, "require", missing)
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "cc3d" else real(name, *a)
    )
    assert protocol.choices()["events"]["available"] is False
    assert protocol.choices()["events"]["install"] == "pip install 'chronocl[events]'"
    client.open(0, size=(128, 128))
    _, got = find(client)
    assert got["missing"] == "pip install 'chronocl[events]'" and "events" not in got
    rid = client.send({"type": "update", "camera": {"azimuth": 120}})
    _, header, _ = client.frame_for(rid)
    assert header["id"] == rid


@pytest.mark.parametrize(
    "msg, says",
    [
        ({"action": "find", "by": "value"}, "events.value is missing"),
        ({"action": "find", "value": 0.5}, "events.value does not go with by opacity"),
        ({"action": "find", "connectivity": 8}, "choose 6, 18 or 26"),
        ({"action": "find", "opacity": 1.5}, "events.opacity"),
        ({"action": "markers"}, "events.show is missing"),
        ({"action": "clear", "view": 1}, "events.view does not go with clear"),
        ({"action": "markers", "show": True, "track": 1}, "events.track does not go with"),
        ({"action": "track"}, "events.track is missing"),
        ({"action": "track", "track": -1}, "events.track"),
        ({"action": "dance"}, "events.action"),
        ({"action": "find", "track": 3}, "events.track does not go with find"),
        ({"action": "find", "find": 3}, "events.find does not go with find"),
        ({"action": "markers", "show": True, "find": 3}, "events.find does not go with markers"),
        ({"action": "find", "colour": 3}, "unknown field 'colour'"),
        ({}, "missing the field 'action'"),
    ],
)
def test_bad_events_messages_are_refused_in_one_line(msg, says):
    import json

    with pytest.raises(ProtocolError) as got:
        parse_message(json.dumps({"type": "events", **msg}))
    text = str(got.value)
    assert says in text and "\n" not in text


def test_a_bad_events_message_is_answered_and_the_socket_serves_on(client):
    client.open(0, size=(128, 128))
    rid = client.send({"type": "events", "action": "find", "view": 3})
    errors: list = []
    client.wait("error", rid, errors=errors)
    assert errors[0]["message"] == "view 3 is not shown; choose a view on the page"
    _, got = find(client)
    assert [e["kind"] for e in got["events"]] == ["merge"]


def test_the_focus_box_stays_within_the_protocols_bounds():
    assert focus_box(np.array([0.5, -0.5, 0.0]), 0.7) == [0.0, -1.0, -0.5, 1.0, 0.0, 0.5]
    assert focus_box(np.array([0.1, 0.2, 0.3]), 0.1) == pytest.approx([0, 0.1, 0.2, 0.2, 0.3, 0.4])


def test_a_redraw_answers_the_newest_framed_request():
    """The markers' frame answers the request waiting, else the one last shown: never the
    events message's id, never an older request's than the one waiting."""
    import threading

    from chronocl.viewer.events_panel import EventTasks

    class Worker(EventTasks):
        def __init__(self) -> None:
            self._cond = threading.Condition()
            self._pending = None
            self._last_rid = 5
            self.asked: list = []

        def update(self, msg: dict) -> None:
            with self._cond:
                self.asked.append(msg["id"])
                self._pending = ("state", msg["id"])

    w = Worker()
    w._redraw()
    assert w.asked == [5]  # the one last shown
    w._pending = ("state", 9)  # newer input waits: the redraw answers it
    w._redraw()
    assert w.asked[-1] == 9
    w._pending, w._last_rid = None, None  # nothing shown yet
    w._redraw()
    assert w.asked[-1] is None


def test_a_step_of_too_many_features_is_refused_in_one_line(client, monkeypatch):
    from chronocl.viewer import events_panel

    monkeypatch.setattr(events_panel, "MAX_FEATURES_PER_STEP", 1)  # the blobs' steps hold 2
    client.open(0, size=(128, 128))
    rid = client.send({"type": "events", "action": "find"})
    errors: list = []
    client.wait("error", rid, timeout=60, errors=errors)
    text = errors[0]["message"]
    assert text.startswith("2 features in step 0: raise the threshold") and "\n" not in text
    monkeypatch.setattr(events_panel, "MAX_FEATURES_PER_STEP", 2)
    _, got = find(client)  # at the cap: found
    assert [e["kind"] for e in got["events"]] == ["merge"]


def test_markers_are_placed_once_for_a_panels_steps_and_at_most_max_events(client, monkeypatch):
    from chronocl.events.graph import EventGraph
    from chronocl.viewer.events_panel import MAX_EVENTS

    calls: list = []
    real = EventGraph.markers

    def counted(self, steps=None, limit=None):
        calls.append((tuple(steps) if steps is not None else None, limit))
        return real(self, steps) if limit is None else real(self, steps, limit)

    monkeypatch.setattr(EventGraph, "markers", counted)
    client.open(0, size=(128, 128))
    find(client, show=True)
    for azimuth in (10, 20, 30):
        client.frame_for(client.send({"type": "update", "camera": {"azimuth": azimuth}}))
    assert calls == [(tuple(range(8)), MAX_EVENTS)]  # the first frame's, kept
    graph = events_run.events(merging_blobs(), threshold=0.5)
    assert len(graph.markers()) == 1 and graph.markers(limit=0) == []


def test_a_frame_after_an_events_message_carries_the_newest_updates_id(client):
    client.open(0, size=(128, 128))
    rid = shown(client)
    fid, _ = find(client, show=True)  # the find's redraw
    later = shown(client)
    assert later > fid > rid
    mid = client.send({"type": "events", "action": "markers", "show": False})
    _, header, _ = redrawn(client, later)
    assert header["id"] != mid
    client.send({"type": "events", "action": "markers", "show": True})
    redrawn(client, later)


def test_a_find_whose_window_changed_while_tracking_is_not_kept(client, monkeypatch):
    import threading

    tracking = threading.Event()
    real = events_run.tracks_of

    def slow(*args, **kwargs):  # after the last labelling checkpoint
        tracking.set()
        time.sleep(1.0)
        return real(*args, **kwargs)

    monkeypatch.setattr(events_run, "tracks_of", slow)
    client.open(0, size=(256, 192))
    rid = client.send({"type": "events", "action": "find", "show": True})
    assert tracking.wait(30)
    client.send({"type": "update", "window": {"t0": 1, "t1": 7}})
    _, got = client.wait("events", rid, timeout=30)
    assert got["cancelled"] == "the window changed; find again"
    # Nothing kept: a probe names no track.
    pid = client.send({"type": "probe", "x": 0.5, "y": 0.5})
    _, probed = client.wait("probe", pid)
    assert probed["voxel"] is not None and "track" not in probed


def test_a_track_chosen_in_an_older_finds_list_is_ignored(client):
    client.open(0, size=(256, 192))
    client.frame_for(client.send({"type": "update", "camera": {"azimuth": 0, "elevation": 0}}))
    old, _ = find(client, show=True)
    new, got = find(client, show=True, connectivity=6)
    shown(client)
    moving = got["tracks"][1]
    client.send({"type": "events", "action": "track", "track": moving["id"], "find": old})
    rid = client.send({"type": "update"})
    _, _, images = client.frame_for(rid)
    assert cyan(jpeg(images[0])) < 5  # not highlighted
    client.send({"type": "events", "action": "track", "track": moving["id"], "find": new})
    _, _, images = redrawn(client, rid)
    assert cyan(jpeg(images[0])) > 40


def test_a_histogram_is_answered_while_a_find_runs(client, slow_labels):
    client.open(0, size=(128, 128))
    rid = client.send({"type": "events", "action": "find"})
    time.sleep(0.3)
    t0 = time.monotonic()
    hid = client.send({"type": "histogram", "range": [0.0, 1.0]})
    order = []
    while len(order) < 2:
        kind, msg = client.recv(60)[:2]
        if kind == "histogram" and msg.get("id") == hid:
            order.append(("histogram", time.monotonic() - t0))
        elif kind == "events" and msg.get("id") == rid:
            order.append(("events", time.monotonic() - t0))
    assert order[0][0] == "histogram" and order[0][1] < 1.0, order
    assert order[1][0] == "events"


@pytest.fixture
def own_server(tmp_path):
    """A server of its own: nothing an earlier test's clients made resident is held still."""
    path = tmp_path / "merge.zarr"
    TimeSeries.from_array(merging_blobs(), source="merge").save(path)
    yield from serving([path])


def test_a_find_labels_the_steps_the_view_holds_and_reads_the_others(own_server, monkeypatch):
    """Before the view's first frame nothing is resident: the find reads each step of the
    window from the store once. After it, the view's window manager holds the window: the find
    labels the steps where they lie, reading none, and finds the same. (On the module's server
    an earlier test's window could still be held, and the first find then read nothing.)"""
    server = own_server
    reads: list[int] = []
    real = TimeSeries.read_brick

    def counted(self, steps, *args, **kwargs):
        reads.extend(int(s) for s in steps)
        return real(self, steps, *args, **kwargs)

    monkeypatch.setattr(TimeSeries, "read_brick", counted)
    c = Client(server)
    try:
        c.wait("dataset", c.send({"type": "open", "dataset": 0}))
        _, streamed = find(c)
        assert sorted(reads) == list(range(8))
        c.frame_for(c.send({"type": "update", "size": [128, 128]}))  # the window resident
        reads.clear()
        _, held = find(c)
        assert reads == []
        assert [e["kind"] for e in held["events"]] == ["merge"]
        assert held["events"] == streamed["events"] and held["tracks"] == streamed["tracks"]
    finally:
        c.close()


def test_the_panel_s_find_labels_on_the_viewer_s_threads(server, monkeypatch):
    """The viewer's --memory is a promise about its own process, whose memory is all it sees:
    a find of a stored window, even one that `find` would label on worker processes, stays on
    its threads."""
    made: list[int] = []

    class Counted(events_run.Labellers):
        def __init__(self, *args, **kwargs):
            made.append(len(made))
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(events_run, "Labellers", Counted)
    monkeypatch.setenv("CHRONOCL_THREADS", "2")
    monkeypatch.setattr(events_run, "PROCESS_MIN_VOXELS", 0)  # any window would do
    c = Client(server)
    try:
        c.wait("dataset", c.send({"type": "open", "dataset": 0}))  # nothing resident yet
        _, reply = find(c)
        assert [e["kind"] for e in reply["events"]] == ["merge"]
        assert made == []
    finally:
        c.close()
