"""The notebook widget in a real marimo notebook: `marimo run` on loopback (a random port, a token,
its config and state folders temporary) serving a notebook that calls `chronocl.show`, opened in
Debian's chromium through Playwright. marimo renders an anywidget with its own front end (no
Jupyter, no ipykernel: its own comm, the widget's view inside a shadow root of its own), so this
is anywidget's standard met by a second host. The picture appears in the cell output and is not
blank; a cell run by a marimo button sets `w.mode = "max"` and the picture changes; a window
brushed by hand on the widget's timeline is what `w.window` reads back in another cell. The page
probes are tests/test_notebook_browser.py's, rewritten to find the widget through marimo's shadow
root."""

from __future__ import annotations

import json
import os
import secrets
import subprocess
import sys
import time

import pytest

pytest.importorskip("playwright.sync_api")
pytest.importorskip("anywidget")
pytest.importorskip("marimo")

from .jupyter_lab import free_port, wait_for_port
from .test_notebook_browser import edits_answered, lit_share
from .viewer_helpers import CHROMIUM, launch_browser

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

# The notebook: the widget, two buttons (the first's cell sets the mode from code, the
# second's reads the widget's state back), the state printed after STATE=.
NOTEBOOK = """import marimo

app = marimo.App(width="full")


@app.cell
def _():
    import json

    import marimo as mo
    import numpy as np

    import chronocl
    from chronocl.data import synthetic

    data = np.stack(list(synthetic.steps("vortex", 12, (32, 32, 32))))
    w = chronocl.show(data, name="vortex", height=520)
    w
    return json, mo, w


@app.cell
def _(mo):
    to_max = mo.ui.button(label="to max", value=0, on_click=lambda n: n + 1)
    read = mo.ui.button(label="read state", value=0, on_click=lambda n: n + 1)
    mo.hstack([to_max, read], justify="start")
    return read, to_max


@app.cell
def _(to_max, w):
    if to_max.value:
        w.mode = "max"
    return


@app.cell
def _(json, mo, read, w):
    mo.plain_text(
        "STATE=" + json.dumps({"reads": read.value, "mode": w.mode, "window": w.window})
    )
    return


if __name__ == "__main__":
    app.run()
"""
# The widget's element, wherever it is: marimo puts each anywidget's view in a shadow root.
HOST = """(() => {
  const find = (root) => {
    const h = root.querySelector('.chronocl-widget');
    if (h) return h;
    for (const el of root.querySelectorAll('*')) {
      const f = el.shadowRoot && find(el.shadowRoot);
      if (f) return f;
    }
    return null;
  };
  return find(document);
})()"""
VIEWER = f"({HOST} || {{}}).viewer"
LIT_SHARE = lit_share(HOST)
SHOWN = f"""() => {{
  const h = {HOST}, img = h && h.shadowRoot.querySelector('.view img');
  return !!img && img.complete && img.naturalWidth > 0;
}}"""
# A settled frame after frame `seq` whose first view's caption starts with `mode`.
SHOWS_MODE = f"""([seq, mode]) => {{
  const h = {HOST}, v = h && h.viewer, l = v && v.last;
  const label = h && h.shadowRoot.querySelector('.view-label');
  return !!l && l.seq > seq && l.quality === 'full' && !l.refining
    && label.textContent.startsWith(mode + ',');
}}"""
SETTLED = f"""([seq]) => {{
  const v = {VIEWER}, l = v && v.last;
  return !!l && l.seq > seq && l.quality === 'full' && !l.refining;
}}"""


