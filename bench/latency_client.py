"""The WebSocket client of bench/viewer_latency.py and the inputs it times: a page's open, data-TF
edits that never repeat a value, one-step scrub slides (with the longest stall between frames),
scrub stops and edits sent while a refine runs. Times are perf_counter seconds of arrival; a
frame is sharp (full resolution) when its header says level 0 and not `reduced`."""

from __future__ import annotations

import json
import time
from contextlib import ExitStack

from chronocl.core.tuning import TUNING
from chronocl.viewer.protocol import unpack_frame
from chronocl.viewer.server import ViewerServer

WINDOW = 10  # steps
SLIDES_PER_STOP = 3
PROBE_DELAYS_MS = (50, 150, 300)  # after the refine was due


def sharp(header: dict) -> bool:
    """Full resolution at full quality: level 0, drawn at the panel's size, not a preview
    (which is level 0 too, but half scale and JPEG 70)."""
    return (
        header.get("level", 0) == 0
        and not header.get("reduced", False)
        and header.get("quality", "full") == "full"
    )


class Client:
    """A WebSocket client that logs every message's arrival (perf_counter seconds)."""

    def __init__(self, server: ViewerServer) -> None:
        from websockets.sync.client import connect

        # Entered as a context manager: websockets 17.1 deprecates a bare connect().
        self._stack = ExitStack()
        url = f"ws://127.0.0.1:{server.port}/ws?token={server.token}"
        self.ws = self._stack.enter_context(connect(url, compression=None, max_size=2**26))
        self.rid, self.sent = 0, {}
        self.log: list[tuple[float, str, dict]] = []  # (arrival, "frame" or a text type, msg)
        self.dataset: dict | None = None
        self.t0, self.step = 0, 1
        json.loads(self.ws.recv())  # info

    def send(self, msg: dict) -> int:
        self.rid += 1
        self.sent[self.rid] = time.perf_counter()
        self.ws.send(json.dumps({**msg, "id": self.rid}))
        return self.rid

    def next(self, timeout: float = 900.0) -> tuple[float, str, dict]:
        m = self.ws.recv(timeout=timeout)
        t = time.perf_counter()
        if isinstance(m, bytes):
            entry = (t, "frame", unpack_frame(m)[0])
        else:
            d = json.loads(m)
            if d["type"] == "error":
                raise RuntimeError(d["message"])
            if d["type"] == "dataset":
                self.dataset = d
            entry = (t, d["type"], d)
        self.log.append(entry)
        return entry

    def pump(self, until: float) -> None:
        """Take the messages that come until perf_counter() reaches `until`."""
        while (left := until - time.perf_counter()) > 0:
            try:
                self.next(timeout=left)
            except TimeoutError:
                return

    def wait(self, rid: int, full: bool = False) -> tuple[float, dict]:
        """The first frame answering request `rid` (`full`: its first sharp one): (ms since the
        request was sent, its header); frames already logged count."""
        for t, kind, h in self.log:
            if kind == "frame" and h["id"] == rid and (not full or sharp(h)):
                return 1e3 * (t - self.sent[rid]), h
        while True:
            t, kind, h = self.next()
            if kind == "frame" and h["id"] == rid and (not full or sharp(h)):
                return 1e3 * (t - self.sent[rid]), h

    def chain(self, rid: int) -> list[dict]:
        """The headers of the frames logged for request `rid`, up to its first sharp one."""
        out = []
        for _, kind, h in self.log:
            if kind == "frame" and h["id"] == rid:
                out.append(h)
                if sharp(h):
                    break
        return out

    def request(self, msg: dict, full: bool = False) -> tuple[float, dict]:
        return self.wait(self.send(msg), full)

    def open(self, size: tuple[int, int]) -> dict:
        """Open data set 0 as the page does; the ms to the first frame and to the sharp one."""
        t_open = self.sent[self.send({"type": "open", "dataset": 0})]
        while self.dataset is None:
            self.next()
        state = self.dataset["state"]
        self.t0 = state["window"]["t0"]
        views = [{"mode": v["mode"], "order": v["order"]} for v in state["views"]]
        rid = self.send({"type": "update", "size": list(size), "views": views})
        ms, header = self.wait(rid, full=True)
        first = next(t for t, kind, _ in self.log if kind == "frame")
        ms_full = ms + 1e3 * (self.sent[rid] - t_open)
        return {"first_ms": 1e3 * (first - t_open), "full_ms": ms_full, "header": header}

    def slide(self, n_steps: int, quality: str = "preview") -> dict:
        """A one-step slide of the window, turning at either end of the series: a drag's
        (the page's timeline sends "preview" while dragging, "full" when it is let go)."""
        if not 0 <= self.t0 + self.step <= n_steps - WINDOW:
            self.step = -self.step
        self.t0 += self.step
        window = {"t0": self.t0, "t1": self.t0 + WINDOW, "stride": 1}
        return {"type": "update", "window": window, "quality": quality}


