"""The memory of a sliding window's partials (issue 47): a slide drops the leaving step's
partials before it makes the entering step's, so that these take the memory of those
(`chronocl.core.memory.recycled_empty`'s spares) instead of mapping fresh pages."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core import memory
from chronocl.core.tf import TimeTF

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


def test_a_steady_slide_makes_its_partials_on_the_memory_of_those_it_dropped(monkeypatch):
    """The leaving step's partials go before the entering step's are made, so that each steady
    slide's new partials (16 MiB here, `TUNING.mapped_bytes`) take the memory of dropped ones
    (`recycled_empty`'s spares) instead of mapping fresh pages: pushed first, the slide after the
    state's fill mapped one (0.5-0.7 s at 256^3 on the busy 2-core machine)."""
    data = np.random.default_rng(3).random((24, 16, 256, 256), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    size = 16 * 256 * 256 * 16  # one partial, RGBA float32
    fresh = []
    take = memory.spares.take

    def counted(nbytes: int):
        got = take(nbytes)
        if nbytes == size and got is None:
            fresh.append(nbytes)
        return got

    monkeypatch.setattr(memory.spares, "take", counted)
    memory.spares.clear()
    absolute = TimeTF.preset("rgb", positions="absolute")
    with chronocl.Session(series, mode="alpha", time_tf=absolute) as s:
        s.set_window(0, 20)
        s.slide(1)  # the state's fill maps its partials
        fresh.clear()
        for _ in range(3):  # steady: the stacks split again after ten
            s.slide(1)
            assert s.stats["path"] == "incremental"
    assert fresh == []
