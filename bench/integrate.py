"""Integration throughput: the OpenCL engine against the numpy reference, VTK and the read roofline.

Cases are the paper's Table 1 workloads (10/20/30 steps of 128^3, 512x64x64, 128x128x64) of the
built-in vortex data, float32 and uint8, every mode, the window resident in memory as one xytz
brick, and end to end beside it: `chronocl.integrate` on the same steps as an in-memory series
(`end_to_end_roofline_fraction`, what a user calling it again and again gets: its output on the
memory of the one before, `chronocl.core.memory.recycled_empty`; `fresh_output_roofline_fraction`
a first call, max only, whose output pages fault as they are written) and a `Session`
re-integrating its resident window after a transfer-function edit (`tf_edit_roofline_fraction`,
every edit a new TF, so none is a cache hit; its bound per mode, `tf_edit_roofline_limit`, is
the device's own read on a GPU where that mode's session kept the window on the device, else
the copy to it, and the memory read on a CPU device);
`end_to_end_vs_kernel` is the first over the kernel's own throughput on the prepared brick.
Prints JSON lines (../shared/BENCH.md) and a summary with `roofline_fraction`,
`dense_tf_roofline_fraction` (every mode with a coloured data TF that has opacity everywhere,
so no step can be skipped), `speedup_vs_numpy`, `max_vs_vtk`, `u8_vs_f32` and `transfer_overlap`
(bench/transfer.py; null on CPU devices).

The roofline is one bound, `chronocl.engine.roofline`: the memory read over the same bytes on
every core (numpy's max in one thread per core, STREAM-like; on a GPU the slower of that and
the copy to the device from pinned staging in chunks, as the engine uploads), so every fraction
is <= 1 and one above 1 means the bound is wrong.
The OpenCL read kernel (`read-opencl`) is that read too on a CPU device, and the bound is then
the faster of the two; on a GPU it reads device memory and is reported only.
`max_vs_vtk` is chronocl on every core against VTK's single-threaded TemporalStatistics;
`max_vs_vtk_one_core` races both in a child pinned to one core (PoCL on one thread). chronocl
writes RGBA and t_index per voxel where VTK writes one scalar.

    python bench/integrate.py --quick      # 30x128^3 only, numpy on 10x128x128x64; < 2 minutes
    python bench/integrate.py --quick --size 256   # the main case at 30x256^3 (about 5 GB)
    python bench/integrate.py --quick --size 512 --steps 10   # issue 32's users' window
    python bench/integrate.py              # every Table 1 case
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record, race
from transfer import transfer_overlap
from vtk_peer import make_pipeline, run_max, vtk_available, vtk_version

from chronocl import Session, TimeSeries, integrate, modes, reference
from chronocl.core.budget import available_bytes
from chronocl.core.memory import aligned_empty, spares
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF
from chronocl.data import synthetic
from chronocl.engine import NumpyEngine
from chronocl.engine.opencl import OpenCLEngine
from chronocl.engine.roofline import LIMITS, bound_of, read_fns
from chronocl.integration.inmemory import make_spec
from chronocl.modes.spec import resolve_order

MODES = modes.names()
TABLE1 = {"128^3": (128, 128, 128), "512x64x64": (512, 64, 64), "128x128x64": (128, 128, 64)}
SPEC_ARGS = {"first_hit": {"threshold": 0.05}}
# A coloured data TF with opacity everywhere: no voxel is empty, nothing can be skipped.
DENSE_TF = DataTF(points=[(0, 0, 0, 1, 0.02), (0.5, 0, 1, 0, 0.1), (1, 1, 0, 0, 0.5)])
# Two opacity curves a TF edit alternates between (a user dragging a point).
EDIT_POINTS = (
    [(0, 1, 1, 1, 0), (0.05, 1, 1, 1, 0), (0.3, 1, 1, 1, 0.25), (1, 1, 1, 1, 0.9)],
    [(0, 1, 1, 1, 0), (0.08, 1, 1, 1, 0), (0.35, 1, 1, 1, 0.3), (1, 1, 1, 1, 0.85)],
)


def make_brick(shape_xyz, steps: int, dtype: str) -> np.ndarray:
    """The vortex window as an xytz brick (Z, W, Y, X)."""
    nx, ny, nz = shape_xyz
    brick = aligned_empty((nz, steps, ny, nx), np.float32)
    for t, vol in enumerate(synthetic.steps("vortex", steps, (nz, ny, nx))):
        brick[:, t] = vol
    if dtype == "uint8":
        quantised = aligned_empty(brick.shape, np.uint8)
        scale = np.float32(255 / brick.max())
        for z in range(nz):  # a slab at a time: whole-brick temporaries are 3 x 5.4 GB at 512^3
            quantised[z] = np.round(brick[z] * scale)
        return quantised
    return brick


def case_name(label: str, steps: int, dtype: str) -> str:
    return f"{label}xT{steps}-{'f32' if dtype == 'float32' else 'u8'}"


class Runner:
    def __init__(self, repeats: int) -> None:
        self.repeats = repeats
        self.ocl = OpenCLEngine()
        self.results: dict[tuple[str, str, str], float] = {}  # (case, impl, mode) -> Gvox/s
        self._series: tuple[np.ndarray, TimeSeries] | None = None  # end_to_end_fns' last
        self._out: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # integrate_fn's, by shape
        self.skipped: list[str] = []  # contenders left out for want of memory
        self.room = {"session": True, "vtk": True}  # what `plan_memory` found room for
        self.off_device: set[tuple] = set()  # (brick shape, mode) whose TF-edit session's
        # window left the device (its steps went up at every edit)

    def race(self, shape: tuple, contenders: dict, repeats: int | None = None) -> None:
        """Time contenders {(case, impl, mode): fn} round-robin on bricks of `shape`."""
        nz, w, ny, nx = shape
        n = repeats or self.repeats
        timings = race({"/".join(key): fn for key, fn in contenders.items()}, n)
        for (case, impl, mode), (med, best) in zip(contenders, timings.values(), strict=True):
            gvox = nz * ny * nx * w / med / 1e9
            self.results[(case, impl, mode)] = gvox
            emit(
                {
                    "bench": "integrate",
                    "case": case,
                    "impl": impl,
                    "mode": mode,
                    "median_s": round(med, 6),
                    "min_s": round(best, 6),
                    "repeats": n,
                    "value": round(gvox, 4),
                    "unit": "Gvoxsteps/s",
                }
            )

    def integrate_fn(self, engine, brick, mode, data_tf=None):
        nz, w, ny, nx = brick.shape
        sel = Selection(tuple(range(w)), w)
        spec = make_spec(mode, data_tf=data_tf, **SPEC_ARGS.get(mode, {}))
        positions = spec.time_tf.positions_of(sel.steps, w)
        order = resolve_order(spec.order, sel)
        vr = (0.0, 255.0) if brick.dtype == np.uint8 else (float(brick.min()), float(brick.max()))
        # The output is allocated once and shared by every contender of the shape (they run
        # one after the other): one per contender held 32 of them, 86 GB at 10 x 512^3.
        if (nz, ny, nx) not in self._out:
            self._out = {
                (nz, ny, nx): (
                    aligned_empty((nz, ny, nx, 4), np.float32),
                    aligned_empty((nz, ny, nx), np.int32),
                )
            }
        out = self._out[(nz, ny, nx)]

        def run():
            partial, final = engine.accumulate(
                brick, slice(0, nz), sel.steps, positions, order, spec, vr, out
            )
            if not final:
                reference.finalize(partial, positions, spec)

        return run

    def end_to_end_fns(self, brick, mode) -> dict:
        """`chronocl.integrate` on the brick's steps as an in-memory (T, Z, Y, X) series, and a
        resident `Session` re-integrating after a TF edit (two TFs taken in turn) where its
        copy of the window fits the memory available (else left out, named in `skipped`)."""
        # The series is a (T, Z, Y, X) view of the brick, no copy: its steps lie as the window
        # manager's slots lay them out, and a C-contiguous copy integrates as fast (10 x 256^3:
        # 53-55 ms either way) but does not fit beside the rest at 10 x 512^3.
        if self._series is None or self._series[0] is not brick:
            self._series = (brick, TimeSeries.from_array(np.moveaxis(brick, 1, 0)))
        series = self._series[1]
        steps = series.host
        w = steps.shape[0]
        args = SPEC_ARGS.get(mode, {})

        def call():
            integrate(series, f"0:{w}", mode, engine=self.ocl, **args)

        def fresh():  # a first call at this size: its output's pages fault as it is written
            with spares.aside():  # and the other contenders' spares stay theirs
                integrate(series, f"0:{w}", mode, engine=self.ocl, **args)

        fns = {("integrate-end-to-end", mode): call}
        # Room for the session's slots (twice: a margin) and two outputs of 5 steps' bytes each
        # (float32 RGBA and t_index)
        if self.room["session"]:
            session = Session(series, engine=self.ocl, mode=mode, memory=4 * steps.nbytes, **args)
            session.set_window(0, w)
            edits = itertools.cycle([DataTF(points=p) for p in EDIT_POINTS])

            def tf_edit():
                session.set_spec(data_tf=next(edits))
                if session.stats.get("why_not_on_device"):
                    self.off_device.add((brick.shape, mode))

            fns[("session-tf-edit", mode)] = tf_edit
        else:
            self.skipped.append(f"session-tf-edit/{mode}")
        if mode == "max":
            fns[("integrate-fresh-output", mode)] = fresh
        return fns

    def roofline_fns(self, brick) -> dict:
        """The readers of `chronocl.engine.roofline.read_fns`: the OpenCL read kernel, numpy
        on every core and, on a GPU, the copy to the device."""
        fns = read_fns(self.ocl.dc, brick)
        return {(name, "read"): fn for name, fn in fns.items()}

    def roofline(self, case: str, resident: bool = False) -> tuple[str, float]:
        """(what limits, G voxel-steps/s): the one bound of `chronocl.engine.roofline.bound_of`
        (`resident`: of a window already on the device)."""
        rates = {
            impl: v for (c, impl, mode), v in self.results.items() if c == case and mode == "read"
        }
        limit, gvox = bound_of(rates, resident=resident)
        return LIMITS[limit], gvox


def plan_memory(run: Runner, size: int, steps: int) -> None:
    """Leave out the contenders that hold a copy of the window (a session's slots, VTK's
    steps) where the memory free now cannot hold them beside the rest of the largest case:
    float32 and uint8 bricks, the kernels' output, and `chronocl.integrate`'s two (one kept
    spare) of 5 steps' bytes each (float32 RGBA, t_index)."""
    brick = 4 * size**3 * steps
    outputs = 3 * 5 * 4 * size**3
    need = brick + brick // 4 + outputs
    room = 0.8 * available_bytes()
    run.room["session"] = need + brick + 2 * 5 * 4 * size**3 <= room
    run.room["vtk"] = need + brick <= room


