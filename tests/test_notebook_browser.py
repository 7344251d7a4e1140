"""The notebook widget in a real JupyterLab: a server on loopback (a random port, a token, a
temporary root), a notebook opened in Debian's chromium through Playwright, `chronocl.show`
run in its kernel. The picture appears and is not blank; `w.mode = "max"` from a cell changes
it; what is done by hand in the widget (its mode menu, a window brushed on its timeline) is
read back through the kernel; its keys are its own (not the notebook's) and its Save PNG
downloads over the comm; a second widget on the page keeps its own state; its output cleared,
the widget is suspended (its render thread ended, its steps let go) and `display(w)` shows it
again with the same picture; so does a page reloaded, which never removes its views (their
"gone" on pagehide, or, where that is lost, their heartbeats stopping, tell the kernel);
closing the widget ends its render thread. The viewer's Events
panel, through the widget's comm, lists a series' events, and a click on one moves the
window, which `w.window` reads back. The server and the cells are run with
tests/jupyter_lab.py (which bench/notebook_latency.py uses too)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

playwright_api = pytest.importorskip("playwright.sync_api")
pytest.importorskip("anywidget")
pytest.importorskip("jupyterlab")
pytest.importorskip("nbformat")

from .jupyter_lab import (  # noqa: E402
    NOTEBOOK_READY,
    cell_output,
    jupyter_lab,
    open_notebook,
    run_cell,
    write_notebook,
)
from .viewer_helpers import CHROMIUM, launch_browser  # noqa: E402

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

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
    # 7: after the first widget's output was cleared: suspended once the grace passed
    "import time\nfrom chronocl.notebook.kernel import KERNEL\n"
    "thread = w._live.thread\nsteps = KERNEL.held_steps(w._datasets[0].series)\n"
    "end = time.monotonic() + 30\n"
    "while not w.suspended and time.monotonic() < end:\n    time.sleep(0.05)\n"
    "thread.join(30)\n"
    "print('SUSPENDED=' + json.dumps({'suspended': w.suspended, 'alive': thread.is_alive(), "
    "'steps': KERNEL.held_steps(w._datasets[0].series) is not None, "
    "'held_before': steps is not None, 'mode': w.mode}))",
    # 8: shown again
    "display(w)",
]
# The events notebook: a widget on a series with a merge, a birth and a death
# (tests/test_viewer_events_browser.py's, written to the lab's root as blobs.zarr).
EVENT_CELLS = [
    "import json\nimport chronocl\nw = chronocl.show('blobs.zarr', name='blobs', height=700)\nw",
    "w.window = (8, 18)",  # the window slid away from the merge, from code
    "print('WINDOW=' + json.dumps({'window': w.window}))",
    "w.close()",
]
# The reload notebook: a widget whose views beat every second and are gone after 4 s silent
# (chronocl/notebook/views.py; the defaults are 5 s and 20 s), read back, shown again.
RELOAD_CELLS = [
    "import json\nimport numpy as np\nimport chronocl\nfrom chronocl.data import synthetic\n"
    "from chronocl.notebook import views\n"
    "views.HEARTBEAT_S, views.LOST_AFTER_S = 1.0, 4.0\n"
    "data = np.stack(list(synthetic.steps('vortex', 8, (32, 32, 32))))\n"
    "w = chronocl.show(data, name='reloaded', height=420)\nw",
    "print('VIEWS=' + json.dumps({'views': len(w._views), 'suspended': w.suspended, "
    "'alive': w._live is not None and w._live.thread.is_alive(), 'mode': w.mode}))",
    "w.mode = 'max'",
    "w",  # shown again
    "w.close()",
]
# The first widget's viewer (widget.js puts it on the element that holds the shadow root).
VIEWER = "(document.querySelector('.chronocl-widget') || {}).viewer"
SECOND = "(document.querySelectorAll('.chronocl-widget')[1] || {}).viewer"


def lit_share(host: str) -> str:
    """The share of the first view's picture in the widget `host` (a JS expression for its
    element) that is not background (near black), 0..1, as a page function."""
    return f"""async () => {{
  const img = {host}.shadowRoot.querySelector('.view img');
  // a newer frame may replace the picture mid-decode (EncodingError): decode that one
  for (let k = 0; ; k++) {{
    try {{ await img.decode(); break; }} catch (e) {{ if (k > 20) throw e; }}
    await new Promise((r) => setTimeout(r, 50));
  }}
  const c = document.createElement('canvas');
  c.width = img.naturalWidth; c.height = img.naturalHeight;
  const g = c.getContext('2d');
  g.drawImage(img, 0, 0);
  const px = g.getImageData(0, 0, c.width, c.height).data;
  let lit = 0;
  for (let i = 0; i < px.length; i += 4) if (px[i] + px[i + 1] + px[i + 2] > 60) lit += 1;
  return lit / (px.length / 4);
}}"""


LIT_SHARE = lit_share("document.querySelector('.chronocl-widget')")
SETTLED = f"""([seq]) => {{
  const v = {VIEWER}, l = v && v.last;
  return !!l && l.seq > seq && l.quality === 'full' && !l.refining;
}}"""


def answered(viewer: str) -> str:
    """A settled frame after frame `seq` answering the page's newest request (not the kernel's:
    its ids are above any the page uses), of the widget whose viewer is `viewer`."""
    return f"""([seq]) => {{
  const v = {viewer}, l = v && v.last;
  return !!l && l.seq > seq && l.id === v.sent && l.quality === 'full' && !l.refining;
}}"""


ANSWERED = answered(VIEWER)
# A settled frame after frame `seq` whose first view's caption starts with `mode`.
SHOWS_MODE = f"""([seq, mode]) => {{
  const v = {VIEWER}, l = v && v.last;
  const label = document.querySelector('.chronocl-widget').shadowRoot.querySelector('.view-label');
  return !!l && l.seq > seq && l.quality === 'full' && !l.refining
    && label.textContent.startsWith(mode + ',');
}}"""


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A JupyterLab server on 127.0.0.1 (its own config, data and runtime folders) serving a
    temporary root with the test's notebook; stopped after."""
    root = tmp_path_factory.mktemp("lab-root")
    write_notebook(root / "widget.ipynb", CELLS)
    write_notebook(root / "events.ipynb", EVENT_CELLS)
    write_notebook(root / "reload.ipynb", RELOAD_CELLS)
    with jupyter_lab(root, tmp_path_factory.mktemp("lab-home")) as server:
        yield server


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
    open_notebook(page, lab, "widget.ipynb", len(CELLS))
    yield page, problems
    context.close()


