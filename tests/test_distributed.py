"""Integration on a dask.distributed LocalCluster (spawned processes, PoCL on each worker).

Distributed output must be the bytes of the single-process output for every mode; a killed
worker's slabs are re-run; a failed run resumes, skipping finished slabs; an unreachable
scheduler is one clear error. One cluster (2 workers, 1 thread each) serves the module.
"""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

import chronocl
import chronocl.integration.runs.distributed as dist
import chronocl.integration.runs.streaming as streaming
from chronocl.core.errors import EngineUnavailableError, InvalidParameterError
from chronocl.core.tuning import TUNING
from chronocl.data.series import write_series
from chronocl.integration.runs.streaming import RUN_DIR, integrate_to_store, partial_path

from .test_cli import cli
from .test_streaming import CASES, WINDOW, assert_same_bytes

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    with dist.local_cluster(2) as cluster, distributed.Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    rng = np.random.default_rng(11)
    data = rng.random((7, 13, 11, 19), dtype=np.float32)
    data[:, 3:10] *= np.linspace(0.1, 1.0, 19, dtype=np.float32)
    path = tmp_path_factory.mktemp("dist") / "s.zarr"
    return write_series(path, iter(data), n_steps=7, volume_shape=data.shape[1:], dtype="float32")


@pytest.fixture(scope="module")
def local(store):
    """The single-process OpenCL results, computed once per case."""
    cache: dict = {}

    def get(case: str) -> chronocl.Chronovolume:
        if case not in cache:
            mode, args = CASES[case]
            cache[case] = chronocl.integrate(store, WINDOW, mode, **args)
        return cache[case]

    return get


# Functions run on the workers with client.run (imported there from this module).
def _patch_write_slab(delay: float = 0.0, fail_z0: int | None = None) -> None:
    real = getattr(streaming, "_real_write_slab", streaming.write_slab)
    streaming._real_write_slab = real

    def patched(group, job, slab, *rest):
        time.sleep(delay)
        if slab.z0 == fail_z0:
            raise RuntimeError(f"injected failure in slab {slab.z0}")
        return real(group, job, slab, *rest)

    streaming.write_slab = patched


def _restore_write_slab() -> None:
    if hasattr(streaming, "_real_write_slab"):
        streaming.write_slab = streaming._real_write_slab


def test_workers_are_spawned_processes(client):
    methods = client.run(lambda: __import__("multiprocessing").get_start_method())
    assert len(methods) == 2 and set(methods.values()) == {"spawn"}
    assert len(set(client.run(os.getpid).values())) == 2


@pytest.mark.parametrize("case", list(CASES))
def test_distributed_equals_single_process(tmp_path, client, store, local, case):
    mode, args = CASES[case]
    out = integrate_to_store(
        store, WINDOW, tmp_path / "cv.zarr", mode=mode, slab=2, client=client, **args
    )
    assert_same_bytes(out, local(case))
    assert not partial_path(out).exists()


def test_killed_worker_is_replaced_and_the_output_is_the_same(tmp_path, client, store, local):
    mode, args = CASES["alpha-silhouette"]
    out = tmp_path / "cv.zarr"
    client.run(_patch_write_slab, 0.25)  # slow tasks down so one is running when we kill
    errors: list[BaseException] = []

    def run() -> None:
        try:
            integrate_to_store(store, WINDOW, out, mode=mode, slab=1, client=client, **args)
        except BaseException as exc:  # reported below
            errors.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    try:
        markers = partial_path(out) / RUN_DIR
        deadline = time.monotonic() + 60
        while len(list(markers.glob("slab-*.json"))) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert len(list(markers.glob("slab-*.json"))) < 13  # tasks are still running
        victim = sorted(client.run(os.getpid).values())[0]
        os.kill(victim, signal.SIGKILL)
        thread.join(timeout=120)
    finally:
        client.run(_restore_write_slab)
    assert not thread.is_alive() and not errors, errors
    assert_same_bytes(out, local("alpha-silhouette"))
    client.wait_for_workers(2, timeout=60)
    assert victim not in client.run(os.getpid).values()