def one_core_vs_vtk(size: int, steps: int, repeats: int) -> float | None:
    """chronocl's max over VTK's on one core: the main case raced in a child process pinned to
    one core, with PoCL on one thread and chronocl's host threads at one."""
    if not vtk_available() or 2 * 4 * size**3 * steps > available_bytes():
        return None  # the child's brick and VTK's copy of it would not fit beside this one
    env = {**os.environ, "POCL_MAX_PTHREAD_COUNT": "1", "CHRONOCL_THREADS": "1"}
    child = [sys.executable, __file__, "--one-core-child", str(size), "--steps", str(steps)]
    child += ["--repeats", str(repeats)]
    result = subprocess.run(child, capture_output=True, text=True, env=env, check=False)
    if result.returncode != 0:
        raise RuntimeError(result.stderr)
    record = json.loads(result.stdout.strip().splitlines()[-1])
    emit(record)
    return record["max_vs_vtk_one_core"]


def one_core_child(size: int, steps: int, repeats: int) -> None:
    """Race chronocl's max against VTK's on the main case, this process on one core."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    run = Runner(repeats)
    assert run.ocl.dc.info.compute_units == 1, "PoCL did not take POCL_MAX_PTHREAD_COUNT=1"
    case = case_name(f"{size}^3", steps, "float32")
    brick = make_brick((size,) * 3, steps, "float32")
    pipeline = make_pipeline(np.ascontiguousarray(np.moveaxis(brick, 1, 0)))
    contenders = {
        (case, "opencl-one-core", "max"): run.integrate_fn(run.ocl, brick, "max"),
        (case, "vtk-temporal-statistics", "max"): lambda: run_max(pipeline),
    }
    run.race(brick.shape, contenders)
    ratio = (
        run.results[(case, "opencl-one-core", "max")]
        / run.results[(case, "vtk-temporal-statistics", "max")]
    )
    print(
        json.dumps(
            {
                "bench": "integrate",
                "case": case,
                "impl": "one-core",
                "max_vs_vtk_one_core": round(ratio, 2),
            }
        )
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="30x128^3 only; under 2 minutes")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument(
        "--size", type=int, default=128, help="edge of the main case's cube (128: the paper's)"
    )
    parser.add_argument(
        "--steps", type=int, default=30, help="steps of the main case's window (30: the paper's)"
    )
    parser.add_argument("--one-core-child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one_core_child:
        one_core_child(args.one_core_child, args.steps, args.repeats)
        return
    main_label = f"{args.size}^3"
    TABLE1.setdefault(main_label, (args.size,) * 3)

    emit(env_record("integrate", {"vtk": vtk_version()}))
    run = Runner(args.repeats)
    plan_memory(run, max(args.size, 128), args.steps if args.quick else max(args.steps, 30))
    main_case = case_name(main_label, args.steps, "float32")
    cases = [(main_label, args.steps)]
    if not args.quick:
        cases = sorted({*cases, *((k, w) for k in TABLE1 for w in (10, 20, 30))})
    roof: dict[str, float] = {}
    limits: dict[str, str] = {}
    for label, steps in cases:
        # float32 and uint8 of one workload race together, so their ratio sees the same machine.
        contenders: dict = {}
        bricks = {}
        for dtype in ("float32", "uint8"):
            brick = bricks[dtype] = make_brick(TABLE1[label], steps, dtype)
            case = case_name(label, steps, dtype)
            for key, fn in run.roofline_fns(brick).items():
                contenders[(case, *key)] = fn
            for mode in MODES:
                contenders[(case, "opencl", mode)] = run.integrate_fn(run.ocl, brick, mode)
            if dtype == "float32":  # what a user gets end to end, beside the kernel alone
                for mode in MODES:
                    for key, fn in run.end_to_end_fns(brick, mode).items():
                        contenders[(case, *key)] = fn
            for mode in MODES:  # opacity everywhere, coloured: nothing can be skipped
                contenders[(case, "opencl-dense-tf", mode)] = run.integrate_fn(
                    run.ocl, brick, mode, data_tf=DENSE_TF
                )
            if case == main_case and vtk_available() and run.room["vtk"]:
                # VTK takes one (Z, Y, X) step at a time.
                pipeline = make_pipeline(np.ascontiguousarray(np.moveaxis(brick, 1, 0)))
                contenders[(case, "vtk-temporal-statistics", "max")] = lambda p=pipeline: run_max(p)
        run.race(bricks["float32"].shape, contenders)
        if (label, steps) == (main_label, args.steps):
            main_shape = bricks["float32"].shape
        for dtype in ("float32", "uint8"):
            case = case_name(label, steps, dtype)
            limits[case], roof[case] = run.roofline(case)
    # A TF edit re-integrates the session's window where it lies: on a GPU, in device memory
    # unless it did not fit there (its steps then go up every time, as any integration's)
    edit_bound = {m: run.roofline(main_case, (main_shape, m) not in run.off_device) for m in MODES}

    # numpy reference, raced against OpenCL: the main case in full runs; with --quick the
    # smallest Table 1 workload (10 steps of 128x128x64), to stay under two minutes.
    np_label, np_steps = ("128^3", 30) if not args.quick else ("128x128x64", 10)
    brick = make_brick(TABLE1[np_label], np_steps, "float32")
    np_name = case_name(np_label, np_steps, "float32") + "-vs-numpy"
    contenders = {}
    for mode in MODES:
        contenders[(np_name, "opencl", mode)] = run.integrate_fn(run.ocl, brick, mode)
        contenders[(np_name, "numpy", mode)] = run.integrate_fn(NumpyEngine(), brick, mode)
    run.race(brick.shape, contenders, repeats=5)
    speedup = {
        m: run.results[(np_name, "opencl", m)] / run.results[(np_name, "numpy", m)] for m in MODES
    }
    vtk_key = (main_case, "vtk-temporal-statistics", "max")
    max_vs_vtk = (
        run.results[(main_case, "opencl", "max")] / run.results[vtk_key]
        if vtk_key in run.results
        else None
    )

    u8 = case_name(main_label, args.steps, "uint8")
    del bricks, brick, contenders  # the one-core child builds its own
    run._series, run._out = None, {}
    spares.clear()
    one_core = one_core_vs_vtk(args.size, args.steps, min(args.repeats, 7))
    summary = {
        "roofline_fraction": {
            m: round(run.results[(main_case, "opencl", m)] / roof[main_case], 3) for m in MODES
        },
        "speedup_vs_numpy": {m: round(v, 1) for m, v in speedup.items()},
        "max_vs_vtk": None if max_vs_vtk is None else round(max_vs_vtk, 2),
        "max_vs_vtk_one_core": one_core,
        "vtk_note": "chronocl writes RGBA (4 float32) and t_index (int32) per voxel, VTK's "
        "TemporalStatistics one scalar; max_vs_vtk is chronocl on every core against VTK on "
        "one, max_vs_vtk_one_core both pinned to one core (PoCL one thread, CHRONOCL_THREADS=1)",
        "u8_vs_f32": {
            m: round(run.results[(u8, "opencl", m)] / run.results[(main_case, "opencl", m)], 2)
            for m in MODES
        },
        "roofline_gvox_s": round(roof[main_case], 3),
        "tf_edit_roofline_gvox_s": {m: round(b[1], 3) for m, b in edit_bound.items()},
        "roofline_limit": limits[main_case],
        "end_to_end_roofline_fraction": {
            m: round(run.results[(main_case, "integrate-end-to-end", m)] / roof[main_case], 3)
            for m in MODES
        },
        # max's call with no spare output memory (the first at a size), and its own kernel's
        "fresh_output_roofline_fraction": round(
            run.results[(main_case, "integrate-fresh-output", "max")] / roof[main_case], 3
        ),
        "tf_edit_roofline_limit": {m: b[0] for m, b in edit_bound.items()},
        "tf_edit_roofline_fraction": {
            m: round(run.results[(main_case, "session-tf-edit", m)] / edit_bound[m][1], 3)
            for m in MODES
            if (main_case, "session-tf-edit", m) in run.results
        },
        "skipped_for_memory": run.skipped
        + ([] if run.room["vtk"] or not vtk_available() else ["vtk"])
        + ([] if one_core is not None or not vtk_available() else ["vtk-one-core"]),
        "end_to_end_vs_kernel": {
            m: round(
                run.results[(main_case, "integrate-end-to-end", m)]
                / run.results[(main_case, "opencl", m)],
                3,
            )
            for m in MODES
        },
        "dense_tf_roofline_fraction": {
            m: round(run.results[(main_case, "opencl-dense-tf", m)] / roof[main_case], 3)
            for m in MODES
        },
        # wall / max(kernel, transfer) of the overlapped copy path; null on CPU devices,
        # which integrate host memory in place
        "transfer_overlap": transfer_overlap(),
        "numpy_case": np_name,
        "device": run.ocl.dc.info.label,
    }
    emit({"bench": "integrate", "summary": summary})


if __name__ == "__main__":
    main()
