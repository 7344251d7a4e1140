"""VTK peer of the integrate benchmark: vtkTemporalStatistics max equals numpy's max over time."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("vtk")

_PATH = Path(__file__).resolve().parent.parent / "bench" / "vtk_peer.py"
_spec = importlib.util.spec_from_file_location("chronocl_bench_vtk_peer", _PATH)
assert _spec is not None and _spec.loader is not None
vtk_peer = importlib.util.module_from_spec(_spec)
sys.modules.setdefault(_spec.name, vtk_peer)
_spec.loader.exec_module(vtk_peer)

SHAPE = (5, 3, 4, 6)  # T, Z, Y, X: odd and all different, so an axis mix-up shows


def _steps(dtype: type) -> np.ndarray:
    rng = np.random.default_rng(7)
    if dtype == np.uint8:
        return rng.integers(0, 256, size=SHAPE, dtype=np.uint8)
    return rng.standard_normal(SHAPE, dtype=np.float32)


def test_vtk_is_available():
    assert vtk_peer.vtk_available()
    assert vtk_peer.vtk_version()


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
def test_max_over_time_matches_numpy(dtype):
    a = _steps(dtype)
    got = vtk_peer.run_max(vtk_peer.make_pipeline(a))
    assert got.shape == SHAPE[1:]
    assert got.dtype == a.dtype
    np.testing.assert_array_equal(got, a.max(axis=0))


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
def test_run_max_reexecutes_every_call(dtype):
    a = _steps(dtype)
    pipe = vtk_peer.make_pipeline(a)
    first = vtk_peer.run_max(pipe)
    expected_first = a.max(axis=0)
    np.testing.assert_array_equal(first, expected_first)
    # The source wraps `a` without copying, so an in-place change is only seen if the
    # pipeline really runs all time steps again.
    a[3, 1, 2, 4] = np.iinfo(np.uint8).max if dtype == np.uint8 else 100.0
    a[SHAPE[0] - 1, 0, 0, 0] = 255 if dtype == np.uint8 else 50.0
    second = vtk_peer.run_max(pipe)
    np.testing.assert_array_equal(second, a.max(axis=0))
    assert second[1, 2, 4] == a[3, 1, 2, 4]
    assert second[0, 0, 0] == a[SHAPE[0] - 1, 0, 0, 0]
    # The first result is an independent array, untouched by the second run.
    np.testing.assert_array_equal(first, expected_first)


def test_single_time_step():
    a = _steps(np.float32)[:1].copy()
    np.testing.assert_array_equal(vtk_peer.run_max(vtk_peer.make_pipeline(a)), a[0])


def test_rejects_non_contiguous_or_wrong_rank():
    a = _steps(np.float32)
    with pytest.raises(ValueError):
        vtk_peer.make_pipeline(a[:, :, :, ::2])
    with pytest.raises(ValueError):
        vtk_peer.make_pipeline(a[0])