def last(page) -> dict:
    return page.evaluate(f"() => {VIEWER}.last")


def settle(page, before: dict | None) -> dict:
    page.wait_for_function(SETTLED, arg=[0 if before is None else before["seq"]], timeout=60_000)
    return last(page)


def edits_answered(page, viewer: str, seq: int) -> dict:
    """Wait until the kernel has the page's edits: a settled frame after frame `seq` answers the
    last update the page sent (`answered`). The page sends its pending update on the next
    animation frame, so two frames on it has gone; a cell run sooner could overtake it.
    Returns that frame."""
    sent = page.evaluate(
        "() => new Promise((done) => requestAnimationFrame(() => "
        f"requestAnimationFrame(() => done({viewer}.sent))))"
    )
    assert sent > 0  # (0: the page had no connection to send it on)
    page.wait_for_function(answered(viewer), arg=[seq], timeout=60_000)
    return page.evaluate(f"() => {viewer}.last")


def test_show_in_jupyterlab_is_driven_from_code_and_by_hand(notebook, lab, tmp_path):
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
    edits_answered(page, VIEWER, after["seq"])
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

    # The first widget's output cleared (as its menu's Clear Cell Output does): its view goes,
    # and after the grace the kernel suspends it (its render thread ended, its steps let go);
    # shown again, it resumes with the picture it had.
    shown = settle(page, None)
    page.evaluate(
        """async () => {
          const app = window.jupyterapp, nb = app.shell.currentWidget.content;
          nb.activeCellIndex = 0;
          nb.deselectAll();
          await app.commands.execute('notebook:clear-cell-output');
        }"""
    )
    page.wait_for_function(
        "() => window.jupyterapp.shell.currentWidget.content.widgets[0]"
        ".node.querySelector('.chronocl-widget') === null",
        timeout=10_000,
    )
    run_cell(page, 7)
    assert cell_output(page, 7, "SUSPENDED") == {
        "suspended": True,
        "alive": False,
        "steps": False,
        "held_before": True,
        "mode": "mean",
    }
    again = "window.jupyterapp.shell.currentWidget.content.widgets[8].node"
    run_cell(page, 8)
    page.wait_for_function(
        f"() => {{ const h = {again}.querySelector('.chronocl-widget');"
        " const v = h && h.viewer, l = v && v.last;"
        " return !!l && l.quality === 'full' && !l.refining; }",
        timeout=60_000,
    )
    resumed = page.evaluate(f"() => {again}.querySelector('.chronocl-widget').viewer.last")
    assert resumed["digest"] == shown["digest"]  # the same picture as before it was cleared
    shot = tmp_path / "widget-shown-again.png"
    page.locator(".jp-Cell").nth(8).locator(".chronocl-widget").screenshot(path=str(shot))
    print(f"\nthe widget shown again: {shot}")

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


