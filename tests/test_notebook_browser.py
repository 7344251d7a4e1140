"""The notebook widget in a real JupyterLab: a server on loopback (a random port, a token, a
temporary root), a notebook opened in Debian's chromium through Playwright, `chronocl.show`
run in its kernel. The picture appears and is not blank; `w.mode = "max"` from a cell changes
it; what is done by hand in the widget (its mode menu, a window brushed on its timeline) is
read back through the kernel; its keys are its own (not the notebook's) and its Save PNG
downloads over the comm; a second widget on the page keeps its own state; closing the widget
ends its render thread."""

from __future__ import annotations

import json
import os
import re
import secrets
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

playwright_api = pytest.importorskip("playwright.sync_api")
pytest.importorskip("anywidget")
pytest.importorskip("jupyterlab")
nbformat = pytest.importorskip("nbformat")

from .viewer_helpers import CHROMIUM, launch_browser  # noqa: E402

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

START_TIMEOUT_S = 60
CELLS = [
    # 0: the widget on a small generated series
    "import json\n"
    "import numpy as np\n"
    "import chronocl\n"
    "from chronocl.data import synthetic\n"
    "data = np.stack(list(synthetic.steps('vortex', 12, (32, 32, 32))))\n"
    "w = chronocl.show(data, name='vortex', height=520)\n"
    "w",
    # 1: set from code
    "w.mode = 'max'",
    # 2: read back what the page set
    "print('STATE=' + json.dumps({'mode': w.mode, 'window': w.window, "
    "'views': w.views, 'time_tf': w.time_tf}))",
    # 3: a second widget on the same page
    "w2 = chronocl.show(data[:6], name='second', height=420)\nw2",
    # 4: close the first
    "thread = w._worker.thread\nw.close()\nthread.join(30)\n"
    "print('CLOSED=' + json.dumps({'closed': w.closed, 'alive': thread.is_alive(), "
    "'second': w2.mode}))",
    # 5: a series' summary (its HTML repr, with its picture)
    "chronocl.TimeSeries.from_array(data, times=list(range(12)), time_unit='s')",
    # 6: after the front end closed the second widget's model
    "thread2 = w2._worker.thread\nthread2.join(30)\n"
    "print('FRONT_CLOSED=' + json.dumps({'closed': w2.closed, 'alive': thread2.is_alive()}))",
]
# The first widget's viewer (widget.js puts it on the element that holds the shadow root).
VIEWER = "(document.querySelector('.chronocl-widget') || {}).viewer"
SECOND = "(document.querySelectorAll('.chronocl-widget')[1] || {}).viewer"
# The share of the first view's picture that is not background (near black), 0..1.
LIT_SHARE = """async () => {
  const img = document.querySelector('.chronocl-widget').shadowRoot.querySelector('.view img');
  await img.decode();
  const c = document.createElement('canvas');
  c.width = img.naturalWidth; c.height = img.naturalHeight;
  const g = c.getContext('2d');
  g.drawImage(img, 0, 0);
  const px = g.getImageData(0, 0, c.width, c.height).data;
  let lit = 0;
  for (let i = 0; i < px.length; i += 4) if (px[i] + px[i + 1] + px[i + 2] > 60) lit += 1;
  return lit / (px.length / 4);
}"""
SETTLED = f"""([seq]) => {{
  const v = {VIEWER}, l = v && v.last;
  return !!l && l.seq > seq && l.quality === 'full' && !l.refining;
}}"""
# A settled frame after frame `seq` whose first view's caption starts with `mode`.
SHOWS_MODE = f"""([seq, mode]) => {{
  const v = {VIEWER}, l = v && v.last;
  const label = document.querySelector('.chronocl-widget').shadowRoot.querySelector('.view-label');
  return !!l && l.seq > seq && l.quality === 'full' && !l.refining
    && label.textContent.startsWith(mode + ',');
}}"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_notebook(path: Path) -> None:
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(src) for src in CELLS]
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, path)


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A JupyterLab server on 127.0.0.1 (its own config, data and runtime folders), its base URL
    and token; stopped after."""
    root = tmp_path_factory.mktemp("lab-root")
    home = tmp_path_factory.mktemp("lab-home")
    write_notebook(root / "widget.ipynb")
    # No announcements toast over the notebook.
    (home / "config" / "labconfig").mkdir(parents=True)
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
    log = open(home / "lab.log", "w")
    proc = subprocess.Popen(
        [
            sys.executable, "-m", "jupyterlab", "--no-browser", "--ip=127.0.0.1",
            f"--port={port}", f"--IdentityProvider.token={token}",
            f"--ServerApp.root_dir={root}", "--LabApp.expose_app_in_browser=True",
            "--ServerApp.open_browser=False", "--allow-root", "--LabApp.check_for_updates_class="
            "jupyterlab.NeverCheckForUpdate",
        ],
        env=env, stdout=log, stderr=subprocess.STDOUT, cwd=root,
    )  # fmt: skip
    base = f"http://127.0.0.1:{port}"
    try:
        end = time.monotonic() + START_TIMEOUT_S
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if proc.poll() is not None or time.monotonic() > end:
                    raise RuntimeError(
                        f"JupyterLab did not start: {(home / 'lab.log').read_text()[-2000:]}"
                    ) from None
                time.sleep(0.2)
        yield {"base": base, "token": token, "root": root, "log": home / "lab.log"}
    finally:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


