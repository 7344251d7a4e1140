"""Scrubbing: the time to slide a window by one step, W = 8, 16, 32, 64, on 128^3 data.

With absolute time positions a `Session` updates the window incrementally (fixed-point sums
for additive, a sliding aggregate of partial chronovolumes for the other modes), so a slide
should cost the same at any W; with relative positions every slide re-integrates the window
from resident steps, which grows with W. Each case warms up with W slides (the first slide
after a jump builds the sliding state from all W steps), then times `--slides` slides one
by one. The per-slide cost of the incremental path is amortised (stacks are rebuilt every
few dozen slides), so the summary uses the mean over the timed slides; median and minimum
are printed too.

    python bench/scrub.py --quick     # W = 8 and 64, 64 timed slides; < 2 minutes
    python bench/scrub.py             # W = 8, 16, 32, 64

Summary: `w64_over_w8` {mode: mean slide time at W=64 / at W=8, absolute positions}
(target <= 1.5) and `relative_w64_over_w8` for comparison.
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

from chronocl.data import synthetic
from chronocl.data.series import TimeSeries
from chronocl.session import Session
from chronocl.tf import DataTF, TimeTF

MODES = ("alpha", "first_hit", "additive", "max", "min")
# Opacity everywhere: no voxel is empty, so no step can be skipped.
DENSE_TF = DataTF(points=[(0, 0, 0, 1, 0.02), (0.5, 0, 1, 0, 0.1), (1, 1, 0, 0, 0.5)])
SPEC_ARGS = {"first_hit": {"threshold": 0.05}}


def make_series(n_steps: int, n: int) -> TimeSeries:
    """The vortex data, in memory: 16 distinct steps repeated with a drift so none are equal."""
    base = list(synthetic.steps("vortex", 16, (n, n, n)))
    data = np.empty((n_steps, n, n, n), np.float32)
    for t in range(n_steps):
        data[t] = np.roll(base[t % 16], t // 16, axis=2)
    return TimeSeries.from_array(data)


def time_slides(session: Session, width: int, warmup: int, slides: int) -> list[float]:
    session.set_window(0, width)
    for _ in range(warmup):
        session.slide(1)
    times = []
    for _ in range(slides):
        t0 = time.perf_counter()
        session.slide(1)
        times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="W = 8 and 64 only")
    ap.add_argument("--size", type=int, default=128, help="edge of the cubic volume")
    ap.add_argument("--slides", type=int, default=64, help="timed slides per incremental case")
    ap.add_argument("--relative-slides", type=int, default=3, help="timed slides per relative case")
    ap.add_argument("--engine", default="opencl", choices=["opencl", "numpy"])
    args = ap.parse_args()
    widths = (8, 64) if args.quick else (8, 16, 32, 64)
    n = args.size
    n_steps = 2 * max(widths) + args.slides + args.relative_slides + 2
    emit(env_record("scrub", {"size": n, "n_steps": n_steps, "engine": args.engine}))
    series = make_series(n_steps, n)
    case = f"{n}^3"
    per_mode: dict[str, dict[str, dict[int, float]]] = {}
    for mode in MODES:
        per_mode[mode] = {"absolute": {}, "relative": {}}
        for positions in ("absolute", "relative"):
            for w in widths:
                time_tf = TimeTF.preset("rgb", positions=positions)
                with Session(
                    series,
                    memory="12GB",
                    engine=args.engine,
                    mode=mode,
                    data_tf=DENSE_TF,
                    time_tf=time_tf,
                    **SPEC_ARGS.get(mode, {}),
                ) as session:
                    if positions == "absolute":
                        times = time_slides(session, w, w, args.slides)
                    else:
                        times = time_slides(session, w, 1, args.relative_slides)
                    path = session.stats["path"]
                    held = session.stats["held_partials"]
                mean = statistics.fmean(times)
                per_mode[mode][positions][w] = mean
                emit(
                    {
                        "bench": "scrub",
                        "case": f"{case}xW{w}",
                        "impl": f"{args.engine}-{path}",
                        "mode": mode,
                        "positions": positions,
                        "mean_s": round(mean, 5),
                        "median_s": round(statistics.median(times), 5),
                        "min_s": round(min(times), 5),
                        "repeats": len(times),
                        "held_partials": held,
                        "value": round(1e3 * mean, 2),
                        "unit": "ms/slide",
                    }
                )
    lo, hi = min(widths), max(widths)
    summary = {
        "w64_over_w8": {
            m: round(v["absolute"][hi] / v["absolute"][lo], 3) for m, v in per_mode.items()
        },
        "relative_w64_over_w8": {
            m: round(v["relative"][hi] / v["relative"][lo], 3) for m, v in per_mode.items()
        },
        "ms_per_slide_absolute": {
            m: {w: round(1e3 * t, 1) for w, t in v["absolute"].items()} for m, v in per_mode.items()
        },
        "ms_per_slide_relative": {
            m: {w: round(1e3 * t, 1) for w, t in v["relative"].items()} for m, v in per_mode.items()
        },
        "target_w64_over_w8": 1.5,
    }
    emit({"bench": "scrub", "summary": summary})


if __name__ == "__main__":
    main()
