"""The viewer's window histograms: the sum of small per-step counts, each from a small sample of
its step (the coarsest stored level with enough voxels, else a strided sample decoding a bounded
part of the step), never a full-resolution step; and the side thread they run on."""

from __future__ import annotations

import shutil
import threading

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import ChronoclError
from chronocl.core.tuning import TUNING
from chronocl.core.values import normalize
from chronocl.data import synthetic
from chronocl.data.series import open_series, write_series
from chronocl.viewer.datasets import Dataset, sample_level, sample_steps
from chronocl.viewer.side_work import SideWork


def _steps(shape, n=6):
    return np.stack(list(synthetic.steps("vortex", n, shape))).astype(np.float32)


def _direct(series, source, steps, lo, hi) -> list[int]:
    """The counts summed step by step from `source(step)` (raw values), normalised as u."""
    counts = np.zeros(TUNING.hist_bins, np.int64)
    for t in steps:
        u = normalize(source(t), series.vmin, series.vmax)
        counts += np.histogram(u, bins=TUNING.hist_bins, range=(lo, hi))[0]
    return counts.tolist()


def test_a_store_with_levels_is_counted_from_its_coarsest_level_never_level_0(tmp_path):
    path = tmp_path / "v.zarr"
    chronocl.TimeSeries.from_array(_steps((128, 96, 112)), source="v").save(path)
    series = open_series(path)
    assert series.n_levels == 2 and sample_level(series) == 1  # 64x48x56: enough voxels
    coarse = series.level(1)
    # Level 0's chunks gone: a read of a full-resolution step would fail from now on.
    shutil.rmtree(path / "data" / "c")
    with pytest.raises(ChronoclError):
        series.read([0])
    ds = Dataset("v", series, str(path))
    for lo, hi in ((0.0, 1.0), (0.25, 0.75)):
        hist = ds.histogram(lo, hi, range(1, 6))
        assert hist["steps"] == [1, 2, 3, 4, 5] and hist["range"] == [lo, hi]
        want = _direct(series, lambda t: coarse.read([t])[0], hist["steps"], lo, hi)
        assert hist["counts"] == want
    assert sum(ds.histogram(0.0, 1.0, [2])["counts"]) == 64 * 48 * 56