@pytest.fixture(scope="module")
def browser():
    yield from launch_browser()


@pytest.fixture
def notebook(browser, lab):
    """The notebook open in JupyterLab, its kernel idle; the page and its errors."""
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(f"{lab['base']}/lab/tree/widget.ipynb?token={lab['token']}")
    page.wait_for_function(
        """() => {
          const app = window.jupyterapp, nb = app && app.shell.currentWidget;
          const k = nb && nb.sessionContext && nb.sessionContext.session
            && nb.sessionContext.session.kernel;
          return !!k && k.status === 'idle' && nb.content && nb.content.widgets.length === 7;
        }""",
        timeout=60_000,
    )
    yield page, problems
    context.close()


def run_cell(page, index: int) -> float:
    """Run cell `index` (as Shift+Enter does); returns the page's clock when it was started."""
    return page.evaluate(
        """async (i) => {
          const app = window.jupyterapp, nb = app.shell.currentWidget;
          nb.content.activeCellIndex = i;
          const t = performance.now();
          await app.commands.execute('notebook:run-cell');
          return t;
        }""",
        index,
    )


def cell_output(page, index: int, key: str, timeout_s: float = 60) -> dict:
    """The JSON a cell printed after `key=`, waited for."""
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
        time.sleep(0.2)
    raise AssertionError(f"cell {index} printed no {key}= in {timeout_s} s")


def last(page) -> dict:
    return page.evaluate(f"() => {VIEWER}.last")


def settle(page, before: dict | None) -> dict:
    page.wait_for_function(SETTLED, arg=[0 if before is None else before["seq"]], timeout=60_000)
    return last(page)


