"""Shared pieces of the viewer tests: small stores, a server on a thread, a socket client."""

from __future__ import annotations

import json
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np
import pytest

from chronocl import modes
from chronocl.core.selection import Selection
from chronocl.data import synthetic
from chronocl.data.series import TimeSeries, open_series
from chronocl.data.simulations import simulate
from chronocl.integration.fit_range import window_range
from chronocl.viewer.protocol import unpack_frame
from chronocl.viewer.server import ViewerServer

BROWSER_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
]
CHROMIUM = "/usr/bin/chromium"

# A page function: true once the frame after `seq` is the full-quality answer to the newest
# request, not a coarse or refining one.
SETTLED_FRAME = """([seq]) => {
  const v = window.viewer, l = v && v.last;
  return !!l && l.seq > seq && l.quality === 'full' && l.id >= v.sent && !l.refining;
}"""


@pytest.fixture
def full_size_frames(monkeypatch):
    """Frames drawn at the panels' full size (never a little smaller for the latency target,
    as a slow moment on a busy machine would make them): frames compared are the same size.
    A module uses it by importing it (autouse there with `pytestmark` or by name)."""
    from chronocl.viewer import frames, worker

    monkeypatch.setattr(worker, "DrawBudget", lambda: frames.DrawBudget(target_ms=1e9))


def launch_browser():
    """Headless Chromium for a module's tests (a generator for a module-scoped fixture)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=BROWSER_ARGS)
        yield b
        b.close()


@contextmanager
def browser_page(width: int = 1280, height: int = 820):
    """A headless Chromium page of `width` x `height` and the page errors it raises (a list
    to assert empty), closed after."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=BROWSER_ARGS)
        context = browser.new_context(viewport={"width": width, "height": height}, bypass_csp=True)
        page = context.new_page()
        problems: list[str] = []
        page.on("pageerror", lambda e: problems.append(str(e)))
        try:
            yield page, problems
        finally:
            context.close()
            browser.close()


def make_stores(root: Path) -> list[Path]:
    """A 32^3 vortex of 12 steps and a 32x24x24 jet of 10 steps, as chronocl stores."""
    out = []
    for name, steps, shape in (("vortex", 12, (32, 32, 32)), ("jet", 10, (24, 24, 32))):
        data = np.stack(list(synthetic.steps(name, steps, shape)))
        path = root / f"{name}.zarr"
        TimeSeries.from_array(data, source=name).save(path)
        out.append(path)
    return out


def start_server(stores: list[Path]) -> ViewerServer:
    server = ViewerServer(stores)
    server.start()
    return server


def serving(stores: list[Path], gl_current: bool = False):
    """A server on `stores` for a module's `server` fixture (a generator: `yield from` it),
    stopped after. `gl_current`: the process's GL context made current in this (the main)
    thread first, as after other tests have rendered."""
    if gl_current:
        from chronocl.render.views import raycaster

        raycaster()
    server = start_server(stores)
    yield server
    server.stop()


@pytest.fixture(name="client")
def connected_client(server):
    """`client`: a socket client of the module's `server` fixture, closed after the test. A
    module uses it by importing `connected_client`."""
    c = Client(server)
    yield c
    c.close()


