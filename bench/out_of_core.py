"""Out-of-core integration: a series >= 4x the memory budget and >= 1 GB, streamed slab by slab.

Generates a smooth time-varying float32 series in a temporary folder (deleted afterwards),
integrates it with `chronocl.streaming.integrate_to_store` under `--budget` in a child process
that records its RSS, and reads the same store with plain zarr in the same run. Prints JSON lines
(../shared/BENCH.md) and a summary with

- `peak_rss_over_budget` = (peak RSS - baseline RSS) / budget, where the baseline is the
  child's RSS after importing chronocl, creating the OpenCL context and building the kernels
  (the interpreter, numpy, zarr, pyopencl and PoCL), measured just before the integration;
  target <= 1.25;
- `throughput_vs_read` = integration throughput / plain zarr read throughput of the same data
  (bytes of the window per second); target >= 0.70.

    python bench/out_of_core.py --quick                  # one compressor, 2 repeats; < 2 minutes
    python bench/out_of_core.py                          # none, zstd and blosc-lz4; 3 repeats
    python bench/out_of_core.py --compressor zstd --mode max
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record

from chronocl.budget import parse_memory
from chronocl.data.series import COMPRESSORS, open_series, write_series


def field(t: int, n: int, steps: int) -> np.ndarray:
    """A smooth travelling pattern with 1 % noise (real data do not compress to nothing)."""
    axis = np.linspace(0.0, 1.0, n, dtype=np.float32)
    z, y, x = axis[:, None, None], axis[None, :, None], axis[None, None, :]
    phase = np.float32(2 * np.pi * t / steps)
    vol = np.sin(6 * x + phase) * np.cos(5 * y - phase) * np.sin(4 * z + 0.5 * phase)
    vol = 0.5 + 0.5 * vol.astype(np.float32)
    rng = np.random.default_rng(t)
    vol += rng.standard_normal(vol.shape, dtype=np.float32) * np.float32(0.01)
    return vol


def generate(path: Path, steps: int, n: int, compressor: str, chunk_mb: float):
    return write_series(
        path,
        (field(t, n, steps) for t in range(steps)),
        n_steps=steps,
        volume_shape=(n, n, n),
        dtype="float32",
        chunk_bytes=int(chunk_mb * 2**20),
        compressor=compressor,
        source=f"bench/out_of_core {steps}x{n}^3",
    )


def disk_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


# -- the child: integrate under the budget, report RSS -----------------------------------------
def _rss() -> int:
    import psutil

    return psutil.Process().memory_info().rss


def _reset_peak() -> bool:
    """Reset the kernel's RSS high-water mark (VmHWM); False where not allowed."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _hwm() -> int | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def child(store: str, out: str, budget: int, mode: str) -> None:
    import gc

    import chronocl
    from chronocl.integrate import prepare
    from chronocl.streaming import integrate_to_store, plan_slabs

    series = open_series(store)
    _, ny, nx = series.volume_shape
    warm = np.random.default_rng(0).random((2, 2, ny, nx), dtype=np.float32)
    chronocl.integrate(chronocl.TimeSeries.from_array(warm), None, mode)  # context, kernels
    plan = plan_slabs(prepare(series, None, mode, None, {}), budget, "opencl")
    del warm
    gc.collect()
    baseline = _rss()
    sampled = [baseline]
    stop = threading.Event()

    def sample() -> None:  # a cross-check where VmHWM cannot be reset
        while not stop.wait(0.002):
            sampled.append(_rss())

    hwm_ok = _reset_peak()
    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    t0 = time.perf_counter()
    integrate_to_store(series, None, out, mode=mode, memory=budget, overwrite=True)
    seconds = time.perf_counter() - t0
    stop.set()
    sampler.join()
    hwm = _hwm() if hwm_ok else None
    peak = max(hwm or 0, max(sampled))
    print(
        json.dumps(
            {
                "seconds": seconds,
                "baseline_rss": baseline,
                "peak_rss": peak,
                "peak_method": "VmHWM reset before the run" if hwm_ok else "sampled every 2 ms",
                "sampled_peak_rss": max(sampled),
                "slabs": len(plan.slabs),
                "slab_rows": plan.slab_rows,
                "estimated_peak": plan.peak_bytes,
            }
        )
    )


def run_child(store: Path, out: Path, budget: int, mode: str) -> dict:
    result = subprocess.run(
        [sys.executable, __file__, "--child", str(store), str(out), str(budget), mode],
        capture_output=True,
        text=True,
        check=False,
    )
    if result.returncode != 0:
        raise RuntimeError(result.stderr)
    return json.loads(result.stdout.strip().splitlines()[-1])


