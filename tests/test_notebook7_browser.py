"""The notebook widget in a real Notebook 7 (`jupyter notebook`, not JupyterLab): its server on
loopback (a random port, a token, a temporary root), a notebook opened in Debian's chromium
through Playwright, `chronocl.show` run in its kernel. The picture appears in the cell output
and is not blank; `w.mode = "max"` from a cell changes it; closing the widget ends its render
thread. The server and the cells are run with tests/jupyter_lab.py, as in JupyterLab
(tests/test_notebook_browser.py, whose page probes this reuses)."""

from __future__ import annotations

import os

import pytest

pytest.importorskip("playwright.sync_api")
pytest.importorskip("anywidget")
pytest.importorskip("notebook")
pytest.importorskip("nbformat")

from .jupyter_lab import (
    cell_output,
    jupyter_server,
    open_notebook,
    run_cell,
    write_notebook,
)
from .test_notebook_browser import CELLS as LAB_CELLS
from .test_notebook_browser import LIT_SHARE, SHOWS_MODE, VIEWER, last, settle
from .viewer_helpers import CHROMIUM, launch_browser

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

CELLS = [
    *LAB_CELLS[:2],  # the JupyterLab test's widget and its mode set from code
    "thread = w._worker.thread\nw.close()\nthread.join(30)\n"
    "print('CLOSED=' + json.dumps({'mode': w.mode, 'closed': w.closed, "
    "'alive': thread.is_alive()}))",
]
# The first view's picture shown in the cell output, decoded.
SHOWN = (
    "() => { const h = document.querySelector('.chronocl-widget');"
    " const img = h && h.shadowRoot.querySelector('.view img');"
    " return !!img && img.complete && img.naturalWidth > 0; }"
)


def notebook7_own(error) -> bool:
    """The one error Notebook 7.6's own page raises as it loads any notebook (its keyboard
    shortcuts plugin reading the settings schema of a plugin it has not loaded: seen with a
    notebook of `1+1`, no widget, and gone with @jupyterlab/shortcuts-extension disabled),
    told apart by its message and its place in Notebook's own bundle; not the widget's."""
    stack = (getattr(error, "stack", None) or "").splitlines()
    return (
        str(error) == "Cannot read properties of undefined (reading 'schema')"
        and len(stack) > 1
        and "/static/notebook/notebook_core." in stack[1]
    )


@pytest.fixture(scope="module")
def classic(tmp_path_factory):
    """A Notebook 7 server on 127.0.0.1 serving a temporary root with the test's notebook."""
    root = tmp_path_factory.mktemp("notebook7-root")
    write_notebook(root / "widget.ipynb", CELLS)
    with jupyter_server(root, tmp_path_factory.mktemp("notebook7-home"), "notebook") as server:
        yield server


@pytest.fixture(scope="module")
def browser():
    yield from launch_browser()


def test_show_in_notebook7_draws_and_follows_code(browser, classic):
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda e: None if notebook7_own(e) else problems.append(str(e)))
    try:
        open_notebook(page, classic, "widget.ipynb", len(CELLS))
        # Notebook 7's own page and application, not JupyterLab's
        assert "/notebooks/widget.ipynb" in page.url
        assert page.evaluate("() => window.jupyterapp.name") == "Jupyter Notebook"

        # The widget's first picture in the cell output: a lit vortex, not a blank panel.
        run_cell(page, 0)
        page.wait_for_function(
            f"() => {{ const v = {VIEWER}; return !!v && v.full >= 1; }}", timeout=60_000
        )
        frame = settle(page, None)
        page.wait_for_function(SHOWN, timeout=30_000)
        lit = page.evaluate(LIT_SHARE)
        assert lit > 0.02, f"the picture is blank ({lit:.3%} of it lit)"
        assert page.locator(".jp-OutputArea .chronocl-widget").count() == 1
        assert page.locator(".chronocl-widget .view select.mode").first.input_value() == "alpha"

        # Set from a cell: the page shows max, and the picture changes.
        run_cell(page, 1)
        page.wait_for_function(SHOWS_MODE, arg=[frame["seq"], "max"], timeout=60_000)
        after = last(page)
        assert after["digest"] != frame["digest"]
        assert page.locator(".chronocl-widget .view select.mode").first.input_value() == "max"
        page.wait_for_function(SHOWN, timeout=30_000)
        assert page.evaluate(LIT_SHARE) > 0.02

        run_cell(page, 2)
        assert cell_output(page, 2, "CLOSED") == {"mode": "max", "closed": True, "alive": False}
        assert problems == []
    finally:
        context.close()
