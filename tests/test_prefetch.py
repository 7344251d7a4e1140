"""Time-aware prefetch over a real HTTP store on loopback with latency (tests/remote_servers.py).

The scrub's speed comes from the requests' times: the tests give the manager's `ScrubModel`
a clock of their own, so a "fast" and a "slow" scrub are exactly that, while the read time of
a step is measured from the real reads. Interleavings are forced with a gate in the server
(chunk requests wait for it), not with sleeps.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

import chronocl
from chronocl import WindowManager
from chronocl.data.scrub_model import ScrubModel
from chronocl.data.series import write_series

from .remote_servers import StoreServer, _Handler

pytest.importorskip("aiohttp")

SHAPE = (40, 4, 8, 16)  # 2 rows of 8 x 16 float32 a chunk: 2 chunks a step
ROWS = 2
STEP_BYTES = 4 * 8 * 16 * 4
LATENCY_S = 0.03


class _GatedHandler(_Handler):
    """Chunk requests wait for the server's `gate` (metadata does not)."""

    def do_GET(self) -> None:
        if "/c/" in self.path:
            assert self.server.gate.wait(30), "the test never opened the gate"
        super().do_GET()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    root = tmp_path_factory.mktemp("prefetch")
    data = np.random.default_rng(3).random(SHAPE, dtype=np.float32)
    write_series(
        root / "p.zarr",
        list(data),
        n_steps=SHAPE[0],
        volume_shape=SHAPE[1:],
        dtype=np.float32,
        chunk_bytes=ROWS * SHAPE[2] * SHAPE[3] * 4,
    )
    with StoreServer(root, latency_s=LATENCY_S) as srv:
        srv.gate = threading.Event()
        srv.gate.set()
        srv.RequestHandlerClass = _GatedHandler
        yield srv
        srv.gate.set()