class Client:
    """A blocking WebSocket client that speaks the viewer protocol."""

    def __init__(self, server: ViewerServer, **kwargs) -> None:
        from websockets.sync.client import connect

        # Entered as a context manager: websockets 17.1 deprecates a bare connect().
        self._stack = ExitStack()
        url = f"ws://127.0.0.1:{server.port}/ws?token={server.token}"
        self.ws = self._stack.enter_context(connect(url, **kwargs))
        self.next_id = 1
        self.steps: list[dict] = []  # every "steps" message, skipped by a wait or not
        self.info = self.recv_json()
        assert self.info["type"] == "info"

    def send(self, msg: dict) -> int:
        msg = dict(msg)
        msg.setdefault("id", self.next_id)
        self.next_id = max(self.next_id, msg["id"]) + 1
        self.ws.send(json.dumps(msg))
        return msg["id"]

    def send_raw(self, data: str | bytes) -> None:
        self.ws.send(data)

    def recv(self, timeout: float = 60.0):
        """The next message: ('frame', header, images) or (type, dict)."""
        m = self.ws.recv(timeout=timeout)
        if isinstance(m, bytes):
            header, images = unpack_frame(m)
            return "frame", header, images
        d = json.loads(m)
        if d["type"] == "steps":
            self.steps.append(d)
        return d["type"], d

    def recv_json(self, timeout: float = 60.0) -> dict:
        return json.loads(self.ws.recv(timeout=timeout))

    def wait(self, kind: str, rid: int | None = None, timeout: float = 60.0, errors=None):
        """Skip messages until one of `kind` (answering request `rid`, if given) arrives."""
        return self._until(
            lambda got: got[0] == kind and (rid is None or got[1].get("id") == rid),
            f"no {kind} for request {rid}",
            timeout,
            errors,
            errors_fail=False,
        )

    def frame_for(self, rid: int, timeout: float = 60.0, errors=None):
        """The first frame answering request `rid` or a later one."""
        return self._until(
            lambda got: got[0] == "frame" and (got[1]["id"] or 0) >= rid,
            f"no frame for request {rid}",
            timeout,
            errors,
            errors_fail=True,
        )

    def _until(self, match, missing: str, timeout: float, errors, errors_fail: bool):
        """The first message `match` accepts. Error replies on the way go to `errors` if it
        is a list; else they fail the test where `errors_fail`, and are skipped otherwise."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(missing)
            got = self.recv(left)
            if got[0] == "error":
                if errors is not None:
                    errors.append(got[1])
                elif errors_fail:
                    raise AssertionError(f"error reply: {got[1]}")
            if match(got):
                return got

    def open(self, dataset: int | str = 0, size=(128, 128)):
        rid = self.send({"type": "open", "dataset": dataset})
        _, ds = self.wait("dataset", rid)
        rid = self.send({"type": "update", "size": list(size)})
        return ds, self.frame_for(rid)

    def close(self) -> None:
        self._stack.close()


class CliServer:
    """`chronocl view STORES --no-browser ARGS` in a subprocess, its stderr kept in a file
    (so a test can assert that nothing the clients did printed a traceback there)."""

    def __init__(self, stores: list[Path], log: Path, *args: str, timeout: float = 120.0) -> None:
        import re
        import subprocess
        import sys

        self.log = log
        self._err = open(log, "w")  # closed in stop()
        cmd = [sys.executable, "-m", "chronocl", "view", *map(str, stores), "--no-browser", *args]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self._err, text=True)
        line = self._first_line(timeout)
        m = re.search(r"http://127\.0\.0\.1:(\d+)/\?token=([\w-]+)", line)
        if not m:
            self.stop()
            raise RuntimeError(f"'chronocl view' printed {line!r}; stderr: {self.stderr()}")
        self.port, self.token = int(m.group(1)), m.group(2)
        self.base = f"http://127.0.0.1:{self.port}"
        self.url = f"{self.base}/?token={self.token}"

    def _first_line(self, timeout: float) -> str:
        import threading

        got: list[str] = []
        reader = threading.Thread(target=lambda: got.append(self.proc.stdout.readline()))
        reader.daemon = True
        reader.start()
        reader.join(timeout)
        return got[0] if got else ""

    def stderr(self, start: int = 0) -> str:
        if not self._err.closed:
            self._err.flush()
        return self.log.read_text(errors="replace")[start:]

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(30)
            except Exception:
                self.proc.kill()
                self.proc.wait(30)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._err.close()


def plume_steps() -> np.ndarray:
    """10 steps of a rising plume whose first step is faint: every 5th of a 48-step run
    (step 0 peaks at about a twelfth of the last step's maximum)."""
    return simulate("plume", (24, 40, 24), 48)[::5]


def plume_store(tmp_path_factory, name: str) -> Path:
    """`plume_steps` saved as a store in a fresh folder named `name`."""
    path = tmp_path_factory.mktemp(name) / "plume.zarr"
    TimeSeries.from_array(plume_steps(), source="plume").save(path)
    return path


def fitted(store: Path, t0: int, t1: int, mode: str, stride: int = 1) -> list[float]:
    """The range `fit_range.window_range` fits to the window [t0, t1) of `store` for `mode`."""
    series = open_series(store)
    sel = Selection.window(t0, t1, stride, series.n_steps)
    return list(window_range(series, sel, modes.get(mode)))
