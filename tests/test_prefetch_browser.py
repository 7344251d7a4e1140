"""The timeline shows which steps are in memory: resident, being fetched, not loaded.

A series served over loopback HTTP with latency and a slow link; once the first frame is in,
the server's gate holds every chunk request, and a slide makes the entering step (and the one
read ahead of it) wait there: the page's timeline then shows the window's steps resident and
those two being fetched, until the gate opens. The canvas's pixels are read back.
"""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")
pytest.importorskip("aiohttp")

import chronocl
from chronocl.data import synthetic
from chronocl.data.series import write_series
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.server import ViewerServer

from .remote_servers import StoreServer
from .test_prefetch import _GatedHandler
from .viewer_helpers import CHROMIUM, browser_page

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

# The colour of a timeline cell's bar, sampled in the page (in the middle of the residency
# bar, where the timeline says it drew it): resident steps are drawn solid.
BAR_PIXEL = """(step) => {
  const c = document.getElementById('timeline');
  const r = c.getBoundingClientRect();
  const dpr = window.devicePixelRatio || 1;
  const bar = window.viewer.timelineLayout.residency;
  const x = Math.round(((step + 0.5) / window.viewer.S.info.shape.t) * r.width * dpr);
  const y = Math.round((bar.y + bar.h / 2) * dpr);
  return Array.from(c.getContext('2d').getImageData(x, y, 1, 1).data);
}"""


def test_the_timeline_shows_resident_and_fetching_steps(tmp_path):
    steps = list(synthetic.steps("vortex", 24, (24, 24, 24)))
    write_series(
        tmp_path / "v.zarr", steps, n_steps=24, volume_shape=(24, 24, 24), dtype=np.float32
    )
    shots = os.environ.get("CHRONOCL_SCREENSHOTS", str(tmp_path))
    with StoreServer(tmp_path, latency_s=0.05, bytes_per_s=2e6) as store:
        store.gate = threading.Event()
        store.gate.set()
        store.RequestHandlerClass = _GatedHandler
        url = store.url("v.zarr")
        server = ViewerServer(datasets=[Dataset("v over http", chronocl.open(url), url)])
        server.start()
        try:
            with browser_page(1100, 760) as (page, problems):
                page.goto(server.url)
                page.wait_for_function(
                    "() => window.viewer.frames >= 1 && window.viewer.residency"
                    " && window.viewer.residency.resident.length >= 10",
                    timeout=60_000,
                )
                assert page.evaluate("() => window.viewer.S.state.window.t0") == 7  # [7, 17)
                store.gate.clear()  # nothing arrives from now on
                page.keyboard.press("ArrowRight")  # [8, 18): 17 enters, 18 is read ahead
                page.wait_for_function(
                    "() => window.viewer.residency.loading.includes(17)", timeout=30_000
                )
                state = page.evaluate("() => window.viewer.residency")
                assert set(range(8, 17)) <= set(state["resident"])
                assert 17 in state["loading"] and 18 in state["loading"]
                assert not set(state["resident"]) & set(state["loading"])
                page.locator("#timeline-row").screenshot(path=os.path.join(shots, "fetching.png"))
                resident, fetching, empty = (page.evaluate(BAR_PIXEL, s) for s in (10, 17, 22))
                assert resident == [88, 166, 255, 255]  # solid
                assert fetching[3] > 0 and fetching != resident  # hatched
                assert empty[3] == 0  # not loaded: nothing drawn
                store.gate.set()
                page.wait_for_function(
                    "() => window.viewer.residency.resident.includes(18)"
                    " && window.viewer.residency.loading.length === 0",
                    timeout=30_000,
                )
                page.locator("#timeline-row").screenshot(path=os.path.join(shots, "fetched.png"))
                assert page.evaluate(BAR_PIXEL, 17) == resident
                assert problems == []
        finally:
            store.gate.set()
            server.stop()