def read_all(store: Path) -> float:
    """Seconds to read every step of the store with plain zarr (whole steps)."""
    series = open_series(store)
    arr = series._zarr
    t0 = time.perf_counter()
    for t in range(series.n_steps):
        np.asarray(arr[t])
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one compressor, 2 repeats")
    parser.add_argument("--steps", type=int, default=16)
    parser.add_argument("--size", type=int, default=256, help="volume edge N (N^3 voxels)")
    parser.add_argument("--budget", default="256MB")
    parser.add_argument("--mode", default="alpha")
    parser.add_argument("--compressor", choices=COMPRESSORS, default=None)
    parser.add_argument("--chunk-mb", type=float, default=4.0, help="stored chunk size (MiB)")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--child", nargs=4, metavar=("STORE", "OUT", "BUDGET", "MODE"))
    args = parser.parse_args()
    if args.child:
        store, out, budget, mode = args.child
        child(store, out, int(budget), mode)
        return

    budget = parse_memory(args.budget)
    data_bytes = args.steps * args.size**3 * 4
    if data_bytes < 4 * budget or data_bytes < 2**30:
        parser.error(f"{data_bytes / 2**30:.2f} GiB of data must be >= 1 GiB and >= 4x budget")
    repeats = args.repeats or (2 if args.quick else 3)
    compressors = [args.compressor] if args.compressor else ["none"] if args.quick else COMPRESSORS
    emit(env_record("out_of_core", {"budget": budget, "chunk_mb": args.chunk_mb}))
    tmp = Path(tempfile.mkdtemp(prefix="chronocl-ooc-"))
    results = {}
    try:
        for comp in compressors:
            store = tmp / f"series-{comp}.zarr"
            t0 = time.perf_counter()
            generate(store, args.steps, args.size, comp, args.chunk_mb)
            on_disk = disk_bytes(store)
            case = f"T{args.steps}x{args.size}^3-f32-{comp}"
            emit(
                {
                    "bench": "out_of_core",
                    "case": case,
                    "impl": "generate",
                    "seconds": round(time.perf_counter() - t0, 2),
                    "data_gb": round(data_bytes / 1e9, 3),
                    "disk_gb": round(on_disk / 1e9, 3),
                }
            )
            reads, runs = [], []
            read_all(store)  # warm the page cache as the integration will find it
            for _ in range(repeats):  # alternate, so machine noise hits both alike
                reads.append(read_all(store))
                runs.append(run_child(store, tmp / "cv.zarr", budget, args.mode))
            read_s = statistics.median(reads)
            int_s = statistics.median(r["seconds"] for r in runs)
            peak = max(r["peak_rss"] for r in runs)
            baseline = statistics.median(r["baseline_rss"] for r in runs)
            emit(
                {
                    "bench": "out_of_core",
                    "case": case,
                    "impl": "zarr-read",
                    "median_s": round(read_s, 3),
                    "min_s": round(min(reads), 3),
                    "repeats": repeats,
                    "value": round(data_bytes / read_s / 1e9, 3),
                    "unit": "GB/s",
                }
            )
            emit(
                {
                    "bench": "out_of_core",
                    "case": case,
                    "impl": "stream-opencl",
                    "mode": args.mode,
                    "median_s": round(int_s, 3),
                    "min_s": round(min(r["seconds"] for r in runs), 3),
                    "repeats": repeats,
                    "value": round(data_bytes / int_s / 1e9, 3),
                    "unit": "GB/s",
                    "gvoxsteps_s": round(args.steps * args.size**3 / int_s / 1e9, 3),
                    "baseline_rss_mb": round(baseline / 1e6, 1),
                    "peak_rss_mb": round(peak / 1e6, 1),
                    "peak_method": runs[0]["peak_method"],
                    "estimated_peak_mb": round(runs[0]["estimated_peak"] / 1e6, 1),
                    "slabs": runs[0]["slabs"],
                    "slab_rows": runs[0]["slab_rows"],
                }
            )
            results[comp] = {
                "peak_rss_over_budget": round((peak - baseline) / budget, 3),
                "throughput_vs_read": round(read_s / int_s, 3),
                "read_gb_s": round(data_bytes / read_s / 1e9, 3),
                "integrate_gb_s": round(data_bytes / int_s / 1e9, 3),
                "baseline_rss_mb": round(baseline / 1e6, 1),
                "disk_gb": round(on_disk / 1e9, 3),
            }
            shutil.rmtree(store)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    main_comp = compressors[0]
    summary = {
        **{k: results[main_comp][k] for k in ("peak_rss_over_budget", "throughput_vs_read")},
        "peak_rss_definition": "(peak RSS - baseline RSS) / budget; baseline = the child's RSS "
        "after importing chronocl, creating the OpenCL context and building the kernels",
        "compressor": main_comp,
        "budget_mb": round(budget / 1e6, 1),
        "data_gb": round(data_bytes / 1e9, 3),
        "data_over_budget": round(data_bytes / budget, 2),
        "mode": args.mode,
        "by_compressor": results,
        "cpu_count": os.cpu_count(),
    }
    emit({"bench": "out_of_core", "summary": summary})


if __name__ == "__main__":
    main()
