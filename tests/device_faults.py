"""A child process of tests/test_device_faults.py: each kind of device work a frame does
(integrate, gather, recolour by bricks (in z-spans of rows of bricks where the winners are
over one buffer), one recolouring edited again and again, the sliding kernels), with a
failure injected at each of its device calls in turn (an enqueue, a map, a copy, a buffer
made). Each run starts with the device's reused transfer buffers released (a GPU's, or
CHRONOCL_DEVICE_KIND=gpu's: `cold`), so their making is failed too, and the calls are failed
in turn until a run makes fewer than the one failed (runs may differ: an edit rewrites the
bricks the last one coloured as well).

Each failure must reach the caller as raised, and the next run must equal a run that never
failed. A failure that freed host memory under enqueued work kills this process (a segfault
in the kernel that writes it), which the test sees as its exit code. Prints one JSON line per
kind of work: the device calls of its first run, the failures injected (each raised), and for
the brick recolouring the spans it ran in.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pyopencl as cl

from chronocl.core.memory import aligned_empty
from chronocl.core.tf import DataTF, TimeTF
from chronocl.data.series import TimeSeries
from chronocl.engine.device import get_context
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.inmemory import integrate
from chronocl.integration.interactive.winners import winners
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.recolour.bricks import BrickRecolourer
from chronocl.viewer.recolouring import on_host

ENQUEUES = ("enqueue_nd_range_kernel", "enqueue_copy", "enqueue_map_buffer")


class Injected(RuntimeError):
    """The failure injected."""


class Faults:
    """Counts pyopencl's enqueues and buffers made, and raises `Injected` at call `at`."""

    def __init__(self) -> None:
        self.calls, self.at = 0, None
        self.saved = {name: getattr(cl, name) for name in (*ENQUEUES, "Buffer")}
        faults = self

        class Buffer(self.saved["Buffer"]):
            def __init__(self, *args, **kwargs) -> None:
                faults.tick("Buffer")
                super().__init__(*args, **kwargs)

        def wrap(name):
            def call(*args, **kwargs):
                faults.tick(name)
                return self.saved[name](*args, **kwargs)

            return call

        for name in ENQUEUES:
            setattr(cl, name, wrap(name))
        cl.Buffer = Buffer

    def tick(self, name: str) -> None:
        self.calls += 1
        if self.calls == self.at:
            raise Injected(f"injected at device call {self.at} ({name})")


def spec(mode: str, value_range=(0.0, 255.0)) -> IntegrationSpec:
    return IntegrationSpec(mode=mode, data_tf=DataTF(value_range=value_range), time_tf=TimeTF())


