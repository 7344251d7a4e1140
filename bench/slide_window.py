"""Incremental sliding where it pays (issue 47): a one-step slide's sharp frame with a short and
a long window, through the viewer, and which path each frame took.

A generated vortex (float32, `--size`^3, with its coarse levels; kept under `--keep` and reused)
is served by a `ViewerServer` on a thread of this process and opened by the WebSocket client of
viewer_latency.py (`latency_client.Client`) as the page does. The time TF is set to absolute
positions (the viewer's default, relative, recolours every step on a slide, so nothing slides)
and the mode to `--mode`. For each width (`--widths`, default 10 and 50) in turn, `--rounds`
times: a jump to a window of that width at step 0 (to its sharp frame), `--warm` one-step slides
(the sliding state's first fill, where the viewer slides), then `--slides` one-step slides at
full quality as when a drag is let go, each sent when the last one's sharp frame came and timed
from its send to its sharp frame (level 0, not reduced).

Per slide: the ms to the sharp frame and to the first frame, the levels its frames were drawn
at, the ms level 0 waited for its steps to be read (`timings.read_ms`, within its integrate
ms), why a coarse frame read nothing ahead for it (`timings.why_not_read_ahead`), whether
level 0 slid incrementally (the frames' `timings.incremental`) and, where it integrated the
window again, why (`timings.why_not_incremental`: the rates measured on this machine
predicted integrating cheaper, the memory budget, ...). At the end: the rates the viewer
measured (`costs.Costs`, read from the server's views) and the width from which a
one-step slide pays on them. Summary: per width the p50/min/max of the sharp frame and the
paths; `long_over_short`, the long width's p50 over the short one's (issue 47's target <= 2).

    python bench/slide_window.py --keep /tmp/slidew
    python bench/slide_window.py --quick --size 128 --keep /tmp/slidew
"""

from __future__ import annotations

import argparse
import gc
import re
import statistics
import sys
import tempfile
from contextlib import ExitStack
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record, percentiles
from latency_client import Client, sharp
from viewer_latency import make_store

from chronocl.core.budget import resident_bytes
from chronocl.core.tuning import TUNING
from chronocl.data.series import open_series
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.server import ViewerServer

BENCH = "slide_window"
TARGET_LONG_OVER_SHORT = 2.0  # issue 47: a one-step slide's sharp frame, 50 steps over 10


def slide_to(c: Client, t0: int, width: int) -> dict:
    """The window moved to [t0, t0 + width) at full quality: its frames to the sharp one."""
    window = {"t0": t0, "t1": t0 + width, "stride": 1}
    rid = c.send({"type": "update", "window": window, "quality": "full"})
    ms, _ = c.wait(rid, full=True)
    first, _ = c.wait(rid)
    chain = c.chain(rid)
    level0 = [h for h in chain if h.get("level", 0) == 0]
    incremental = any(h["timings"].get("incremental") for h in level0)
    whys = [h["timings"].get("why_not_incremental") for h in level0]
    return {
        "ms": round(ms, 1),
        "first_ms": round(first, 1),
        "levels": [h.get("level", 0) for h in chain],
        "path": "incremental" if incremental else "integrated",
        "why_not_incremental": next((w for w in whys if w), None),
        "integrate_level0_ms": round(sum(h["timings"]["integrate_ms"] for h in level0), 1),
        # of it, waiting for the window's steps (the entering one unless read ahead)
        "read_level0_ms": round(sum(h["timings"]["read_ms"] for h in level0), 1),
        "why_not_read_ahead": next(
            (
                h["timings"]["why_not_read_ahead"]
                for h in chain
                if h["timings"]["why_not_read_ahead"]
            ),
            None,
        ),
        "sharp": sharp(chain[-1]),
    }