def test_a_store_without_levels_decodes_a_bounded_strided_part_of_each_step(tmp_path, monkeypatch):
    data = _steps((64, 40, 48), 4)
    step_bytes = 64 * 40 * 48 * 4
    series = write_series(
        tmp_path / "flat.zarr",
        iter(data),
        n_steps=4,
        volume_shape=(64, 40, 48),
        dtype=np.float32,
        levels=False,
        chunk_bytes=step_bytes // 8,  # 8 chunks of 8 rows
    )
    assert series.n_levels == 1 and sample_level(series) == 0 and series.z_chunk == 8
    # At most 3 chunks' bytes decoded per step (the budget of a 64 MiB step at 32 MiB,
    # scaled): chunks 1, 4 and 6 (the middle ones of 3 stretches of z), every 2nd voxel of
    # them (3 * 8 * 40 * 48 / 2^3 = 5760 voxels; the sample size scaled alike).
    monkeypatch.setattr(TUNING, "hist_read_bytes", 3 * step_bytes // 8)
    monkeypatch.setattr(TUNING, "hist_sample_voxels", 5760)
    for c in (0, 2, 3, 5, 7):  # the chunks the sample skips are never read
        shutil.rmtree(tmp_path / "flat.zarr" / "data" / "c" / "2" / str(c))
    ds = Dataset("flat", series)
    hist = ds.histogram(0.1, 0.9, [2])

    def sample(t):
        rows = [data[t, z0 : z0 + 8 : 2, ::2, ::2] for z0 in (8, 32, 48)]
        return np.concatenate(rows)

    assert hist["counts"] == _direct(series, sample, [2], 0.1, 0.9)
    assert sum(hist["counts"]) <= 5760


def test_a_series_in_memory_is_sampled_strided_in_place():
    data = _steps((96, 96, 96), 3)
    series = chronocl.TimeSeries.from_array(data)
    assert sample_level(series) == 0  # its levels would be pooled from level 0
    ds = Dataset("mem", series)
    hist = ds.histogram(0.0, 1.0)
    # 96^3 / 2^18 -> every 2nd voxel along each axis (the sample of the old design, unchanged).
    want = _direct(series, lambda t: data[t, ::2, ::2, ::2], [0, 1, 2], 0.0, 1.0)
    assert hist["steps"] == [0, 1, 2] and hist["counts"] == want


def test_the_window_histogram_is_the_sum_of_its_steps_and_gives_up_when_superseded():
    series = chronocl.TimeSeries.from_array(_steps((32, 32, 32), 12))
    ds = Dataset("v", series)
    steps = sample_steps(range(1, 11))
    assert steps == [2, 4, 6, 8, 10]
    hist = ds.histogram(0.2, 0.8, range(1, 11))
    total = sum(ds.step_counts(t, 0.2, 0.8) for t in steps)
    assert hist["steps"] == steps and hist["counts"] == total.tolist()
    asked: list[int] = []

    def given_up() -> bool:
        asked.append(1)
        return len(asked) > 2  # a newer request came after two steps

    assert ds.histogram(0.3, 0.8, range(1, 11), given_up=given_up) is None
    assert len(asked) == 3


def test_side_work_runs_in_order_and_a_newer_job_of_a_key_replaces_the_waiting_one():
    side = SideWork()
    started, release = threading.Event(), threading.Event()
    ran: list[str] = []
    done = threading.Event()

    def blocker() -> None:
        started.set()
        release.wait(30)
        ran.append("blocker")

    assert side.submit("b", blocker)
    assert started.wait(30)
    # While the blocker runs: an older histogram, a fit, a newer histogram.
    side.submit("histogram", lambda: ran.append("old histogram"))
    side.submit(("fit", 1), lambda: ran.append("fit"))
    assert side.waiting("histogram")
    side.submit("histogram", lambda: ran.append("new histogram"))
    side.submit("end", done.set)
    release.set()
    assert done.wait(30)
    assert ran == ["blocker", "fit", "new histogram"]
    side.close()
    assert side.waiting("histogram") and not side.submit("x", lambda: None)


@pytest.mark.parametrize("value_range", [None, (0.2, 0.7)])
def test_a_change_histogram_counts_the_changes_between_consecutive_steps(value_range):
    """Issue 49: a change mode's data TF maps δ = |Δ| between consecutive steps (values
    clipped to the TF's value range and scaled to it, modes/change.py), so its histogram
    counts those, each sampled step from the step before it in the window (at the stride);
    the window's first step changes from nothing."""
    data = _steps((32, 32, 32), 12)
    series = chronocl.TimeSeries.from_array(data)
    ds = Dataset("v", series)
    lo_v, hi_v = (series.vmin, series.vmax) if value_range is None else value_range
    window = list(range(1, 11, 2))  # 1:11:2
    hist = ds.histogram(0.0, 0.5, window, 2, of="change", value_range=value_range)
    assert hist["of"] == "change" and hist["steps"] == [3, 5, 7, 9]  # 1 has no step before
    want = np.zeros(TUNING.hist_bins, np.int64)
    for t in hist["steps"]:
        # the same voxels as the sample: u over the series' range, then the TF's range
        w = [
            np.clip(
                (
                    series.vmin
                    + ds.step_sample(s).astype(np.float64) * (series.vmax - series.vmin)
                    - lo_v
                )
                / (hi_v - lo_v),
                0,
                1,
            )
            for s in (t - 2, t)
        ]
        want += np.histogram(np.abs(w[1] - w[0]), bins=TUNING.hist_bins, range=(0.0, 0.5))[0]
    assert hist["counts"] == want.tolist() and sum(want) > 0
    # a constant series changes nowhere: every count in the first bin
    flat = Dataset("f", chronocl.TimeSeries.from_array(np.ones((3, 8, 8, 8), np.float32)))
    counts = flat.histogram(0.0, 1.0, [0, 1, 2], of="change")["counts"]
    assert counts[0] == 2 * flat.step_sample(0).size and sum(counts[1:]) == 0
    assert ds.histogram(0.0, 1.0, [4], of="change")["steps"] == []  # one step: no change
