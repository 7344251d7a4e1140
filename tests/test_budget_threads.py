"""The memory budget holds however many threads run: an out-of-core integration with 16
threads forced everywhere they can be (chronocl's host threads, PoCL's, zarr's) on this
small machine stays within 1.05x `--memory`, and a budget too small for one slab fails
before any work, in one line.

The integration runs in a fresh process, so what this process holds does not count; its peak
is the kernel's own count (VmHWM, reset just before the integration), not a sample that can
miss it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import psutil
import pytest

from chronocl.core import host_threads
from chronocl.core.errors import InvalidParameterError
from chronocl.data.series import write_series

from .test_cli import assert_one_line_error

FORCED = 16
BUDGET = 64_000_000
STEPS, EDGE = 32, 128  # 268 MB of float32: 4.2x the budget

# Every count that grows with the cores, forced to 16 on this machine.
SIXTEEN = {
    host_threads.THREADS_ENV: str(FORCED),
    "POCL_MAX_PTHREAD_COUNT": str(FORCED),  # PoCL's CPU device: its compute units and threads
    "ZARR_THREADING__MAX_WORKERS": str(FORCED),  # zarr's decode and encode threads
}

CHILD = """
import gc, sys
import numpy as np
import chronocl
from chronocl.core import host_threads
from chronocl.data.series import open_series
from chronocl.integration.runs.streaming import integrate_to_store

series = open_series(sys.argv[1])
warm = np.random.default_rng(0).random((2, 2, 8, 8), dtype=np.float32)
chronocl.integrate(chronocl.TimeSeries.from_array(warm), None, "alpha")  # context, kernels
assert host_threads.workers() == int(sys.argv[4])
del warm
gc.collect()
print("ready", flush=True)
sys.stdin.readline()


def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key + ":"))


with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # the peak resident size (VmHWM) starts again from what is resident now
baseline = status("VmRSS")
integrate_to_store(series, None, sys.argv[2], mode="alpha", memory=int(sys.argv[3]))
print("done", status("VmHWM") - baseline, flush=True)
"""


@pytest.fixture(scope="module")
def big_store(tmp_path_factory):
    """A smooth float32 series with 1 % noise, 4.2x the budget."""
    axis = np.linspace(0, 1, EDGE, dtype=np.float32)
    rng = np.random.default_rng(0)

    def volumes():
        for t in range(STEPS):
            vol = np.sin(6 * axis[None, None, :] + 0.3 * t) * np.cos(5 * axis[None, :, None])
            vol = 0.5 + 0.5 * vol * np.sin(4 * axis[:, None, None])
            yield vol + rng.standard_normal(vol.shape, dtype=np.float32) * np.float32(0.01)

    path = tmp_path_factory.mktemp("big") / "big.zarr"
    return write_series(
        path,
        volumes(),
        n_steps=STEPS,
        volume_shape=(EDGE,) * 3,
        dtype="float32",
        chunk_bytes=1 << 20,
        compressor="zstd",
    )


def peak_growth(store, out, env: dict[str, str]) -> tuple[int, int]:
    """(peak RSS growth during the integration, the kernel's own peak: VmHWM reset before it;
    the most threads the child was seen running, sampled every millisecond)."""
    child = subprocess.Popen(
        [
            sys.executable,
            "-c",
            CHILD,
            str(store.path),
            str(out),
            str(BUDGET),
            env[host_threads.THREADS_ENV],
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # Cold kernel caches of its own. With the PoCL cache other OpenCL tests of the run
        # filled, the child grew by 166-170 MB where it grows by 48 MB cold (its peak read
        # exactly, VmHWM; the old 1 ms sampler missed it): that warm-cache growth is open
        # (issue 46's closing note); the budget checked here is the cold one.
        env={
            **os.environ,
            **env,
            "XDG_CACHE_HOME": str(out.parent / "xdg"),
            "POCL_CACHE_DIR": str(out.parent / "pocl"),
        },
    )
    try:
        assert child.stdout.readline().strip() == "ready", child.stderr.read()
        proc = psutil.Process(child.pid)
        threads = proc.num_threads()
        child.stdin.write("go\n")
        child.stdin.flush()
        while child.poll() is None:
            try:
                threads = max(threads, proc.num_threads())
            except psutil.NoSuchProcess:
                break
            time.sleep(0.001)
        assert child.wait(timeout=300) == 0, child.stderr.read()
        done, growth = child.stdout.readline().split()
        assert done == "done"
    finally:
        if child.poll() is None:
            child.kill()
    return int(growth), threads


def _clears_refs() -> bool:
    """Whether this kernel resets the peak resident size (some sandboxes refuse)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return True


@pytest.mark.skipif(not _clears_refs(), reason="/proc/self/clear_refs cannot reset VmHWM here")
def test_sixteen_threads_stay_within_the_budget(big_store, tmp_path):
    growth, threads = peak_growth(big_store, tmp_path / "cv.zarr", SIXTEEN)
    assert threads >= 2 * FORCED  # PoCL's and chronocl's threads, at least, did run
    assert (tmp_path / "cv.zarr" / "zarr.json").exists()
    assert growth <= 1.05 * BUDGET, (
        f"{FORCED} threads grew by {growth / 1e6:.1f} MB for a {BUDGET / 1e6:.0f} MB budget"
    )


def test_a_budget_below_one_slab_fails_before_any_work(big_store, tmp_path):
    out = tmp_path / "cv.zarr"
    env = {**os.environ, **SIXTEEN}
    bad = subprocess.run(
        [sys.executable, "-m", "chronocl", "integrate", big_store.path, out, "--memory", "1MB"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert_one_line_error(bad, "use --memory")
    assert not out.exists() and not list(tmp_path.iterdir())  # no store, no partial run


@pytest.mark.parametrize("value", ["0", "many", "-2", "1000"])
def test_a_bad_thread_count_is_named(monkeypatch, value):
    monkeypatch.setenv(host_threads.THREADS_ENV, value)
    with pytest.raises(InvalidParameterError, match="CHRONOCL_THREADS"):
        host_threads.workers()


def test_the_thread_count_is_forced_beyond_the_cores(monkeypatch):
    monkeypatch.setenv(host_threads.THREADS_ENV, str(FORCED))
    assert host_threads.workers() == FORCED
    monkeypatch.delenv(host_threads.THREADS_ENV)
    assert host_threads.workers() == max(1, min(host_threads.MAX_THREADS, os.cpu_count() or 1))


def test_a_bad_thread_count_stops_the_cli_before_any_work(big_store, tmp_path):
    out = tmp_path / "cv.zarr"
    env = {**os.environ, host_threads.THREADS_ENV: "many"}
    bad = subprocess.run(
        [sys.executable, "-m", "chronocl", "integrate", big_store.path, out, "--memory", "64MB"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert_one_line_error(bad, "CHRONOCL_THREADS='many' is not a thread count")
    assert not list(tmp_path.iterdir())
