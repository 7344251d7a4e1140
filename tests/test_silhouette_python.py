"""`render(cv, camera)` of a silhouette taken along another view: integrated again along the
camera's view when the chronovolume's store can be opened, else drawn as it is with one
warning naming `Enhance(view=...)`."""

from __future__ import annotations

import shutil
import warnings

import numpy as np
import pytest

import chronocl
from chronocl import Camera, render, render_views
from chronocl.core.enhance import Enhance
from chronocl.data import synthetic

CAMERA = Camera(70, 15)
OTHER_VIEW = (0.0, 0.0, -1.0)  # the default camera's neighbourhood, not CAMERA's view
SIZE = (64, 64)


@pytest.fixture(scope="module")
def data() -> np.ndarray:
    return np.stack(list(synthetic.steps("vortex", 3, (20, 20, 20))))


def silhouette(series, view) -> chronocl.Chronovolume:
    enhance = Enhance("silhouette", k0=0.05, k1=1.5, k2=1.5, view=view)
    return chronocl.integrate(series, "0:3", "alpha", engine="numpy", enhance=enhance)


def test_a_stored_series_is_integrated_again_for_the_camera(tmp_path, data):
    store = tmp_path / "v.zarr"
    chronocl.TimeSeries.from_array(data, source="vortex").save(store)
    series = chronocl.open(store)
    stale = silhouette(series, OTHER_VIEW)
    fresh = silhouette(series, CAMERA.view_direction())
    assert stale.metadata["store"] == str(store.resolve())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning: it could be integrated again
        got = render(stale, CAMERA, SIZE, jitter=False).array
        want = render(fresh, CAMERA, SIZE, jitter=False).array
    np.testing.assert_array_equal(got, want)
    # What the stale one looks like, drawn as it is once its store is gone: not the same.
    shutil.rmtree(store)
    with pytest.warns(UserWarning, match=r"Enhance\('silhouette', view="):
        as_is = render(stale, CAMERA, SIZE, jitter=False).array
    assert np.abs(as_is.astype(int) - want.astype(int)).max() > 16


def test_an_in_memory_series_warns_once_and_draws_as_it_is(data):
    series = chronocl.TimeSeries.from_array(data, source="vortex")
    stale = silhouette(series, OTHER_VIEW)
    assert stale.metadata["store"] is None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        render_views([stale, stale], CAMERA, SIZE, jitter=False)
    texts = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    assert len(texts) == 1 and "Enhance('silhouette', view=" in texts[0], texts
    # Taken along the camera's own view, or not a silhouette: nothing to say.
    edge = chronocl.integrate(series, "0:3", "alpha", engine="numpy", enhance="edge")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        render(silhouette(series, CAMERA.view_direction()), CAMERA, SIZE)
        render(edge, CAMERA, SIZE)