def works(size: int) -> dict:
    """name -> a function doing that work on fresh outputs, returning the arrays it made."""
    rng = np.random.default_rng(3)
    nz = ny = nx = size
    width, steps = 4, (1, 2, 3, 4)
    # the window manager's slots: steps as views of one (Z, W, Y, X) block
    block = aligned_empty((nz, width, ny, nx), np.uint8)
    block[...] = rng.integers(0, 256, block.shape, dtype=np.uint8)
    arrays = {s: block[:, i] for i, s in enumerate(steps)}
    t_index = rng.choice(np.array([*steps, -1], np.int32), size=(nz, ny, nx))
    vr = (0.0, 255.0)
    won = winners(t_index, arrays, steps, 8, vr, spec("max"))
    small = np.ascontiguousarray(block[: max(8, nz // 4)].transpose(1, 0, 2, 3)).astype(np.float32)
    series = TimeSeries.from_array(small)
    engine = OpenCLEngine()
    acc = rng.integers(-(2**40), 2**40, (nz // 4, ny, nx, 4), dtype=np.int64)
    step = rng.random((nz // 4, ny, nx, 4), dtype=np.float32)

    def fixed_add():
        out = acc.copy()
        engine.fixed_add(out, step, 1)
        return (out,)

    def bricks():  # prepared and recoloured, as the viewer's first edit of a window
        prepared = on_host(won, None)
        try:
            return (BrickRecolourer().apply(prepared, spec("max")).rgba,)
        finally:
            prepared.release()

    # winners whose value rises along z, and three TFs each opaque on a band of it of its own:
    # each edit colours other bricks, so a brick the failed edit left coloured where its mask
    # says not is left wrong by the next
    ramp = (np.arange(nz) * 255 // max(1, nz - 1)).astype(np.uint8)[:, None, None]
    kept: list = []  # one recolouring edited again and again, as a viewer's slot (made once)

    def band(lo: float, hi: float) -> IntegrationSpec:
        pts = ((0, 1, 1, 1, 0), (lo, 1, 1, 1, 0), (lo + 0.01, 1, 0.5, 0, 1), (hi, 0, 0.5, 1, 1),
               (hi + 0.01, 1, 1, 1, 0), (1, 1, 1, 1, 0))  # fmt: skip
        return IntegrationSpec(mode="max", data_tf=DataTF(points=pts, value_range=vr))

    bands = [band(0.05, 0.3), band(0.35, 0.6), band(0.65, 0.9)]

    def make_kept() -> None:  # before its calls are counted (main), only where it runs
        arrays = {s: np.broadcast_to(ramp, (nz, ny, nx)) for s in steps}
        kept.append(on_host(winners(t_index, arrays, steps, 8, vr, spec("max")), None))

    def bricks_edited():  # each edit's picture, as the viewer shows each
        bricks = BrickRecolourer()
        return tuple(np.array(bricks.apply(kept[0], edit).rgba, copy=True) for edit in bands)

    def integrated(mode):
        def run():
            cv = integrate(series, "0:4", mode, engine=engine, data_tf=DataTF(value_range=vr))
            return (cv.rgba, cv.t_index)

        return run

    bricks_edited.setup = make_kept
    work = {
        "gather": lambda: (lambda w: (w.u, w.k))(
            winners(t_index, arrays, steps, 8, vr, spec("max"), OpenCLEngine())
        ),
        "integrate_max": integrated("max"),
        "integrate_alpha": integrated("alpha"),
        "bricks": bricks,
        "bricks_edited": bricks_edited,
        "fixed_add": fixed_add,
    }
    prepared = on_host(won, None)  # in z-spans of rows of bricks where over one buffer
    assert prepared is not None, "a row of bricks over the device's largest buffer"
    bricks.spans = bricks_edited.spans = len(prepared.spans)
    prepared.release()
    return work


def cold() -> None:
    """The device's reused transfer buffers (a GPU's staging and brick buffers) released: each
    run makes them, so every run makes the same device calls, their making among them, and the
    next run after a failure finds what the failed one left."""
    dc = get_context()
    with dc.lock:
        dc.streams().clear()


def main() -> None:
    size = int(sys.argv[1])
    only = sys.argv[2:]
    faults = Faults()
    for name, work in works(size).items():
        if only and name not in only:
            continue
        if hasattr(work, "setup"):
            work.setup()
        cold()
        faults.calls, faults.at = 0, None
        want = [np.array(a, copy=True) for a in work() if a is not None]
        calls, at = faults.calls, 0
        # each call failed in turn until a run makes fewer: a run's calls may differ from the
        # first's (an edit rewrites the bricks the last one coloured too)
        while True:
            at += 1
            cold()
            faults.calls, faults.at = 0, at
            try:
                work()
            except Injected:
                pass
            else:
                if faults.calls < at:
                    faults.at = None
                    break
                raise SystemExit(f"{name}: the failure at call {at} of {calls} was not raised")
            faults.calls, faults.at = 0, None
            got = [a for a in work() if a is not None]
            for a, b in zip(got, want, strict=True):
                if not np.array_equal(a, b):
                    raise SystemExit(f"{name}: after a failure at call {at}, a wrong result")
        row = {"work": name, "calls": calls, "failures": at - 1}
        if hasattr(work, "spans"):  # the brick recolouring's z-spans (several: capped)
            row["spans"] = work.spans
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