class Clock:
    """A clock that moves only when told: the scrub's requests are `dt` apart."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def manager(server, clock: Clock, steps: int = 16) -> WindowManager:
    series = chronocl.open(server.url("p.zarr"))
    wm = WindowManager(series, memory=steps * STEP_BYTES, threads=2)
    wm.scrub.clock = clock
    return wm


def within_budget(wm: WindowManager) -> bool:
    state = wm.state()
    held = len(state["resident"]) + len(state["loading"])
    return held <= wm.capacity and wm.resident_bytes <= wm.budget


def scrub(wm: WindowManager, clock: Clock, starts, dt: float, width: int = 4) -> list[int]:
    """Slide forward through `starts`, `dt` seconds apart; the steps read ahead each time."""
    aheads = []
    for start in starts:
        clock.now += dt
        wm.get(range(start, start + width), direction=+1)
        aheads.append(wm.state()["ahead"])
        assert within_budget(wm)
    return aheads


def test_a_fast_scrub_reads_further_ahead_than_a_slow_one(server) -> None:
    clock = Clock()
    with manager(server, clock) as slow, manager(server, clock) as fast:
        slow_ahead = scrub(slow, clock, range(0, 4), dt=1.0)  # 1 step a second
        fast_ahead = scrub(fast, clock, range(0, 4), dt=0.01)  # 100 steps a second
        assert fast.scrub.read_s >= LATENCY_S  # measured: a step is two requests
        assert [len(a) for a in slow_ahead] == [1, 1, 1, 1]
        assert len(fast_ahead[0]) == 1  # the first request: speed unknown
        # 100 steps/s x >= 0.06 s a step x 1.5: at least 9, capped by the 12 free slots.
        assert len(fast_ahead[-1]) >= 5 > len(slow_ahead[-1])
        assert fast_ahead[-1] == list(range(7, 7 + len(fast_ahead[-1])))
        # What was planned is fetched, once each.
        last = fast_ahead[-1]
        fast.request(range(3, last[-1] + 1)).result(timeout=30)
        assert all(fast.reads[s] == 1 for s in range(0, last[-1] + 1))
        assert within_budget(fast)


def test_a_turn_cancels_the_loads_ahead_in_the_old_direction(server) -> None:
    clock = Clock()
    with manager(server, clock) as wm:
        scrub(wm, clock, range(0, 3), dt=0.01)  # measures a step's read time
        clock.now += 10  # a pause: the old speed is forgotten
        server.gate.clear()
        server.requests.clear()
        try:
            for start in (20, 21, 22):  # fast, forward, nothing arrives
                clock.now += 0.01
                wm.request(range(start, start + 4), direction=+1)
            before = wm.state()
            old_ahead = before["ahead"]
            assert len(old_ahead) >= 3 and old_ahead[0] == 26
            assert set(old_ahead) <= set(before["loading"])
            cancelled = wm.cancelled
            assert within_budget(wm)
            clock.now += 0.01
            back = wm.request(range(21, 25), direction=-1)  # the user turns
            after = wm.state()
            assert not set(after["loading"]) & set(old_ahead)
            assert after["ahead"] == [20]  # a new direction: speed unknown, one step
            assert wm.cancelled - cancelled >= len(old_ahead)
        finally:
            server.gate.set()
        back.result(timeout=30)
        assert all(wm.reads[s] == 0 for s in old_ahead)
        # Two readers: the steps ahead were queued behind the window's, never requested.
        asked = {int(p.split("/c/")[1].split("/")[0]) for p in server.chunk_requests()}
        assert not asked & set(old_ahead)
        assert within_budget(wm)


def test_two_panels_scrubbing_apart_never_cancel_each_others_loads(server, monkeypatch) -> None:
    """Two owners of one manager (a viewer's panels, each with its own window) scrub fast in
    opposite directions while nothing arrives: a request cancels only its own owner's loads
    (steps leaving its window, its old reads ahead), never the other's window or reads ahead,
    each scrub reads ahead in its own direction, and both windows arrive within the budget."""

    class Panel:  # an owner: what a session is to its manager
        pass

    left, right = Panel(), Panel()
    clock = Clock()
    with manager(server, clock, steps=24) as wm:
        for start in range(3):
            clock.now += 0.01
            wm.get(range(start, start + 4), direction=+1, owner=left)
        clock.now += 10
        # A step's read time fixed at 20 ms (3 steps read ahead at the scrubs' 100 steps/s):
        # measured, a loaded machine's slow reads made each panel read ahead as far as the
        # budget allowed, and the windows then rightly took the other panel's reads ahead.
        monkeypatch.setattr(ScrubModel, "record_read", lambda self, seconds: None)
        wm.scrub.read_s = wm._owners[id(left)].scrub.read_s = 0.02
        cancelled: dict[str, list[int]] = {"left": [], "right": []}
        theirs: list[int] = []  # steps cancelled that the other panel wanted or read ahead
        asking = ["left"]
        cancel = wm._cancel

        def spy(load) -> None:
            other = wm._owners.get(id(right if asking[0] == "left" else left))
            if other is not None and load.step in other.wanted | set(other.ahead):
                theirs.append(load.step)
            cancelled[asking[0]].append(load.step)
            cancel(load)

        wm._cancel = spy

        def ask(name, steps, direction):
            asking[0] = name
            return wm.request(steps, direction, owner=left if name == "left" else right)

        server.gate.clear()
        try:
            for a, b in ((2, 30), (3, 29), (4, 28)):  # fast, apart, nothing arrives
                clock.now += 0.01
                forward = ask("left", range(a, a + 4), +1)
                backward = ask("right", range(b, b + 4), -1)
            state = wm.state()
            ahead = state["ahead"]
            assert {8, 9, 27} <= set(ahead), ahead  # each read ahead in its own direction
            held = set(state["loading"]) | set(state["resident"])
            assert set(ahead) | set(range(4, 8)) | set(range(28, 32)) <= held
            assert not forward.superseded and not backward.superseded
            assert within_budget(wm)
            turned = ask("left", range(3, 7), -1)  # the left panel turns: its reads ahead go
            assert forward.superseded and not backward.superseded
            assert 27 in wm.state()["ahead"] and 8 not in wm.state()["loading"]
        finally:
            server.gate.set()
        assert not theirs and 7 in cancelled["left"] and 33 in cancelled["right"], cancelled
        assert [a[0, 0, 0] for a in turned.result(timeout=30)] == [
            a[0, 0, 0] for a in wm.get(range(3, 7), owner=left)
        ]
        backward.result(timeout=30)
        assert within_budget(wm)


def test_the_model_forgets_a_stopped_scrub_and_a_turn() -> None:
    clock = Clock()
    model = ScrubModel(clock)
    model.record_read(0.19)
    for start in range(5):
        clock.now += 0.05
        model.record_request(start, +1)
    assert model.velocity() == pytest.approx(20.0)
    assert model.ahead() == 6  # 1.5 x 20 steps/s x 0.19 s = 5.7
    assert model.ahead(stride=3) == 2
    clock.now += 5.0
    assert model.velocity() == 0.0 and model.ahead() == 1  # stopped
    model.record_request(5, +1)
    clock.now += 0.05
    model.record_request(4, -1)  # a turn starts a new history
    assert model.velocity() == 0.0


def test_the_viewer_sends_each_views_resident_steps(tmp_path) -> None:
    pytest.importorskip("starlette")
    from .viewer_helpers import Client, make_stores, start_server

    server = start_server(make_stores(tmp_path)[:1])  # 12 steps: the window is [1, 11)
    client = Client(server)
    try:
        client.open(0, size=(64, 64))
        rid = client.send({"type": "update", "views": [{"mode": "max"}, {"mode": "alpha"}]})
        client.frame_for(rid)

        def whole(views: list) -> bool:
            return len(views) == 2 and all(
                v and set(range(1, 11)) <= set(v["resident"]) for v in views
            )

        # Messages while steps load first, then the whole window resident; that one may come
        # before the frame (the steps were read for the first view's refine already).
        seen = [m["views"] for m in client.steps]
        while not (seen and whole(seen[-1])):
            _, msg = client.wait("steps", timeout=30)
            seen.append(msg["views"])
        views = seen[-1]
        assert views[0] == views[1]  # one manager: the views share the data set's steps
        assert not set(views[0]["resident"]) & set(views[0]["loading"])
    finally:
        client.close()
        server.stop()
