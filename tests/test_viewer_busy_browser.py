"""The busy box says what a frame answering input is doing, with progress (issue 49).

A series whose steps read slowly once the page is open (a delay injected into every read, as
from a slow disk or network): a jump to another window makes a frame that reads its steps for
seconds. In Chromium the busy box says "reading steps n/N" while it waits, through the same
`progress` messages a refine sends (`chronocl.viewer.progress`), and hides when the frame
comes. The stage words for the other stages are checked on the page's own function.
"""

from __future__ import annotations

import os
import re
import time

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from chronocl.data import synthetic
from chronocl.data.timeseries import TimeSeries

from .test_viewer_refine_browser import WINDOW
from .viewer_helpers import CHROMIUM, browser_page, start_server

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

READ_DELAY_S = 0.4  # per read of a step's rows, once `slow["on"]`
STAGES = """async (ps) => {
  const m = await import(new URL('static/connection.js', location.href).href);
  return ps.map((p) => m.stageText(p));
}"""


@pytest.fixture
def slow_store(tmp_path, monkeypatch):
    """A 32^3 vortex of 40 steps (one level) whose reads are slow once `slow["on"]`."""
    data = np.stack(list(synthetic.steps("vortex", 40, (32, 32, 32))))
    path = tmp_path / "vortex32.zarr"
    TimeSeries.from_array(data, source="vortex 32^3").save(path)
    real = TimeSeries.read_rows
    slow = {"on": False}

    def read_rows(self, step, z0, z1, out):
        if slow["on"] and self.path is not None and self.path.name == path.name:
            time.sleep(READ_DELAY_S)
        return real(self, step, z0, z1, out)

    monkeypatch.setattr(TimeSeries, "read_rows", read_rows)
    return path, slow


def test_the_busy_box_says_which_steps_are_read(slow_store, tmp_path):
    path, slow = slow_store
    shots = os.environ.get("CHRONOCL_SCREENSHOTS", str(tmp_path))
    server = start_server([path])
    try:
        with browser_page(1280, 820) as (page, problems):
            page.goto(server.url)
            page.wait_for_function("() => window.viewer && window.viewer.frames >= 1")
            page.wait_for_function("() => window.viewer.last.level === 0", timeout=60_000)
            busy = page.locator("#busy")
            assert not busy.is_visible()

            slow["on"] = True
            before = page.evaluate("() => window.viewer.frames")
            page.evaluate(WINDOW, {"t0": 28, "t1": 38, "stride": 1})
            # the reads take seconds: the box names the stage and counts the steps read
            page.wait_for_function(
                "() => /reading steps \\d+\\/\\d+/.test(document.getElementById('busy')"
                ".textContent) && !document.getElementById('busy').hidden",
                timeout=30_000,
            )
            text = busy.inner_text()
            assert busy.is_visible()
            assert re.search(r"reading steps \d+/10… \d+\.\d s", text), text
            assert "building a new mode" not in text  # no longer a fixed list of guesses
            page.screenshot(path=os.path.join(shots, "viewer-busy-reading-steps.png"))
            page.locator("#busy").screenshot(path=os.path.join(shots, "viewer-busy-box.png"))
            # it counts up as steps arrive
            first = int(re.search(r"reading steps (\d+)/", text).group(1))
            page.wait_for_function(
                "(n) => { const m = /reading steps (\\d+)\\//.exec("
                "document.getElementById('busy').textContent); return m && +m[1] > n; }",
                arg=first,
                timeout=30_000,
            )

            page.wait_for_function(
                "(n) => window.viewer.frames > n && window.viewer.last.id >= window.viewer.sent",
                arg=before,
                timeout=60_000,
            )
            slow["on"] = False
            page.wait_for_function("() => document.getElementById('busy').hidden", timeout=5_000)
            assert not busy.is_visible()

            # The other stages' words, as the render thread reports them.
            words = page.evaluate(
                STAGES,
                [
                    {"stage": "integrating", "done": 2, "total": 8},
                    {"stage": "preparing the recolouring", "done": 1, "total": 8},
                    {"stage": "drawing", "done": 0, "total": 1},
                    {"stage": "sliding", "done": 0, "total": 0},
                ],
            )
            assert words == [
                "integrating 2/8 slabs",
                "recolouring",
                "drawing",
                "sliding",
            ]
            assert problems == []
    finally:
        server.stop()
