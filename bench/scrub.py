"""Scrubbing: the time to slide a window by one step, W = 8, 16, 32, 64, on 128^3 data.

With absolute time positions a `Session` updates the window incrementally (fixed-point sums
for modes that slide by inversion, a sliding aggregate of partial chronovolumes for the
others; every registered mode is timed), so a slide
should cost the same at any W; with relative positions every slide re-integrates the window
from resident steps, which grows with W. Each case warms up with W slides (the first slide
after a jump builds the sliding state from all W steps), then times `--slides` slides one by
one, the widths round-robin (one slide of each in turn) so machine noise hits them alike. The
incremental cost is amortised (the stacks are rebuilt every few dozen slides), so the summary
uses the mean over the timed slides (whole rebuild cycles); medians and minima are printed too.

    python bench/scrub.py --quick     # W = 8 and 64, 48 timed slides (one W = 64 cycle); ~2 minutes
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

from chronocl import modes
from chronocl.core.tf import DataTF, TimeTF
from chronocl.data import synthetic
from chronocl.data.series import TimeSeries
from chronocl.integration.interactive.session import Session

MODES = modes.names()
# Opacity everywhere: no voxel is empty, so no step can be skipped.
DENSE_TF = DataTF(points=[(0, 0, 0, 1, 0.02), (0.5, 0, 1, 0, 0.1), (1, 1, 0, 0, 0.5)])
THRESHOLD = 0.05  # the opacity threshold, for the modes that have one


def make_series(n_steps: int, n: int) -> TimeSeries:
    """The vortex data, in memory: 16 distinct steps repeated with a drift so none are equal."""
    base = list(synthetic.steps("vortex", 16, (n, n, n)))
    data = np.empty((n_steps, n, n, n), np.float32)
    for t in range(n_steps):
        data[t] = np.roll(base[t % 16], t // 16, axis=2)
    return TimeSeries.from_array(data)


def time_slides(sessions: dict[int, Session], warmup: int, slides: int) -> dict[int, list[float]]:
    """Slide every session `slides` times, round-robin, so machine noise hits each width alike."""
    for w, session in sessions.items():
        session.set_window(0, w)
        for _ in range(warmup or w):
            session.slide(1)
    times: dict[int, list[float]] = {w: [] for w in sessions}
    for _ in range(slides):
        for w, session in sessions.items():
            t0 = time.perf_counter()
            session.slide(1)
            times[w].append(time.perf_counter() - t0)
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="W = 8 and 64 only")
    ap.add_argument("--size", type=int, default=128, help="edge of the cubic volume")
    # 144 slides hold three full rebuild cycles of the W = 64 stacks (one per 48 slides), so the
    # mean is the amortised cost whatever phase the timing starts in.
    ap.add_argument(
        "--slides", type=int, default=None, help="timed slides per width (default 144, quick 48)"
    )
    ap.add_argument("--relative-slides", type=int, default=3, help="timed slides per relative case")
    ap.add_argument("--engine", default="opencl", choices=["opencl", "numpy"])
    args = ap.parse_args()
    widths = (8, 64) if args.quick else (8, 16, 32, 64)
    if args.slides is None:
        args.slides = 48 if args.quick else 144
    if args.quick:
        args.relative_slides = min(args.relative_slides, 2)
    n = args.size
    n_steps = 2 * max(widths) + args.slides + args.relative_slides + 2
    emit(env_record("scrub", {"size": n, "n_steps": n_steps, "engine": args.engine}))
    series = make_series(n_steps, n)
    case = f"{n}^3"
    per_mode: dict[str, dict[str, dict[int, float]]] = {}
    medians: dict[str, dict[tuple[str, int], float]] = {}
    for mode in MODES:
        per_mode[mode] = {"absolute": {}, "relative": {}}
        for positions in ("absolute", "relative"):
            time_tf = TimeTF.preset("rgb", positions=positions)
            sessions = {
                w: Session(
                    series,
                    memory="12GB",
                    engine=args.engine,
                    mode=mode,
                    data_tf=DENSE_TF,
                    time_tf=time_tf,
                    threshold=THRESHOLD,
                )
                for w in widths
            }
            if positions == "absolute":
                times = time_slides(sessions, 0, args.slides)
            else:
                times = time_slides(sessions, 1, args.relative_slides)
            for w, session in sessions.items():
                path, held = session.stats["path"], session.stats["held_partials"]
                session.close()
                mean = statistics.fmean(times[w])
                per_mode[mode][positions][w] = mean
                medians.setdefault(mode, {})[(positions, w)] = statistics.median(times[w])
                emit(
                    {
                        "bench": "scrub",
                        "case": f"{case}xW{w}",
                        "impl": f"{args.engine}-{path}",
                        "mode": mode,
                        "positions": positions,
                        "mean_s": round(mean, 5),
                        "median_s": round(statistics.median(times[w]), 5),
                        "min_s": round(min(times[w]), 5),
                        "repeats": len(times[w]),
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
        "w64_over_w8_median": {
            m: round(v[("absolute", hi)] / v[("absolute", lo)], 3) for m, v in medians.items()
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
