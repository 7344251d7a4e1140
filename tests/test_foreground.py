"""Background memory warms yield to frames (issue 46): the warm of free slots lets go of the
GIL in its system calls and pauses between pieces while a frame is being made, so a frame's
passes keep their pace beside it."""

from __future__ import annotations

import statistics
import threading
import time

import numpy as np
import pytest

from chronocl.core import foreground
from chronocl.core.memory import aligned_empty, prefault
from chronocl.render.upload import convert

WARM_BYTES = 1 << 30
ROW_BYTES = 64 << 20


BESIDE_A_WARM = 6.0  # frames' time beside a warm over alone, at most (the test's docstring)


def _occupancy_ms(rgba: np.ndarray) -> float:
    t = time.perf_counter()
    convert(rgba, "f1")
    return 1e3 * (time.perf_counter() - t)


def _beside_a_warm(rgba: np.ndarray) -> float:
    """Frames' mean time beside a warm of WARM_BYTES over their median time alone."""
    for _ in range(3):  # the host threads started, the pages touched
        _occupancy_ms(rgba)
    alone = statistics.median(_occupancy_ms(rgba) for _ in range(9))
    # Rows of 64 MB: each system call as long as a 1 MB one took on a virtual machine whose
    # host returned freed memory (10 ms and more), where holding the GIL showed.
    block = aligned_empty((WARM_BYTES // ROW_BYTES, ROW_BYTES), np.uint8)
    warmed: list[bool] = []
    warm = threading.Thread(
        target=lambda: warmed.append(prefault(block, between=foreground.yield_to_frames))
    )
    during = []
    warm.start()
    try:
        while warm.is_alive() and len(during) < 40:
            with foreground.working():
                during.append(_occupancy_ms(rgba))
            time.sleep(0.005)  # between frames the warm goes on
    finally:
        warm.join(60)
    assert warmed == [True], "the warm did not finish"
    assert len(during) >= 5, f"only {len(during)} frames came during the warm"
    # The mean: a frame that waited for a whole system call is the defect, however few
    return statistics.fmean(during) / alone


@pytest.mark.skipif(
    not prefault(aligned_empty((16, 1 << 20), np.uint8)), reason="no MADV_POPULATE_WRITE (< 5.14)"
)
def test_a_frame_s_occupancy_pass_keeps_its_pace_during_a_warm_of_a_gigabyte():
    """With mmap.madvise (the GIL held) and no pauses the frames took 15x their time alone;
    with this warm 0.7-1.9x on a quiet machine, up to 2.2x beside a 2-core soak, and 3.9-4.2x
    in a CI run whose other worker kept both cores busy meanwhile (the warm's own system calls
    then take the frame's core). The better of two tries, within BESIDE_A_WARM: well under the
    defect's 15x."""
    rng = np.random.default_rng(0)
    shape = (64, 192, 192)
    rgba = (rng.random((*shape, 4)) * 255 * (rng.random((*shape, 1)) < 0.3)).astype(np.uint8)
    ratios = [_beside_a_warm(rgba)]
    if ratios[0] > BESIDE_A_WARM:
        ratios.append(_beside_a_warm(rgba))
    assert min(ratios) <= BESIDE_A_WARM, f"frames beside the warm took {ratios}x their time alone"


def test_work_marked_as_a_frame_holds_background_pieces_back():
    assert not foreground.busy()
    stops = []
    block = aligned_empty((16, 1 << 20), np.uint8)
    assert not prefault(block, between=lambda: stops.append(1) is not None)  # stopped at once
    assert stops == [1]
    with foreground.working():
        with foreground.working():  # nested: still busy when the inner one ends
            pass
        assert foreground.busy()
        assert not foreground.yield_to_frames(timeout=0.05)
    assert foreground.yield_to_frames(timeout=0.0)
