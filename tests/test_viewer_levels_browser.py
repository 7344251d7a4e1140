"""A 256^3 series in the browser: the first frame arrives at a coarse level and says so in
the status line; the full-resolution frame follows once input stops."""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

import chronocl
from chronocl.data import synthetic

from .viewer_helpers import CHROMIUM, browser_page, start_server

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)


def test_a_256_cube_arrives_coarse_then_refines(tmp_path):
    data = np.stack(list(synthetic.steps("vortex", 4, (256, 256, 256))))
    path = tmp_path / "vortex256.zarr"
    chronocl.TimeSeries.from_array(data, source="vortex 256^3").save(path)
    del data
    assert chronocl.open(path).n_levels == 3
    shots = os.environ.get("CHRONOCL_SCREENSHOTS", str(tmp_path))
    server = start_server([path])
    try:
        with browser_page(1280, 820) as (page, problems):
            page.goto(server.url)
            page.wait_for_function(
                "() => window.viewer && window.viewer.frames >= 1", timeout=120_000
            )
            coarse = page.evaluate("() => window.viewer.levels[0]")
            assert coarse == 2  # 64^3 first: nothing measured yet on this machine
            level, status = page.evaluate(
                "() => [window.viewer.last.level, document.getElementById('status').textContent]"
            )
            if level > 0:  # (read with the level: a refine's frame replaces the status)
                assert "refining" in status
                page.screenshot(path=os.path.join(shots, "levels-coarse.png"))
            page.wait_for_function(
                "() => window.viewer.last && window.viewer.last.level === 0", timeout=120_000
            )
            status = page.inner_text("#status")
            assert "full resolution (256×256×256)" in status and "refining" not in status
            assert page.evaluate("() => document.body.dataset.refining") == "no"
            page.screenshot(path=os.path.join(shots, "levels-full.png"))
            assert problems == []
    finally:
        server.stop()
