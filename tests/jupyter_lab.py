"""A Jupyter server on loopback, JupyterLab 4's or Notebook 7's, and its notebook driven in
Chromium (Playwright): what the notebook widget's browser tests (tests/test_notebook_browser.py
in JupyterLab, tests/test_notebook7_browser.py in Notebook 7) and its latency bench
(bench/notebook_latency.py, which imports it as `tests.jupyter_lab`) share.

The server runs in its own config, data and runtime folders (a random port, a token, the
announcements toast off); a cell is run as Shift+Enter runs it (the `notebook:run-cell`
command on the page's `window.jupyterapp`, which `expose_app_in_browser` gives: Notebook 7's
application is built of JupyterLab's components, so the same shell, notebook panel and command
serve both); what a cell printed after `KEY=` is read back as JSON.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

START_TIMEOUT_S = 60


def wait_for_port(proc: subprocess.Popen, port: int, log_path: Path, name: str) -> None:
    """Until the server `proc` (its output in `log_path`) takes connections on `port` of
    127.0.0.1; RuntimeError with the log's end where it died or START_TIMEOUT_S passed."""
    end = time.monotonic() + START_TIMEOUT_S
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            if proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError(
                    f"{name} did not start: {log_path.read_text()[-2000:]}"
                ) from None
            time.sleep(0.2)


# True once the notebook's kernel is idle and its cells (the argument: how many) are shown.
NOTEBOOK_READY = """(cells) => {
  const app = window.jupyterapp, nb = app && app.shell.currentWidget;
  const k = nb && nb.sessionContext && nb.sessionContext.session
    && nb.sessionContext.session.kernel;
  return !!k && k.status === 'idle' && !!nb.content && nb.content.widgets.length === cells;
}"""
KERNEL_IDLE = (
    "() => window.jupyterapp.shell.currentWidget.sessionContext.session.kernel.status === 'idle'"
)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_notebook(path: Path, cells: list[str]) -> None:
    """A notebook of code cells `cells` on the python3 kernel, written to `path`."""
    import nbformat

    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(src) for src in cells]
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, path)


# The front ends: how each is started (after the options both take) and a notebook's page.
FRONT_ENDS = {
    "lab": {
        "name": "JupyterLab",
        "argv": [
            "-m", "jupyterlab", "--LabApp.expose_app_in_browser=True",
            "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
        ],
        "notebook_url": "/lab/tree/{name}",
    },
    "notebook": {  # Notebook 7 (`jupyter notebook`), not JupyterLab
        "name": "Notebook 7",
        "argv": ["-m", "notebook", "--JupyterNotebookApp.expose_app_in_browser=True"],
        "notebook_url": "/notebooks/{name}",
    },
}  # fmt: skip


@contextmanager
def jupyter_server(root: Path, home: Path, front_end: str = "lab") -> Iterator[dict]:
    """A Jupyter server of `front_end` ("lab": JupyterLab, "notebook": Notebook 7) on 127.0.0.1
    serving `root`, its config, runtime, settings and log under `home`; yields {"base": its
    URL, "token", "root", "log": the log's path, "front_end"}; stopped after. RuntimeError
    with the log's end where it does not start in START_TIMEOUT_S."""
    spec = FRONT_ENDS[front_end]
    (home / "config" / "labconfig").mkdir(parents=True, exist_ok=True)
    (home / "config" / "labconfig" / "page_config.json").write_text(
        json.dumps({"disabledExtensions": {"@jupyterlab/apputils-extension:announcements": True}})
    )
    token, port = secrets.token_hex(16), free_port()
    env = os.environ | {
        "JUPYTER_CONFIG_DIR": str(home / "config"),
        "JUPYTER_RUNTIME_DIR": str(home / "runtime"),
        "JUPYTERLAB_SETTINGS_DIR": str(home / "settings"),
        "JUPYTERLAB_WORKSPACES_DIR": str(home / "workspaces"),
        "JUPYTER_PLATFORM_DIRS": "1",
    }
    log_path = home / f"{front_end}.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            [
                sys.executable, *spec["argv"], "--no-browser", "--ip=127.0.0.1",
                f"--port={port}", f"--IdentityProvider.token={token}",
                f"--ServerApp.root_dir={root}", "--ServerApp.open_browser=False", "--allow-root",
            ],
            env=env, stdout=log, stderr=subprocess.STDOUT, cwd=root,
        )  # fmt: skip
        try:
            wait_for_port(proc, port, log_path, spec["name"])
            yield {
                "base": f"http://127.0.0.1:{port}",
                "token": token,
                "root": root,
                "log": log_path,
                "front_end": front_end,
            }
        finally:
            proc.terminate()
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def jupyter_lab(root: Path, home: Path):
    """A JupyterLab server (`jupyter_server(root, home, "lab")`)."""
    return jupyter_server(root, home, "lab")


def open_notebook(page, server: dict, name: str, cells: int, timeout_s: float = 60) -> None:
    """Notebook `name` (under the server's root) opened on `page` in the server's front end,
    waited for until its kernel is idle and its `cells` cells are shown."""
    path = FRONT_ENDS[server.get("front_end", "lab")]["notebook_url"].format(name=name)
    page.goto(f"{server['base']}{path}?token={server['token']}")
    page.wait_for_function(NOTEBOOK_READY, arg=cells, timeout=timeout_s * 1000)


def run_cell(page, index: int, wait: bool = True) -> float:
    """Run cell `index` (as Shift+Enter does); returns the page's clock when it was started.
    `wait`: returns once JupyterLab has run it, else at once (a bench timing what follows)."""
    return page.evaluate(
        """async ([i, wait]) => {
          const app = window.jupyterapp, nb = app.shell.currentWidget;
          nb.content.activeCellIndex = i;
          const t = performance.now();
          const ran = app.commands.execute('notebook:run-cell');
          if (wait) await ran;
          return t;
        }""",
        [index, wait],
    )


def wait_kernel_idle(page, timeout_s: float = 60) -> None:
    page.wait_for_function(KERNEL_IDLE, timeout=timeout_s * 1000)


def cell_output(page, index: int, key: str, timeout_s: float = 60) -> dict:
    """The JSON cell `index` printed after `key=`, waited for; AssertionError with the cell's
    text where it failed (a traceback or an error shown) or printed none in `timeout_s`."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        text = page.evaluate(
            "(i) => window.jupyterapp.shell.currentWidget.content.widgets[i].node.innerText",
            index,
        )
        found = re.search(rf"{key}=(\{{.*\}})", text)
        if found:
            return json.loads(found.group(1))
        if "Traceback" in text or "Error" in text:
            raise AssertionError(f"cell {index} failed:\n{text}")
        time.sleep(0.05)
    raise AssertionError(f"cell {index} printed no {key}= in {timeout_s} s")