def test_events_found_in_the_widget_and_one_clicked_moves_its_window(browser, lab):
    """The viewer's Events panel in the widget, through its comm: Find events lists the
    window's merge, birth and death; the window moved from code, a click on the merge moves it
    back to the merge and frames it, and the kernel's `w.window` follows."""
    pytest.importorskip("cc3d")
    from chronocl.data.series import TimeSeries

    from .test_viewer_events_browser import series

    TimeSeries.from_array(series(), source="blobs").save(lab["root"] / "blobs.zarr")
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda e: problems.append(str(e)))
    try:
        open_notebook(page, lab, "events.ipynb", len(EVENT_CELLS))
        run_cell(page, 0)
        page.wait_for_function(
            f"() => {{ const v = {VIEWER}; return !!v && v.full >= 1; }}", timeout=60_000
        )
        settle(page, None)
        assert page.evaluate(f"() => {VIEWER}.S.state.window") == {"t0": 5, "t1": 15, "stride": 1}

        page.locator(".chronocl-widget #events-find").click()
        page.wait_for_function(
            f"() => {{ const v = {VIEWER}; return !!v.events && !!v.events.found; }}",
            timeout=60_000,
        )
        found = page.evaluate(f"() => {VIEWER}.events.found")
        assert found["window"] == [5, 15, 1]
        kinds = [(e["kind"], e["step"], e["next_step"]) for e in found["events"]]
        assert kinds == [("merge", 6, 7), ("birth", 9, 10), ("death", 13, 14)]
        rows = page.locator(".chronocl-widget #events-list li[data-index]")
        assert rows.count() == 3
        assert rows.nth(0).inner_text().split("\n")[0].endswith("merge")
        assert "6→7" in rows.nth(0).inner_text()

        # The window slid away from the merge from code; the page shows it.
        run_cell(page, 1)
        page.wait_for_function(f"() => {VIEWER}.S.state.window.t0 === 8", timeout=30_000)
        before = last(page)
        # A click on the merge: the window holds its steps, the camera turns about it.
        rows.nth(0).click()
        page.wait_for_function(f"() => {VIEWER}.S.state.window.t0 === 2", timeout=30_000)
        page.wait_for_function(ANSWERED, arg=[before["seq"]], timeout=60_000)
        assert page.evaluate(f"() => {VIEWER}.S.state.window") == {"t0": 2, "t1": 12, "stride": 1}
        focus = page.evaluate(f"() => {VIEWER}.S.focus")
        assert focus == pytest.approx(found["events"][0]["focus"], abs=1e-6)
        assert "selected" in rows.nth(0).get_attribute("class")
        run_cell(page, 2)
        assert cell_output(page, 2, "WINDOW") == {"window": [2, 12, 1]}
        run_cell(page, 3)
        assert problems == []
    finally:
        context.close()


