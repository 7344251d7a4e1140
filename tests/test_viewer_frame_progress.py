"""A frame answering input tells the page how far it got (issue 49): `progress` messages of
what "frame", with the request's id, from the same checkpoints a refine reports
(`chronocl.viewer.progress`), the last one "drawing" before the frame itself. Over the socket,
no browser (`test_viewer_busy_browser` checks what the busy box makes of them).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from chronocl.core.tuning import TUNING
from chronocl.data import synthetic
from chronocl.data.timeseries import TimeSeries

from .viewer_helpers import Client, start_server


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    path = tmp_path_factory.mktemp("viewer-frame-progress") / "vortex.zarr"
    data = np.stack(list(synthetic.steps("vortex", 24, (64, 64, 64))))
    TimeSeries.from_array(data, source="vortex").save(path)
    srv = start_server([path])
    yield srv
    srv.stop()


def notes_until_frame(client: Client, rid: int) -> list[dict]:
    """The `progress` messages of what "frame" before the frame answering `rid`."""
    notes = []
    while True:
        got = client.recv(60)
        if got[0] == "progress" and got[1]["what"] == "frame":
            notes.append(got[1])
        if got[0] == "frame" and (got[1]["id"] or 0) >= rid:
            return notes


def test_a_frame_answering_input_reports_its_stages(server, monkeypatch):
    monkeypatch.setattr(TUNING, "frame_progress_after_s", 0.0)  # (the frames here are quick)
    c = Client(server)
    try:
        c.open(0, size=(96, 96))
        # a jump: the window's steps read and integrated, then drawn
        rid = c.send({"type": "update", "window": {"t0": 12, "t1": 20}})
        notes = notes_until_frame(c, rid)
        assert notes and all(n["id"] == rid and n["view"] is None for n in notes), notes
        assert notes[-1]["stage"] == "drawing", notes
        stages = {n["stage"] for n in notes}
        assert stages & {"reading steps", "integrating", "sliding"}, notes
        for n in notes:
            assert 0 <= n["done"] <= n["total"] and n["views"] == 1, n
        # a mode change integrates the window again: its slabs counted, in order
        rid = c.send({"type": "update", "views": [{"mode": "max"}]})
        notes = notes_until_frame(c, rid)
        slabs = [n["done"] for n in notes if n["stage"] == "integrating"]
        assert slabs == sorted(slabs) and notes[-1]["stage"] == "drawing", notes
        # a camera turn only draws
        rid = c.send({"type": "update", "camera": {"azimuth": 50.0}})
        assert [n["stage"] for n in notes_until_frame(c, rid)] == ["drawing"]
    finally:
        c.close()


def test_a_quick_frame_sends_no_progress_and_a_slow_one_does(server, monkeypatch):
    """Reports come only once a frame has worked `frame_progress_after_s` (the page shows none
    sooner): none for a quick frame, and a slow frame's from then on."""
    c = Client(server)
    try:
        c.open(0, size=(96, 96))
        monkeypatch.setattr(TUNING, "frame_progress_after_s", 60.0)
        rid = c.send({"type": "update", "window": {"t0": 4, "t1": 12}})
        assert notes_until_frame(c, rid) == []
        # The progress of one that worked past the delay (here: none), the last one drawing.
        monkeypatch.setattr(TUNING, "frame_progress_after_s", 1e-9)
        rid = c.send({"type": "update", "window": {"t0": 13, "t1": 21}})
        notes = notes_until_frame(c, rid)
        assert notes and notes[-1]["stage"] == "drawing", notes
    finally:
        c.close()


def test_a_report_of_the_quiet_time_is_sent_when_it_ends(monkeypatch):
    """A stage reported early that then runs long is named once the quiet time ends (the busy
    box shows from 400 ms); a frame sent within the quiet time sends nothing, then or later."""
    import time

    from chronocl.viewer.progress import RefineProgress

    monkeypatch.setattr(TUNING, "frame_progress_after_s", 0.2)
    sent: list[dict] = []
    slow = RefineProgress(sent.append, 1, "frame", 7)
    slow("reading steps", 1, 2)
    slow("integrating", 0, 1)  # the newest is the one held
    assert sent == []
    deadline = time.monotonic() + 30  # the work goes on: the held report goes when it ends
    while not sent and time.monotonic() < deadline:
        time.sleep(0.01)
    assert [(m["stage"], m["id"], m["what"]) for m in sent] == [("integrating", 7, "frame")]
    slow("drawing", 0, 1)  # after it, at once
    slow.finish()
    assert [m["stage"] for m in sent] == ["integrating", "drawing"]

    quick: list[dict] = []
    fast = RefineProgress(quick.append, 1, "frame", 8)
    fast("integrating", 0, 1)
    fast("drawing", 0, 1)
    fast.finish()  # the frame went within the quiet time
    time.sleep(0.4)
    assert quick == []


def test_no_report_goes_after_its_frame(tmp_path, monkeypatch):
    """A frame whose delivery outlasts the quiet time (a slow page or comm): its held report
    ("drawing") is not sent after it."""
    import json
    import threading
    import time

    from chronocl.viewer.datasets import open_datasets
    from chronocl.viewer.saving import Downloads
    from chronocl.viewer.worker import ClientWorker

    path = tmp_path / "v.zarr"
    TimeSeries.from_array(np.stack(list(synthetic.steps("vortex", 6, (16, 16, 16))))).save(path)
    log: list[str] = []
    framed = threading.Event()

    def send(data, wait=True) -> bool:
        if isinstance(data, bytes):
            log.append("frame")
            time.sleep(0.5)  # delivered slowly: the quiet time ends meanwhile
            framed.set()
        else:
            msg = json.loads(data)
            log.append(f"{msg['type']}:{msg.get('what')}:{msg.get('stage')}")
        return True

    worker = ClientWorker(open_datasets([path]), send, Downloads(), engine="numpy")
    try:
        worker.open(0, 1, frame=True)
        assert framed.wait(60)
        time.sleep(1.0)  # its refine, if any
        monkeypatch.setattr(TUNING, "frame_progress_after_s", 0.25)
        log.clear()
        framed.clear()
        worker.update({"type": "update", "id": 2, "camera": {"azimuth": 40.0}})
        assert framed.wait(60)
        time.sleep(0.5)
        assert "frame" in log
        after = log[log.index("frame") + 1 :]
        assert not [m for m in after if m.startswith("progress:frame")], log
    finally:
        worker.close()


def test_reported_work_is_heard_and_neither_given_up_nor_split():
    """A frame answering input runs under `interrupt.reported`: its checkpoints reach the
    progress, but it is not `watched`, so a session integrates it whole and a gather goes in
    one piece, as without the report (a refine, `interruptible`, goes in pieces)."""
    from chronocl.core.interrupt import checkpoint, heard, interruptible, reported, watched

    told: list[tuple] = []
    assert not heard() and not watched()
    with reported(lambda *p: told.append(p)):
        assert heard() and not watched()
        checkpoint("reading steps", 1, 4)
    with interruptible(lambda: False, lambda *p: told.append(p)):
        assert heard() and watched()
        checkpoint("integrating", 2, 8)
    assert told == [("reading steps", 1, 4), ("integrating", 2, 8)]
