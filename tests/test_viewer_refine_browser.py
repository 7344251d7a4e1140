"""Never frozen (issue 32): input during a refine to full resolution is answered at once.

A series whose full-resolution steps read slowly (a delay injected into every read of level
0, as from a slow disk or network; its coarse levels read at full speed) makes each refine
take seconds. In Chromium, the page shows the refine's progress in its status line; a key
pressed while it runs is answered by a frame in a small part of the time the refine takes
when left alone (the refine is given up at its next checkpoint); Esc cancels a refine, and
no full-resolution frame follows until the next change.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

import chronocl
from chronocl.data import synthetic
from chronocl.data.timeseries import TimeSeries

from .viewer_helpers import CHROMIUM, browser_page, start_server

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

READ_DELAY_S = 2.5  # per chunk row of a full-resolution step
# A window as the page sends it (its own module), for jumps no key makes.
WINDOW = """async (w) => {
  const m = await import(new URL('static/connection.js', location.href).href);
  m.update({window: w}, 'full');
}"""


@pytest.fixture
def slow_store(tmp_path, monkeypatch):
    """A 96^3 vortex of 24 steps with coarse levels, whose level 0 reads slowly."""
    data = np.stack(list(synthetic.steps("vortex", 24, (96, 96, 96))))
    path = tmp_path / "vortex96.zarr"
    TimeSeries.from_array(data, source="vortex 96^3").save(path)
    assert chronocl.open(path).n_levels >= 2
    real = TimeSeries.read_rows

    def slow(self, step, z0, z1, out):
        if self.level_index == 0 and self.path is not None and self.path.name == path.name:
            time.sleep(READ_DELAY_S)
        return real(self, step, z0, z1, out)

    monkeypatch.setattr(TimeSeries, "read_rows", slow)
    return path


def frames(page) -> int:
    return page.evaluate("() => window.viewer.frames")


def answered(page, before: int) -> None:
    """Wait for a frame, after the `before` frames seen, that answers the last request sent."""
    page.wait_for_function(
        "(n) => window.viewer.frames > n && window.viewer.last.id !== null"
        " && window.viewer.last.id >= window.viewer.sent",
        arg=before,
        timeout=60_000,
    )


def jump(page, window: list[int]) -> None:
    """Set the window [t0, t1) as the page does and wait for its full-resolution frame."""
    before = frames(page)
    page.evaluate(WINDOW, {"t0": window[0], "t1": window[1], "stride": 1})
    answered(page, before)
    sharp(page)


def sharp(page) -> None:
    page.wait_for_function("() => window.viewer.last.level === 0", timeout=120_000)


def test_input_during_a_refine_is_answered_at_once_and_esc_cancels(slow_store, tmp_path):
    shots = os.environ.get("CHRONOCL_SCREENSHOTS", str(tmp_path))
    server = start_server([slow_store])
    try:
        with browser_page(1280, 820) as (page, problems):
            page.goto(server.url)
            page.wait_for_function("() => window.viewer && window.viewer.frames >= 1")
            sharp(page)  # the first window read at full resolution
            jump(page, [0, 3])

            # Left alone, a refine after a jump reads the window's three steps: its whole time.
            t0 = time.monotonic()
            jump(page, [6, 9])
            alone = time.monotonic() - t0

            # Again, and a key pressed once the refine has begun reading.
            before = frames(page)
            page.evaluate(WINDOW, {"t0": 15, "t1": 18, "stride": 1})
            answered(page, before)
            page.wait_for_function(
                "() => window.viewer.refineProgress"
                " && window.viewer.refineProgress.stage === 'reading steps'"
                " && document.body.dataset.refining === 'yes'",
                timeout=60_000,
            )
            assert "refining to full resolution: reading steps" in page.inner_text("#status")
            page.screenshot(path=os.path.join(shots, "refine-progress.png"))
            before = frames(page)
            t0 = time.monotonic()
            page.locator("#status").click()  # keys go to the page, not a field
            page.keyboard.press("ArrowRight")
            answered(page, before)
            during = time.monotonic() - t0
            assert during < alone / 3, (during, alone)

            # Esc during a refine: cancelled, and no sharp frame follows on its own.
            page.wait_for_function("() => document.body.dataset.refining === 'yes'", timeout=60_000)
            page.keyboard.press("Escape")
            assert page.evaluate("() => document.body.dataset.refining") == "cancelled"
            assert "refine cancelled" in page.inner_text("#status")
            seen = frames(page)
            time.sleep(alone)
            assert page.evaluate("() => window.viewer.last.level") > 0
            assert frames(page) == seen
            assert problems == []
    finally:
        server.stop()
