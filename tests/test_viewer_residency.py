"""The timeline's residency (issue 47, "residency.py reads a snapshot the render thread
publishes"; issue 49, a status you can trust): the event loop's poll reads each view's
full-resolution window manager as the render thread published it after its last frame
(`Views.shown_managers`), so the steps it reports are those of the windows shown, two views
on two windows included, and nothing the render thread replaces meanwhile is read."""

from __future__ import annotations

import numpy as np

import chronocl
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.residency import residency
from chronocl.viewer.view_sessions import Views
from chronocl.viewer.view_state import default_state, merge


def test_residency_is_the_published_managers_of_the_views_shown():
    data = np.random.default_rng(3).random((12, 16, 18, 20), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    views = Views([Dataset("d", series)], "opencl", None, "2GB")
    try:
        assert residency(views) == []  # no frame yet: nothing shown
        state = merge(default_state(0, series), {"window": {"t0": 0, "t1": 4}}, 12)
        two = {"views": [{"mode": "alpha"}, {"mode": "max", "window": {"t0": 6, "t1": 10}}]}
        state = merge(state, two, 12)
        views.chronovolumes(state)
        views.full_resolution(range(2))
        got = residency(views)
        assert len(got) == 2 and all(v is not None for v in got)
        resident = set(got[0]["resident"]) | set(got[0]["loading"])
        assert {0, 1, 2, 3} | {6, 7, 8, 9} <= resident  # one manager for both windows
        published = views.shown_managers
        # The render thread replacing a view's session (a mode switch) reads nothing of it:
        # the poll keeps answering from the last frame's managers until the next frame.
        views.slots[1].drop_session()
        assert views.shown_managers is published and len(residency(views)) == 2
        views.chronovolumes(merge(state, {"views": [{"mode": "alpha"}]}, 12))
        assert len(residency(views)) == 1  # the next frame shows one view
    finally:
        views.release()
    assert residency(views) == []
