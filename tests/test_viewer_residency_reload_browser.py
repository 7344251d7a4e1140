"""Target 4 of issue 49: the residency bar against the views' windows, with two views after a
reload (the report: steps 10-15 "not in memory" while the left view showed window 10:20 at
full resolution).

In Chromium: two views, the first on the shared window 10:20, the second on its own window
0:5; once both are at full resolution the page is reloaded (its state comes back from the
address). Then the residency the page holds (`viewer.residency`, from the server's `steps`
messages) covers both windows' steps, and the timeline's residency bar is solid at each of
them (its pixels read back, as `test_prefetch_browser` does).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

import chronocl
from chronocl.data import synthetic
from chronocl.data.timeseries import TimeSeries

from .test_prefetch_browser import BAR_PIXEL
from .test_viewer_page_browser import Page, browser, shots_dir  # noqa: F401
from .test_viewer_refine_browser import WINDOW
from .viewer_helpers import CHROMIUM, start_server

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

SHARED, OWN = (10, 20), (0, 5)
SOLID = [88, 166, 255, 255]  # a resident step's cell of the residency bar
RESIDENT = """(want) => {
  const r = window.viewer.residency;
  return !!r && want.every((s) => r.resident.includes(s));
}"""
WINDOWS = """() => window.viewer.S.state.views.map((v) => v.window || null)"""


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A 96^3 vortex of 24 steps with a coarse level: frames answering input are coarse, and
    the views reach full resolution by a refine (level 0 is what the bar shows)."""
    path = tmp_path_factory.mktemp("viewer-residency") / "vortex.zarr"
    data = np.stack(list(synthetic.steps("vortex", 24, (96, 96, 96))))
    TimeSeries.from_array(data, source="vortex").save(path)
    assert chronocl.open(path).n_levels >= 2
    srv = start_server([path])
    yield srv
    srv.stop()


def settled(p: Page) -> dict:
    """The full-resolution frame answering the newest request (both views at level 0)."""
    p.settle({"seq": 0})
    p.page.wait_for_function("() => window.viewer.last.level === 0", timeout=60_000)
    return p.last()


def test_the_residency_bar_covers_both_views_windows_after_a_reload(
    browser,  # noqa: F811
    server,
    tmp_path,
):
    shots = shots_dir(tmp_path)
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        page.select_option("#nviews", "2")
        settled(p)
        page.evaluate(WINDOW, {"t0": SHARED[0], "t1": SHARED[1], "stride": 1})
        settled(p)
        field = '.view[data-i="1"] input.own-window'
        page.fill(field, f"{OWN[0]}:{OWN[1]}")
        page.press(field, "Enter")
        page.wait_for_function(
            "() => window.viewer.S.state.views.length === 2"
            " && !!window.viewer.S.state.views[1].window"
        )
        settled(p)
        before = page.evaluate(WINDOWS)

        page.reload()
        page.wait_for_function("() => window.viewer && window.viewer.full >= 1", timeout=60_000)
        last = settled(p)
        # the same views and windows as before the reload, both at full resolution
        assert page.evaluate(WINDOWS) == before
        state = page.evaluate("() => window.viewer.S.state.window")
        assert (state["t0"], state["t1"]) == SHARED
        assert last["views"] == 2

        want = [*range(*SHARED), *range(*OWN)]
        try:
            page.wait_for_function(RESIDENT, arg=want, timeout=30_000)
        finally:
            page.locator("#timeline-row").screenshot(
                path=os.path.join(shots, "residency-two-views-after-reload.png")
            )
        residency = page.evaluate("() => window.viewer.residency")
        assert set(want) <= set(residency["resident"]), residency
        bar = {s: page.evaluate(BAR_PIXEL, s) for s in want}
        assert all(px == SOLID for px in bar.values()), bar
        assert p.problems == []
    finally:
        p.context.close()
