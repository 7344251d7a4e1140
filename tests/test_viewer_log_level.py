"""`chronocl view --log-level` (issue 49): internal errors reach the server's log with their
tracebacks, while the page gets one line.

The real CLI runs in a subprocess (`CliServer`); a `sitecustomize` module on its PYTHONPATH
makes one message fail inside the server as a bug would (`ClientWorker.cancel_refine` raises
a RuntimeError), the only change to the process. A bad level is one line, exit 2.
"""

from __future__ import annotations

import os
import time

import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from . import cli_process
from .viewer_helpers import Client, CliServer, make_stores

INJECTED = "injected by test_viewer_log_level"
SITECUSTOMIZE = f"""
from chronocl.viewer.worker import ClientWorker


def cancel_refine(self):
    raise RuntimeError({INJECTED!r})


ClientWorker.cancel_refine = cancel_refine
"""


def test_an_internal_error_on_the_message_path_logs_its_traceback(tmp_path, monkeypatch):
    stores = make_stores(tmp_path / "stores")
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(SITECUSTOMIZE)
    path = os.environ.get("PYTHONPATH")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(hook), *([path] if path else [])]))
    server = CliServer(stores[:1], tmp_path / "stderr.txt", "--log-level", "debug")
    try:
        c = Client(server)
        try:
            rid = c.send({"type": "cancel"})
            message = c.wait("error", rid)[1]["message"]
        finally:
            c.close()
        # the page: the one-line summary, no traceback
        assert message.startswith(f"internal error (RuntimeError: {INJECTED}) on a message")
        assert "\n" not in message and "Traceback" not in message
        # the log: the same line, then the traceback down to the failing call
        deadline = time.monotonic() + 30
        while "cancel_refine" not in server.stderr() and time.monotonic() < deadline:
            time.sleep(0.1)
        log = server.stderr()
        assert f"ERROR chronocl.viewer: chronocl viewer: {message}" in log, log
        assert "Traceback (most recent call last)" in log, log
        assert f"RuntimeError: {INJECTED}" in log and "cancel_refine" in log, log
        assert server.alive()
    finally:
        server.stop()


def test_a_bad_log_level_is_one_line_and_exit_2(tmp_path):
    stores = make_stores(tmp_path / "stores")
    got = cli_process.run(["view", stores[0], "--no-browser", "--log-level", "loud"])
    assert got.returncode == 2, got
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1, got.stderr
    assert "--log-level 'loud'" in lines[0] and "warning, info, debug" in lines[0]
    assert "Traceback" not in got.stderr


def test_view_help_documents_the_log_level(tmp_path):
    got = cli_process.run(["view", "--help"])
    assert got.returncode == 0
    assert "--log-level" in got.stdout
    assert "chronocl view vortex.zarr --log-level debug" in got.stdout
