"""A change view's TF editor in Chromium (issue 49): change looks the data TF up at δ = |Δ|
between consecutive steps, so its editor shows the histogram of the window's changes (not of
its values) and an axis in data units of change, from 0 to the TF range's span; back in a value
mode the values' histogram returns.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os

import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from .test_viewer_count_legend_browser import choose
from .test_viewer_page_browser import Page, browser, server, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

HIST = "() => window.viewer.S.histogram"


def test_a_change_view_s_editor_shows_the_changes_histogram_on_a_change_axis(
    browser,  # noqa: F811
    server,  # noqa: F811
    tmp_path,
):
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        page.wait_for_function(f"() => ({HIST})() && ({HIST})().of === 'value'", timeout=60_000)
        values = p.eval(HIST)
        info = p.eval("() => window.viewer.S.info")
        choose(p, "#views .view select.mode", "change")
        page.wait_for_function(f"() => ({HIST})().of === 'change'", timeout=60_000)
        change = p.eval(HIST)
        steps = values["steps"]
        # each counted step from the one before it: the window's first has no change
        first = values["window"][0]
        assert change["steps"] == [t for t in steps if t != first] and len(change["steps"]) >= 4
        assert len(change["counts"]) == len(values["counts"])
        per_step = sum(values["counts"]) // len(steps)  # the sample's voxels in [0, 1]
        assert sum(change["counts"]) == per_step * len(change["steps"])
        assert change["counts"] != values["counts"]
        # most voxels change little between consecutive steps: the mass sits near 0
        half = len(change["counts"]) // 2
        assert sum(change["counts"][:half]) > sum(change["counts"][half:])
        note = page.inner_text("#hist-note")
        assert note.startswith("histogram of |Δ|") and "change across" in note, note
        # the axis: changes from 0 to the series' span (the TF has no range of its own)
        span = info["vmax"] - info["vmin"]
        assert float(page.input_value("#zoom-lo")) == 0
        assert float(page.input_value("#zoom-hi")) == pytest.approx(span, rel=1e-2)
        box = page.locator("#tf").bounding_box()
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        assert page.inner_text("#tf-hover").startswith("|Δ| ")
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-change-histogram.png"))

        choose(p, "#views .view select.mode", "max")  # a value mode again
        page.wait_for_function(f"() => ({HIST})().of === 'value'", timeout=60_000)
        assert p.eval(HIST)["counts"] == values["counts"]
        assert "value across" in page.inner_text("#hist-note")
        assert float(page.input_value("#zoom-lo")) == pytest.approx(info["vmin"], abs=1e-3)
    finally:
        p.close()