class Edits:
    """Data-TF edits as the page sends them: one control point's opacity moved to a value no
    edit before had (golden-ratio steps over [0.1, 0.9]), so none is a cache hit."""

    def __init__(self, data_tf: dict) -> None:
        self.tf, self.k = data_tf, 0

    def __call__(self) -> dict:
        self.k += 1
        pts = [list(p) for p in self.tf["points"]]
        pts[2][4] = round(0.1 + 0.8 * ((self.k * 0.6180339887) % 1.0), 6)
        return {"type": "update", "data_tf": {**self.tf, "points": pts}}


def tf_edits(c: Client, edit: Edits, count: int) -> tuple[list, list, list]:
    """`count` edits, each to its sharp frame: [(ms, header)] of the first frames, of the sharp
    ones, and each edit's chain of frame headers (the first to the sharp one)."""
    firsts, fulls, chains = [], [], []
    for _ in range(count):
        first = c.request(edit())
        firsts.append(first)
        fulls.append(first if sharp(first[1]) else c.wait(c.rid, full=True))
        chains.append(c.chain(c.rid))
    return firsts, fulls, chains


def scrub(c: Client, n_steps: int, count: int) -> tuple[list, dict]:
    """`count` one-step slides, each sent when the last one's first frame came: their
    (ms, header), and the longest gap between consecutive frames (with whether a histogram
    reply arrived within it)."""
    start = len(c.log)
    got = [c.request(c.slide(n_steps)) for _ in range(count)]
    prev, seen_hist = c.sent[c.rid - count + 1], False
    stall = {"ms": 0.0, "after_histogram": False}
    for t, kind, _ in c.log[start:]:
        if kind == "histogram":
            seen_hist = True
        elif kind == "frame":
            if 1e3 * (t - prev) > stall["ms"]:
                stall = {"ms": round(1e3 * (t - prev), 2), "after_histogram": seen_hist}
            prev, seen_hist = t, False
    return got, stall


def scrub_stops(c: Client, n_steps: int, count: int) -> list:
    """`count` stops: SLIDES_PER_STOP slides in a row, then the last one's sharp frame."""
    out = []
    for _ in range(count):
        for _ in range(SLIDES_PER_STOP - 1):
            c.request(c.slide(n_steps))
        out.append(c.request(c.slide(n_steps, "full"), full=True))  # let go
    return out


def refine_probes(c: Client, edit: Edits) -> list[dict]:
    """An edit sent while the last edit's refine runs (PROBE_DELAYS_MS after it was due): the
    ms to the first frame answering it, and whether the refine was still running then."""
    out = []
    for delay in PROBE_DELAYS_MS:
        ms, h = c.request(edit())
        before = c.rid
        c.pump(c.sent[before] + ms / 1e3 + TUNING.refine_after_s + delay / 1e3)
        done = any(k == "frame" and m["id"] == before and sharp(m) for _, k, m in c.log)
        wait_ms, _ = c.request(edit())
        c.wait(c.rid, full=True)  # settled before the next probe
        out.append(
            {"delay_ms": delay, "wait_ms": round(wait_ms, 2), "in_refine": not (sharp(h) or done)}
        )
    return out