# The page's WebSocket sends, where `window.dropGone` is set, all but the messages saying a
# view went (JupyterLab's kernel messages, text or binary, hold the comm message's JSON).
DROP_GONE = """(() => {
  const send = WebSocket.prototype.send;
  const text = (data) => (typeof data === 'string' ? data : new TextDecoder().decode(data));
  WebSocket.prototype.send = function (data) {
    if (window.dropGone && text(data).includes('"view":"gone"')) return;
    return send.call(this, data);
  };
})();"""


def views_read_back(page, until: dict, timeout_s: float = 60) -> dict:
    """The reload notebook's cell 1 run until it prints `until` (or `timeout_s` passed): the
    kernel's count of the widget's views and whether it is suspended. Each run is a cell of its
    own: the views' silence while one runs is not counted (views.CellTime)."""
    end = time.monotonic() + timeout_s
    while True:
        run_cell(page, 1)
        got = cell_output(page, 1, "VIEWS")
        if got == until or time.monotonic() > end:
            return got
        page.wait_for_timeout(500)


def test_a_reloaded_page_suspends_its_widget_and_shown_again_it_resumes(browser, lab):
    """A page reloaded never calls the view's cleanup: its view's best-effort "gone" on
    pagehide, or its heartbeats stopping, tell the kernel, which suspends the widget (read back
    through the kernel from the reloaded page); shown again there, it resumes with the picture
    it had. A page whose "gone" is lost (a renderer crashed sends none) is found by its
    silence alone."""
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.on("dialog", lambda d: d.accept())  # (JupyterLab asks before leaving unsaved cells)
    again = "window.jupyterapp.shell.currentWidget.content.widgets[3].node"
    shown_again = f"{again}.querySelector('.chronocl-widget')"
    resumed = f"""() => {{ const h = {shown_again}, v = h && h.viewer, l = v && v.last;
      return !!l && l.quality === 'full' && !l.refining && l.views === 1; }}"""
    page.add_init_script(DROP_GONE)
    try:
        open_notebook(page, lab, "reload.ipynb", len(RELOAD_CELLS))
        run_cell(page, 0)
        page.wait_for_function(
            f"() => {{ const v = {VIEWER}; return !!v && v.full >= 1; }}", timeout=60_000
        )
        run_cell(page, 2)  # (a picture of its own: not the first, which any widget shows)
        page.wait_for_function(SHOWS_MODE, arg=[0, "max"], timeout=60_000)
        shown = last(page)
        alive = {"views": 1, "suspended": False, "alive": True, "mode": "max"}
        assert views_read_back(page, alive, timeout_s=0) == alive

        page.reload()
        page.wait_for_function(NOTEBOOK_READY, arg=len(RELOAD_CELLS), timeout=60_000)
        assert page.locator(".chronocl-widget").count() == 0  # (the cells' outputs unsaved)
        gone = {"views": 0, "suspended": True, "alive": False, "mode": "max"}
        assert views_read_back(page, gone) == gone

        run_cell(page, 3)
        page.wait_for_function(resumed, timeout=60_000)
        assert page.evaluate(f"() => {shown_again}.viewer.last")["digest"] == shown["digest"]
        assert page.evaluate(lit_share(shown_again)) > 0.02
        assert views_read_back(page, alive, timeout_s=0) == alive

        # Its "gone" lost (as a crashed renderer sends none; here dropped on the kernel's socket):
        # the heartbeats stop, and 4 s later the view is counted gone and the widget suspended.
        page.evaluate("() => { window.dropGone = true; }")
        page.reload()
        page.wait_for_function(NOTEBOOK_READY, arg=len(RELOAD_CELLS), timeout=60_000)
        assert views_read_back(page, gone) == gone
        run_cell(page, 3)
        page.wait_for_function(resumed, timeout=60_000)
        assert page.evaluate(f"() => {shown_again}.viewer.last")["digest"] == shown["digest"]
        run_cell(page, 4)
        assert problems == []
    finally:
        context.close()
