"""Host-to-device transfers: how uploads overlap the kernels, and what each device format moves.

On a GPU the copy path integrates a brick in chunks whose upload overlaps the kernel of the
chunk before (chronocl/engine/transfer.py). This measures, for one window held in memory
as one xytz brick (the vortex data, float32), per device format (auto = float32, float16,
uint16, uint8): kernel, transfer (uploads + read-backs) and wall seconds from the OpenCL
profiling events, overlapped and serial, and the bytes moved. `transfer_overlap` is
wall / max(kernel, transfer) of the overlapped auto run: 1.0 is perfect overlap, 2.0 none;
on CPU devices, which wrap host memory instead of copying, it is null.

    python bench/transfer.py --quick            # 30x64^3
    python bench/transfer.py                    # 30x128^3, the integrate benchmark's case
    python bench/transfer.py --quick --force    # measure the copy path on a CPU device too

Prints one JSON object (../shared/BENCH.md: an env record, then the figures).
`transfer_overlap(device)` is what bench/integrate.py's summary reports.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record

from chronocl.core.memory import aligned_empty
from chronocl.core.selection import Selection
from chronocl.data import synthetic
from chronocl.engine.device import get_context
from chronocl.engine.device_formats import resolve_format
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.inmemory import make_spec
from chronocl.modes.spec import resolve_order

FORMATS = ("auto", "float16", "uint16", "uint8")


def make_brick(edge: int, steps: int) -> np.ndarray:
    """The vortex window as an xytz float32 brick (Z, W, Y, X) of an edge^3 volume."""
    brick = aligned_empty((edge, steps, edge, edge), np.float32)
    for t, vol in enumerate(synthetic.steps("vortex", steps, (edge, edge, edge))):
        brick[:, t] = vol
    return brick


def measure(engine: OpenCLEngine, brick: np.ndarray, mode: str, repeats: int) -> dict:
    """The transfer statistics of the fastest of `repeats` integrations (after one warm-up)."""
    nz, w, ny, nx = brick.shape
    sel = Selection(tuple(range(w)), w)
    spec = make_spec(mode)
    positions = spec.time_tf.positions_of(sel.steps, w)
    order = resolve_order(spec.order, sel)
    value_range = (float(brick.min()), float(brick.max()))
    out = (aligned_empty((nz, ny, nx, 4), np.float32), aligned_empty((nz, ny, nx), np.int32))
    best = None
    for i in range(repeats + 1):
        engine.accumulate(brick, slice(0, nz), sel.steps, positions, order, spec, value_range, out)
        stats = engine.last_transfer
        if i and (best is None or stats.wall_s < best.wall_s):
            best = stats
    return best.to_dict()


def transfer_overlap(
    device: str | None = None,
    brick: np.ndarray | None = None,
    mode: str = "alpha",
    repeats: int = 5,
    force: bool = False,
) -> float | None:
    """wall / max(kernel, transfer) of the overlapped copy path on `device` (default: the
    selected one) for `brick` (default: 30 steps of the 128^3 vortex, float32); None on CPU
    devices unless `force`."""
    if get_context(device).is_cpu and not force:
        return None
    brick = make_brick(128, 30) if brick is None else brick
    engine = OpenCLEngine(device, host_ptr=False)
    return measure(engine, brick, mode, repeats)["overlap"]


def run(device: str | None, edge: int, steps: int, mode: str, repeats: int, force: bool) -> dict:
    """Every format overlapped and serial on one brick (or null figures on a CPU device)."""
    dc = get_context(device)
    result = {
        "device": dc.info.label,
        "is_cpu": dc.is_cpu,
        "case": f"{steps}x{edge}^3-f32",
        "mode": mode,
        "transfer_overlap": None,
        "formats": {},
    }
    if dc.is_cpu and not force:
        result["note"] = "CPU device: bricks are wrapped in place (no transfer); --force measures"
        return result
    brick = make_brick(edge, steps)
    value_range = (float(brick.min()), float(brick.max()))
    for name in FORMATS:
        fmt = resolve_format(name, brick.dtype, value_range)
        overlapped = OpenCLEngine(device, host_ptr=False, device_format=name)
        serial = OpenCLEngine(device, host_ptr=False, device_format=name, overlap=False)
        on = measure(overlapped, brick, mode, repeats)
        off = measure(serial, brick, mode, repeats)
        result["formats"][name] = {
            "dtype": fmt.dtype.name,
            "max_error_u": fmt.max_error,
            "bytes_up": on["upload_bytes"],
            "bytes_down": on["download_bytes"],
            "overlapped": on,
            "serial": off,
            "serial_over_overlapped_wall": off["wall_s"] / on["wall_s"] if on["wall_s"] else None,
        }
    auto = result["formats"]["auto"]["overlapped"]
    result["transfer_overlap"] = None if dc.is_cpu else auto["overlap"]
    if dc.is_cpu:
        result["note"] = "CPU device forced through the copy path: transfer_overlap stays null"
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="30x64^3 instead of 30x128^3")
    parser.add_argument("--edge", type=int, default=None, help="edge of the cubic volume")
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--mode", default="alpha")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default=None, help="OpenCL device (see 'chronocl devices')")
    parser.add_argument(
        "--force", action="store_true", help="measure the copy path on a CPU device too"
    )
    args = parser.parse_args()
    edge = args.edge or (64 if args.quick else 128)
    figures = run(args.device, edge, args.steps, args.mode, args.repeats, args.force)
    emit({**env_record("transfer"), **figures})


if __name__ == "__main__":
    main()