def test_failed_run_resumes_skipping_finished_slabs(tmp_path, client, store, local, monkeypatch):
    mode, args = CASES["additive-max"]
    out = tmp_path / "cv.zarr"
    client.run(_patch_write_slab, 0.0, 12)  # the last slab fails
    try:
        with pytest.raises(RuntimeError, match="injected failure in slab 12"):
            integrate_to_store(store, WINDOW, out, mode=mode, slab=1, client=client, **args)
    finally:
        client.run(_restore_write_slab)
    assert not out.exists()
    time.sleep(0.5)  # let tasks that were still running finish writing
    done = {p.name for p in (partial_path(out) / RUN_DIR).glob("slab-*.json")}
    assert done and len(done) < 13

    submitted: list = []
    real = dist.DaskExecutor.run_slabs

    def spy(self, task, plan, todo, total):
        submitted.extend(todo)
        return real(self, task, plan, todo, total)

    monkeypatch.setattr(dist.DaskExecutor, "run_slabs", spy)
    integrate_to_store(store, WINDOW, out, mode=mode, slab=1, client=client, **args)
    names = {f"slab-{s.z0:07d}-{s.z1:07d}.json" for s in submitted}
    assert names and names.isdisjoint(done) and len(names) + len(done) == 13
    assert_same_bytes(out, local("additive-max"))


def test_local_and_distributed_runs_share_the_resume_markers(tmp_path, client, store, local):
    """A local run cut short is finished on the cluster (same parameters, same bytes)."""
    out = tmp_path / "cv.zarr"
    real, calls = streaming.write_slab, []

    def failing(group, job, slab, *rest):
        calls.append(slab.z0)
        if len(calls) >= 3:  # this and every later slab (writes run behind the integration)
            raise RuntimeError("injected")
        return real(group, job, slab, *rest)

    streaming.write_slab = failing
    try:
        with pytest.raises(RuntimeError):
            integrate_to_store(store, WINDOW, out, mode="max", slab=2)
    finally:
        streaming.write_slab = real
    assert len(list((partial_path(out) / RUN_DIR).glob("slab-*.json"))) == 2
    integrate_to_store(store, WINDOW, out, mode="max", slab=2, client=client)
    assert_same_bytes(out, local("max"))


def test_worker_without_the_device_fails_clearly(tmp_path, client, store):
    with pytest.raises(EngineUnavailableError, match=r"worker tcp://.*no OpenCL device matches"):
        integrate_to_store(
            store, WINDOW, tmp_path / "cv.zarr", device="no-such-device", client=client
        )
    assert not (tmp_path / "cv.zarr").exists()


@pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")  # flat test data
def test_in_memory_series_cannot_go_to_workers(tmp_path, client):
    series = chronocl.TimeSeries.from_array(np.ones((2, 3, 4, 5), dtype=np.float32))
    with pytest.raises(InvalidParameterError, match="save it first"):
        integrate_to_store(series, None, tmp_path / "cv.zarr", client=client)


def test_cli_runs_on_a_scheduler(tmp_path, client, store, local):
    out = tmp_path / "cv.zarr"
    address = client.scheduler_info()["address"]
    result = cli(
        "integrate", store.path, out, "--mode", "max", "--window", WINDOW, "--scheduler", address
    )
    assert result.returncode == 0, result.stderr
    assert_same_bytes(out, local("max"))


def test_unreachable_scheduler_is_one_line_exit_2(tmp_path, store):
    assert TUNING.connect_timeout_s <= 10
    with pytest.raises(dist.SchedulerUnreachableError, match="cannot reach the dask scheduler"):
        dist.connect_scheduler("tcp://127.0.0.1:9", timeout=1)
    result = cli("integrate", store.path, tmp_path / "cv.zarr", "--scheduler", "tcp://127.0.0.1:9")
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "cannot reach the dask scheduler" in lines[0], result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "cv.zarr").exists()
