"""Each out-of-core run records where its time went (chronocl.integration.runs.stages): every
slab's read, integration and write counted once, the finish after them, and no stage of the
integrating thread longer than the run."""

from __future__ import annotations

import numpy as np

from chronocl.data.series import write_series
from chronocl.integration.inmemory import prepare
from chronocl.integration.runs import stages, streaming
from chronocl.integration.runs.streaming import integrate_to_store


def test_a_run_times_each_stage_of_each_slab(tmp_path):
    data = np.random.default_rng(3).random((6, 24, 16, 16), dtype=np.float32)
    series = write_series(
        tmp_path / "s.zarr", iter(data), n_steps=6, volume_shape=data.shape[1:], dtype="float32"
    )
    job = prepare(series, None, "max", None, {})
    budget = 10 * streaming.slab_bytes(job, 4, "opencl")
    plan = streaming.plan_slabs(job, budget, "opencl", slab=4)
    assert len(plan.slabs) == 6
    out = tmp_path / "cv.zarr"
    integrate_to_store(series, None, out, mode="max", memory=budget, slab=4)
    times = stages.last()
    n = len(plan.slabs)
    assert {s: times[s]["calls"] for s in ("read", "integrate", "write")} == dict.fromkeys(
        ("read", "integrate", "write"), n
    )
    assert times["finish"]["calls"] == 1  # the commit (max finalises per voxel: no second pass)
    assert times["seconds"] > 0
    for s in stages.STAGES:
        assert 0 <= times[s]["thread_cpu_s"] and 0 <= times[s]["wall_s"]
    # The integrating thread runs the kernels and the finish one after the other.
    assert times["integrate"]["wall_s"] + times["finish"]["wall_s"] <= times["seconds"]
