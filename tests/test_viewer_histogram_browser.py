"""Scrubbing in Chromium is never held up by histogram work.

The data set's step samples come from slow storage (each new one takes SLOW_S longer, as a
network store's would; the counts are the real ones), so a window's histogram takes a second
or more while the frames of a 48^3 series take a fraction of that. Where the histogram ran on
the render thread between frames, every frame after one waited for it; on the side thread the
frames keep the scrub's pace. The test compares the two side by side in one run: the frames'
arrival times (Playwright's socket events) and the times the histograms were being counted
(recorded by the data set, in the same process and clock).
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
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.server import ViewerServer

from .viewer_helpers import CHROMIUM, browser_page

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

SLOW_S = 1.0  # extra time of each new step sample
PRESS_S = 0.12  # the scrub's pace: one ArrowRight this often
PRESSES = 24
STEPS, T0 = 64, 27  # the opening window is (27, 37): 10 steps in the middle


class SlowStorage(Dataset):
    """A data set whose step samples are read from slow storage; `counting` holds the
    (start, end) of every window histogram counted."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.counting: list[tuple[float, float]] = []

    def step_sample(self, step: int) -> np.ndarray:
        with self._lock:
            cached = step in self._samples
        if not cached:
            time.sleep(SLOW_S)
        return super().step_sample(step)

    def histogram(self, *args, **kwargs):
        start = time.monotonic()
        try:
            return super().histogram(*args, **kwargs)
        finally:
            self.counting.append((start, time.monotonic()))


def test_frames_keep_the_scrubs_pace_while_histograms_are_counted():
    data = np.stack(list(synthetic.steps("vortex", STEPS, (48, 48, 48))))
    ds = SlowStorage("vortex", chronocl.TimeSeries.from_array(data, source="vortex 48^3"))
    for t in range(T0, T0 + 10):  # the page opens without waiting on slow reads
        ds.step_sample(t)
    server = ViewerServer(datasets=[ds])
    server.start()
    frames: list[float] = []
    hists: list[tuple[float, str]] = []

    def received(payload) -> None:
        if isinstance(payload, bytes):
            frames.append(time.monotonic())
        elif '"type": "histogram"' in payload:
            hists.append((time.monotonic(), payload))

    try:
        with browser_page(1200, 800) as (page, problems):
            page.on("websocket", lambda ws: ws.on("framereceived", received))
            page.goto(server.url)
            page.wait_for_function(
                "() => window.viewer && window.viewer.full >= 1 && window.viewer.S.histogram",
                timeout=120_000,
            )
            page.wait_for_timeout(500)
            ds.counting.clear()
            # Scrub: the window slides one step every PRESS_S; every other slide brings a new
            # sampled step (sample_steps: every 2nd of a 10-step window), read slowly.
            start = time.monotonic()
            for _ in range(PRESSES):
                page.keyboard.press("ArrowRight")
                page.wait_for_timeout(PRESS_S * 1000)
            end = time.monotonic()
            page.wait_for_function(
                f"() => window.viewer.S.histogram.window[0] === {T0 + PRESSES}",
                timeout=60_000,
            )
            assert problems == []
    finally:
        server.stop()

    # The histograms were being counted for most of the scrub: slow work was pending.
    busy = [(max(a, start), min(b, end)) for a, b in ds.counting if b > start and a < end]
    assert sum(b - a for a, b in busy) > 0.5 * (end - start), (busy, start, end)
    inside = [(a, b) for a, b in ds.counting if start <= a and b <= end]
    longest = max((b - a for a, b in inside), default=0.0)
    assert longest >= SLOW_S, (ds.counting, start, end)
    # ...and the frames kept coming meanwhile: frames arrived within every histogram counted
    # during the scrub that took a slow read, and no gap between the scrub's frames is as
    # long as the longest of them (on the render thread, the frame after it would have
    # waited for it whole).
    during = [t for t in frames if start <= t <= end]
    for a, b in inside:
        if b - a >= SLOW_S:
            assert sum(a <= t <= b for t in during) >= 2, (a, b, during)
    gaps = np.diff([start, *during])
    assert len(during) >= PRESSES / 4 and gaps.max() < longest, (gaps, longest)
    # The histogram follows the window: the last is the last window's.
    last = T0 + PRESSES
    assert f'"window": [{last}, {last + 10}, 1]' in hists[-1][1], hists[-1][1]