@pytest.fixture(scope="module")
def marimo_app(tmp_path_factory):
    """`marimo run` of the test's notebook on 127.0.0.1 with a token, its config and state
    under a temporary home; yields its URL (the token in it); stopped after."""
    root = tmp_path_factory.mktemp("marimo-root")
    home = tmp_path_factory.mktemp("marimo-home")
    (root / "widget.py").write_text(NOTEBOOK)
    port, token = free_port(), secrets.token_hex(16)
    # marimo's config and state (recent files, sessions) in the temporary home; the kernel's
    # caches (PoCL's built kernels) where they are
    env = os.environ | {
        "XDG_CONFIG_HOME": str(home / "config"),
        "XDG_STATE_HOME": str(home / "state"),
    }
    log_path = home / "marimo.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            [
                sys.executable, "-m", "marimo", "-y", "run", "--headless", "--token",
                "--token-password", token, "--host", "127.0.0.1", "--port", str(port),
                "widget.py",
            ],
            env=env, stdout=log, stderr=subprocess.STDOUT, cwd=root,
        )  # fmt: skip
        try:
            wait_for_port(proc, port, log_path, "marimo")
            yield {"url": f"http://127.0.0.1:{port}/?access_token={token}", "log": log_path}
        finally:
            proc.terminate()
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.fixture(scope="module")
def browser():
    yield from launch_browser()


def read_state(page, reads: int, timeout_s: float = 60) -> dict:
    """The state the notebook's last cell printed after its button's `reads`-th click."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        text = page.locator("text=/STATE=/").first.inner_text()
        got = json.loads(text.split("STATE=", 1)[1])
        if got["reads"] == reads:
            return got
        time.sleep(0.05)
    raise AssertionError(f"no state after read {reads} in {timeout_s} s: {text}")


def last(page) -> dict:
    return page.evaluate(f"() => {VIEWER}.last")


def test_show_in_marimo_draws_and_follows_code_and_hand(browser, marimo_app, tmp_path):
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda e: problems.append(str(e)))
    try:
        page.goto(marimo_app["url"])
        # The widget's first picture in marimo's output: a lit vortex, not a blank panel.
        page.wait_for_function(
            f"() => {{ const v = {VIEWER}; return !!v && v.full >= 1; }}", timeout=120_000
        )
        page.wait_for_function(SETTLED, arg=[0], timeout=60_000)
        frame = last(page)
        page.wait_for_function(SHOWN, timeout=30_000)
        lit = page.evaluate(LIT_SHARE)
        assert lit > 0.02, f"the picture is blank ({lit:.3%} of it lit)"
        # inside marimo's own element for anywidgets, not a Jupyter output area
        assert page.evaluate(f"() => {HOST}.getRootNode().host.tagName") == "MARIMO-ANYWIDGET"
        mode = page.locator(".chronocl-widget .view select.mode").first
        assert mode.input_value() == "alpha"
        shown = page.evaluate(
            f"() => {{ const w = {VIEWER}.S.state.window; return [w.t0, w.t1]; }}"
        )
        assert read_state(page, 0) == {"reads": 0, "mode": "alpha", "window": [*shown, 1]}
        assert shown != [0, 5]  # (the window brushed below is a change)

        # Set from code, in a cell the button runs: the page shows max, the picture changes.
        page.get_by_role("button", name="to max").click()
        page.wait_for_function(SHOWS_MODE, arg=[frame["seq"], "max"], timeout=60_000)
        after = last(page)
        assert after["digest"] != frame["digest"]
        assert mode.input_value() == "max"
        page.wait_for_function(SHOWN, timeout=30_000)
        assert page.evaluate(LIT_SHARE) > 0.02

        # By hand: a window brushed over steps 0..4 on the timeline, read back in a cell.
        timeline = f"{HOST}.shadowRoot.querySelector('#timeline')"
        page.evaluate(f"() => {timeline}.scrollIntoView({{block: 'center'}})")
        a = page.evaluate(f"() => {VIEWER}.timelineAt(0)")
        b = page.evaluate(f"() => {VIEWER}.timelineAt(4)")
        page.mouse.move(a["x"], a["y"])
        page.mouse.down()
        page.mouse.move(b["x"], b["y"], steps=8)
        page.mouse.up()
        page.wait_for_function(
            f"() => {{ const s = {VIEWER}.S.state.window; return s.t0 === 0 && s.t1 === 5; }}",
            timeout=30_000,
        )
        assert edits_answered(page, VIEWER, after["seq"])["digest"] != after["digest"]
        page.get_by_role("button", name="read state").click()
        assert read_state(page, 1) == {"reads": 1, "mode": "max", "window": [0, 5, 1]}
        page.screenshot(path=str(tmp_path / "marimo.png"))
        assert problems == []
    finally:
        context.close()