def test_show_in_jupyterlab_is_driven_from_code_and_by_hand(notebook, lab):
    page, problems = notebook

    # The widget's first picture: a lit vortex, not a blank panel.
    started = run_cell(page, 0)
    page.wait_for_function(
        f"() => {{ const v = {VIEWER}; return !!v && v.full >= 1; }}", timeout=60_000
    )
    first_ms = page.evaluate("(t) => performance.now() - t", started)
    frame = settle(page, None)
    assert frame["views"] == 1
    page.wait_for_function(
        "() => { const h = document.querySelector('.chronocl-widget');"
        " const img = h && h.shadowRoot.querySelector('.view img');"
        " return !!img && img.complete && img.naturalWidth > 0; }",
        timeout=30_000,
    )
    lit = page.evaluate(LIT_SHARE)
    assert lit > 0.02, f"the picture is blank ({lit:.3%} of it lit)"
    # The viewer's own controls, in the cell output: the mode menu is the registry's.
    assert page.locator(".chronocl-widget .view select.mode").first.input_value() == "alpha"
    assert "vortex" in page.locator(".chronocl-widget #dataset").inner_text()

    # Set from code: the page shows max, and the picture changes.
    run_cell(page, 1)
    page.wait_for_function(f"() => {VIEWER}.S.state.views[0].mode === 'max'", timeout=30_000)
    page.wait_for_function(SHOWS_MODE, arg=[frame["seq"], "max"], timeout=60_000)
    after = last(page)
    assert after["digest"] != frame["digest"]
    assert page.locator(".chronocl-widget .view select.mode").first.input_value() == "max"
    assert "max" in page.locator(".chronocl-widget .view-label").first.inner_text()

    # By hand: the mode menu, a window brushed over steps 0..4, the time colour menu.
    page.locator(".chronocl-widget .view select.mode").first.select_option("mean")
    a = page.evaluate(f"() => {VIEWER}.timelineAt(0)")
    b = page.evaluate(f"() => {VIEWER}.timelineAt(4)")
    page.mouse.move(a["x"], a["y"])
    page.mouse.down()
    page.mouse.move(b["x"], b["y"], steps=8)
    page.mouse.up()
    page.locator(".chronocl-widget #time-color").select_option("lightness")
    page.wait_for_function(
        f"() => {{ const s = {VIEWER}.S.state; return s.window.t0 === 0 && s.window.t1 === 5 && "
        "s.time_tf.color === 'lightness'; }",
        timeout=30_000,
    )
    settle(page, after)
    run_cell(page, 2)
    state = cell_output(page, 2, "STATE")
    assert state["mode"] == "mean"
    assert state["views"][0]["mode"] == "mean"
    assert state["window"] == [0, 5, 1]
    assert state["time_tf"]["color"] == "lightness"

    # Keys typed in the widget act on it, not on the notebook ('a' would insert a cell); Save
    # PNG downloads the picture, which came over the comm.
    cells = page.evaluate("() => window.jupyterapp.shell.currentWidget.content.widgets.length")
    page.evaluate(
        "() => document.querySelector('.chronocl-widget').shadowRoot"
        ".querySelector('.chronocl').focus()"
    )
    page.keyboard.press("?")
    assert page.locator(".chronocl-widget #help").is_visible()
    page.keyboard.press("a")
    page.keyboard.press("Escape")
    assert not page.locator(".chronocl-widget #help").is_visible()
    assert page.evaluate("() => window.jupyterapp.shell.currentWidget.content.widgets.length") == (
        cells
    )
    with page.expect_download(timeout=60_000) as saved:
        page.locator(".chronocl-widget #save-image").click()
    assert saved.value.suggested_filename == "vortex-0-5.png"
    assert Path(saved.value.path()).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # A second widget: its own data set, state and picture; the first's stays as it was.
    run_cell(page, 3)
    page.wait_for_function(f"() => {{ const v = {SECOND}; return !!v && v.full >= 1; }}")
    second = page.locator(".chronocl-widget").nth(1)
    assert "second (32³, 6 steps)" in second.locator("#dataset").inner_text()
    assert second.locator(".view select.mode").first.input_value() == "alpha"
    assert page.evaluate(f"() => {VIEWER}.S.state.views[0].mode") == "mean"
    assert page.evaluate(f"() => {SECOND}.S.info.name") == "second"

    # Closed from code: the render thread ends; the second widget goes on.
    run_cell(page, 4)
    assert cell_output(page, 4, "CLOSED") == {"closed": True, "alive": False, "second": "alpha"}

    # A series displays its summary: what it is, and its picture.
    run_cell(page, 5)
    page.wait_for_function(
        "() => { const img = document.querySelector('.chronocl-repr img');"
        " return !!img && img.complete && img.naturalWidth > 0; }",
        timeout=30_000,
    )
    summary = page.locator(".chronocl-repr").inner_text()
    assert "32×32×32 (x, y, z) × 12 steps" in summary and "0 .. 11 s" in summary

    # The front end closes the second widget's model (as closing it from JavaScript does): the
    # kernel frees its worker.
    closed = page.evaluate(
        """async () => {
          const wm = document.querySelector('.chronocl-widget').widgetManager;
          for (const p of Object.values(wm._models)) {
            const m = await p;
            if (m.get('height') === 420) { m.close(); return true; }
          }
          return false;
        }"""
    )
    assert closed
    run_cell(page, 6)
    assert cell_output(page, 6, "FRONT_CLOSED") == {"closed": True, "alive": False}
    assert problems == []
    print(f"\nnotebook widget: first picture {first_ms:.0f} ms after the cell was run")