def measured_rates() -> list[dict]:
    """The slide costs of the server's views (read, not changed): per level ns per voxel-step
    integrated (d), and in voxel-steps of it a steady one-step slide (s) and a fill per step
    (f), which are the widths from which a slide is predicted cheaper, its state filled (s) and
    to fill (s + f)."""
    from chronocl.viewer.view_sessions import Views

    out = []
    for views in (o for o in gc.get_objects() if isinstance(o, Views)):
        rates = views.slide_costs
        kinds = {key for key in (*rates.slide, *rates.fill)} or {(lv, False) for lv in rates.direct}
        for level, inverts in sorted(k for k in kinds if k[0] in rates.direct):
            d = rates.direct[level]
            s, f = rates.slide.get((level, inverts)), rates.fill.get((level, inverts))
            out.append(
                {
                    "level": level,
                    "slides_by_sums": inverts,  # the mode adds and takes out steps (mean, count)
                    "direct_ns_per_voxel_step": round(1e6 * d, 4),
                    "slide_voxel_steps": None if s is None else round(s, 1),
                    "fill_voxel_steps": None if f is None else round(f, 1),
                    "pays_from_width_filled": None if s is None else round(s, 1),
                    "pays_from_width": None if s is None or f is None else round(s + f, 1),
                }
            )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 round of 3 slides per width")
    ap.add_argument("--size", type=int, default=256, help="volume side (default 256)")
    ap.add_argument("--widths", default="10,50", help="window widths, short first")
    ap.add_argument("--slides", type=int, default=None, help="timed slides per round (6)")
    ap.add_argument("--rounds", type=int, default=None, help="rounds over the widths (2)")
    ap.add_argument("--warm", type=int, default=2, help="untimed slides after each jump")
    ap.add_argument("--mode", default="alpha")
    ap.add_argument("--memory", default=None, help="the viewer's --memory (its default)")
    ap.add_argument("--image", default="512x512", help="panel size WxH")
    ap.add_argument("--keep", type=Path, default=None, help="folder to keep (and reuse) stores")
    ap.add_argument(
        "--guess",
        default=None,
        help="the viewer's guesses before it measured, in voxel-steps of integration: a slide "
        f"and a fill per step, 'S,F' (TUNING.slide_steps, fill_steps: "
        f"{TUNING.slide_steps:g},{TUNING.fill_steps:g}); lower, it tries sliding, then decides",
    )
    args = ap.parse_args()
    if args.guess:  # the server runs in this process
        TUNING.slide_steps, TUNING.fill_steps = (float(v) for v in args.guess.split(","))
    widths = [int(w) for w in args.widths.split(",")]
    slides = args.slides or (3 if args.quick else 6)
    rounds = args.rounds or (1 if args.quick else 2)
    size = tuple(int(v) for v in args.image.lower().split("x"))
    n_steps = max(widths) + args.warm + slides + 2
    n = args.size
    emit(
        env_record(
            BENCH,
            {
                "size": n,
                "steps": n_steps,
                "widths": widths,
                "mode": args.mode,
                "image": size,
                "memory": args.memory or "the viewer's default",
                "guess_slide_fill_steps": [TUNING.slide_steps, TUNING.fill_steps],
            },
        )
    )
    with ExitStack() as stack:
        root = args.keep or Path(
            stack.enter_context(tempfile.TemporaryDirectory(prefix="chronocl-slide-"))
        )
        root.mkdir(parents=True, exist_ok=True)
        path, _ = make_store(root, n, n_steps, np.float32)
        series = open_series(path)
        server = ViewerServer(datasets=[Dataset("vortex", series)], memory=args.memory)
        server.start()
        got: dict[int, list[dict]] = {w: [] for w in widths}
        try:
            c = Client(server)
            c.open(size)
            time_tf = {**c.dataset["state"]["time_tf"], "positions": "absolute"}
            views = [{"mode": args.mode, "order": "forward"}]
            c.request({"type": "update", "time_tf": time_tf, "views": views}, full=True)
            for r in range(rounds):
                for w in widths:
                    jump = slide_to(c, 0, w)  # a window integrated anew
                    emit({"bench": BENCH, "round": r, "width": w, "op": "jump", **jump})
                    for k in range(1, args.warm + 1):
                        warm = slide_to(c, k, w)
                        emit({"bench": BENCH, "round": r, "width": w, "op": "warm", **warm})
                    for k in range(args.warm + 1, args.warm + 1 + slides):
                        one = slide_to(c, k, w)
                        got[w].append(one)
                        emit({"bench": BENCH, "round": r, "width": w, "op": "slide", **one})
            rates = measured_rates()
            c.ws.close()
        finally:
            server.stop()
    summary: dict = {"size": n, "mode": args.mode, "widths": {}}
    for w in widths:
        rows = got[w]
        paths = [r["path"] for r in rows]
        # the reasons, their figures left out (each frame's prediction differs a little)
        whys = {re.sub(r"\d+(\.\d+)?", "#", r["why_not_incremental"] or "") for r in rows}
        summary["widths"][str(w)] = {
            "sharp_ms": percentiles([r["ms"] for r in rows]),
            "first_ms_p50": round(statistics.median(r["first_ms"] for r in rows), 1),
            "integrate_level0_ms_p50": round(
                statistics.median(r["integrate_level0_ms"] for r in rows), 1
            ),
            "read_level0_ms_p50": round(statistics.median(r["read_level0_ms"] for r in rows), 1),
            "incremental": f"{paths.count('incremental')}/{len(paths)}",
            "why_not_incremental": sorted(w for w in whys if w),
            "why_last": rows[-1]["why_not_incremental"],
        }
    short, long = str(min(widths)), str(max(widths))
    p50 = {k: summary["widths"][k]["sharp_ms"]["p50"] for k in (short, long)}
    summary["long_over_short"] = round(p50[long] / p50[short], 2)
    summary["target_long_over_short"] = TARGET_LONG_OVER_SHORT
    summary["rates"] = rates
    summary["rss_mb"] = round((resident_bytes() or 0) / 2**20)
    emit({"bench": BENCH, "summary": summary})


if __name__ == "__main__":
    main()
