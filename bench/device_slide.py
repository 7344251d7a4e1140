"""One-step slides of a session whose engine copies bricks (a GPU): the sliding state kept on the
device against the same state kept on the host, side by side, with the bytes moved per slide.

An engine that copies bricks (a GPU; here PoCL with host pointers off, the same code path) keeps
a session's incremental state on the device between slides (docs/window.md, "Where the sliding
state lives"): a slide sends up the entering step and reads back the chronovolume. The "host"
case is the state as a CPU device keeps it (what every engine did before): leaves integrated from
stacked host bricks and read back, partials and sums sent to the device for every combine and
fixed-point add, and read back again. Every registered mode, absolute time positions; each case
slides forward then back (`--slides` timed slides after two warm-up slides that build the
state), the two cases alternating per mode so machine noise hits them alike. Bytes are counted
at pyopencl (copies, and buffers made from host memory).

    python bench/device_slide.py --quick    # 128^3, W 10, 6 slides; ~1 minute here
    python bench/device_slide.py            # 256^3

Summary: per mode, ms per slide and MB up / down per slide, device state over host state.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record

from chronocl import modes
from chronocl.core.tf import TimeTF
from chronocl.data.series import TimeSeries
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.interactive import slider
from chronocl.integration.interactive.session import Session


class Transfers:
    """Bytes between host and device through pyopencl while entered (every call goes on)."""

    def __init__(self) -> None:
        self.up = self.down = 0

    def __enter__(self) -> Transfers:
        import pyopencl as cl

        self._saved = cl.enqueue_copy, cl.Buffer
        copy, spy = cl.enqueue_copy, self

        def enqueue_copy(queue, dest, src, **kw):
            to_device = isinstance(dest, cl.MemoryObjectHolder)
            if to_device != isinstance(src, cl.MemoryObjectHolder):
                n = memoryview(src if to_device else dest).nbytes
                spy.up, spy.down = (spy.up + n, spy.down) if to_device else (spy.up, spy.down + n)
            return copy(queue, dest, src, **kw)

        class Buffer(cl.Buffer):
            def __init__(self, context, flags, size=0, hostbuf=None):
                super().__init__(context, flags, size, hostbuf)
                if hostbuf is not None and flags & cl.mem_flags.COPY_HOST_PTR:
                    spy.up += memoryview(hostbuf).nbytes

        cl.enqueue_copy, cl.Buffer = enqueue_copy, Buffer
        return self

    def __exit__(self, *exc: object) -> None:
        import pyopencl as cl

        cl.enqueue_copy, cl.Buffer = self._saved


def slides(series: TimeSeries, engine, mode: str, width: int, n: int, on_device: bool) -> dict:
    """Time `n` one-step slides (forward, then back) with the state on the device or the host."""
    reserve = slider.reserve
    if not on_device:  # no device budget for the state: it stays on the host
        slider.reserve = lambda dc, nbytes: None
    try:
        rgb = TimeTF.preset("rgb", positions="absolute")
        with Session(series, mode=mode, time_tf=rgb, engine=engine, memory="16GB") as s:
            s.set_window(0, width)
            s.slide(1)
            s.slide(1)  # the state is built from the window's leaves
            times, up, down = [], [], []
            for k in [1] * (n - n // 2) + [-1] * (n // 2):
                with Transfers() as moved:
                    t = time.perf_counter()
                    s.slide(k)
                    times.append(time.perf_counter() - t)
                assert s.stats["path"] == "incremental", s.stats
                assert (s.at(0)._slider.dc is not None) == on_device
                up.append(moved.up)
                down.append(moved.down)
    finally:
        slider.reserve = reserve
    mb = 2**20
    return {
        "ms": round(1e3 * statistics.median(times), 1),
        "min_ms": round(1e3 * min(times), 1),
        "up_mb": round(statistics.fmean(up) / mb, 2),
        "down_mb": round(statistics.fmean(down) / mb, 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="128^3, 6 slides")
    ap.add_argument("--size", type=int, default=None, help="edge of the cube (default 256)")
    ap.add_argument("--width", type=int, default=10, help="steps in the window")
    ap.add_argument("--slides", type=int, default=None, help="timed slides (default 8, quick 6)")
    ap.add_argument("--device", default=None, help="OpenCL device (default: chronocl's choice)")
    args = ap.parse_args()
    n = args.size or (128 if args.quick else 256)
    count = args.slides or (6 if args.quick else 8)
    engine = OpenCLEngine(args.device, host_ptr=False)
    device = engine.dc.info.label
    emit(env_record("device_slide", {"size": n, "width": args.width, "device": device}))
    rng = np.random.default_rng(1)
    data = rng.random((args.width + count + 3, n, n, n), dtype=np.float32)
    data[data < 0.3] = 0.0  # some empty space, as in real data
    series = TimeSeries.from_array(data)
    summary = {}
    for mode in modes.names():
        got = {}
        for state in ("host", "device"):
            got[state] = slides(series, engine, mode, args.width, count, state == "device")
            case = {"case": f"{n}^3xW{args.width}", "mode": mode, "state": state}
            emit({"bench": "device_slide", **case, **got[state]})
        host, dev = got["host"], got["device"]
        summary[mode] = {
            "ms": [host["ms"], dev["ms"]],
            "mb_moved": [round(host["up_mb"] + host["down_mb"], 1), dev["up_mb"] + dev["down_mb"]],
            "time_ratio": round(dev["ms"] / host["ms"], 3),
        }
    emit({"bench": "device_slide", "summary": summary, "order": "[host state, device state]"})


if __name__ == "__main__":
    main()
