"""Viewer latency as users see it: from a client's input to the frame in its hands.

Each case generates the built-in vortex into a chronocl store with its coarse levels and serves
it from a viewer server on a thread of this process. A WebSocket client (bench/latency_client.py)
opens it as the page does (open, then the panel size; the page cache dropped first where this
process may, else the summary says `page_cache: hot`), keeps the viewer's default time TF
(relative positions) and times:

- open -> the first full-resolution ("sharp") frame. A frame is sharp when its header says
  level 0 and not `reduced` (drawn smaller than the panel for the latency target);
- data-TF edits (an opacity control point moved, the fitted range kept, as the page sends
  them; every edit a value no edit before it had: none is a cache hit): the first COLD_EDITS
  right after the open, with no warm-up ("cold"), then the others ("warm"), each to the first
  frame and to the sharp frame; then in every mode: the switch to it, the first edit
  after the switch (where max/min/first_hit/change prepare their winners) and later edits,
  each to its sharp frame;
- scrub steps (the window slid by one step, each sent when the last one's frame came, at
  "preview" quality, as the page's timeline drag does): to the first frame, whether the
  session updated incrementally, and the longest stall (the largest gap between consecutive
  frames, from the first slide's send; and whether a histogram reply came within it);
- scrub stops (SLIDES_PER_STOP one-step slides in a row, the last at "full" quality as when the
  drag is let go, timed from its send to its sharp frame);
- input during a refine: an edit sent 50-300 ms after the refine of the last edit's coarse
  frame was due (TUNING.refine_after_s after that frame), timed to the first frame answering it.

The sharp frames' split (integrate / read-back / upload / render / encode) comes from the frame
headers; read-back is null while the server counts it inside integrate_ms. The direct baseline
makes the same edits without server or socket on a resident level-0 `Session` holding the same
window under the same memory budget, built with the viewer's options (RGBA8 output from the
kernels, the viewer's measured choice of sliding or integrating): set_spec, upload (the
viewer's), draw, JPEG, each timed.

Cases: by default 128^3, 256^3 (float32, 20 steps) and 512^3 (uint8, 12 steps), a 10-step
window, a 512x512 panel, a 12GB budget, the direct baseline at 128^3. `--users` runs the users'
case instead (issue 32): float32 512^3 x 20 steps (about 10.7 GB written), a 10-step window,
the 930x640 panel of a 1400x900 page, the viewer's default memory budget, with the direct
baseline; `--users-side 256` is a dry run of the same path. `--keep DIR` keeps the stores there
and reuses them.

    python bench/viewer_latency.py --quick
    python bench/viewer_latency.py --quick --sizes 128 --image 1024x733
    python bench/viewer_latency.py --quick --users [--users-side 256] [--keep DIR]

Summary keys (per size; under `users` for --users): `first_frame_ms`, `full_res_ms` (TF edit ->
sharp frame), `max_full_res_ms`, `modes` (per mode `switch_ms`, `first_edit_ms`, `edit_ms`; for
max, min, first_hit and change `first_edit_after_look_ms`, the first edit LOOK_S after a switch),
`open_full_res_ms`, `open_first_frame_ms`, `page_cache` ("dropped" or "hot" at the open),
`cold_full_res_ms` / `warm_full_res_ms` (p50, p95, max of the sharp frames after the cold and
the warm edits), `all_full_res_ms` (of all of them together), `cold_over_warm` (the p50s'
ratio; target <= 1.5),
`scrub_first_frame_ms`, `scrub_incremental` ("k/n"), `scrub_stall_ms`, `scrub_stop_full_res_ms`,
`refine_input_wait_ms` (longest; `refine_probes_in_refine` "k/n"), `first_frame_level`,
`full_res_split_ms` (`full_split`), `integrate_gvoxel_steps_s` (the full-resolution integration
of a TF edit), `split_ms` (median timings of each action's frames), `drawn`, `rss_mb` (this
process, server and client, at the end), `memory` (the budget); `direct_tf_edit_ms_128` /
`direct_split_ms_128` (`direct_tf_edit_ms` / `direct_split_ms` under `users`) and `targets`
(issue 32's bounds, each named for the figure it bounds).
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record, percentiles
from latency_client import WINDOW, Client, Edits, refine_probes, scrub, scrub_stops, sharp, tf_edits

from chronocl import modes
from chronocl.core.budget import resident_bytes
from chronocl.data import synthetic
from chronocl.data.series import open_series
from chronocl.integration.interactive.winners import RECOLOURED
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.server import ViewerServer

BENCH = "viewer_latency"
# A user looks at a new mode's picture before editing its TF: this long, here. The viewer
# gathers the winners of max, min, first_hit and change meanwhile (TUNING.prepare_after_s);
# `first_edit_ms` is the edit sent at once, which gives that gather up and makes its own.
LOOK_S = 3.0
USERS_PANEL = (930, 640)  # the view area of a 1400x900 page showing one view
COLD_EDITS = 3  # the edits right after an open, reported on their own as "cold"
# Issue 32, "Targets" (here: 2 cores, llvmpipe; gpu_*: on a lent H100 or H200).
TARGETS = {
    "first_frame_ms": 150,  # every size
    "full_res_ms_256": 400,
    "full_res_ms_512": 1200,
    "max_full_res_ms_512": 500,  # a max-mode TF edit: a recolour only
    "users_full_res_ms": 1500,  # the users' case: sharp frame after a TF edit
    "users_scrub_stop_full_res_ms": 2000,
    "users_open_full_res_ms": 8000,
    "users_refine_input_wait_ms": 250,
    "users_scrub_stall_ms": 300,
    # integrate_gvoxel_steps_s over bench/integrate.py's kernel speed on the same machine, at least
    "users_integrate_vs_kernel": 0.5,
    "gpu_full_res_ms_512": 100,
    "gpu_scrub_stop_full_res_ms_512": 100,
}
SPLIT = (
    "integrate_ms",
    "recolour_ms",
    "readback_ms",
    "upload_ms",
    "upload_overlapped_ms",  # a refine's slabs written while it integrated: within integrate_ms
    "render_ms",
    "encode_ms",
    "server_ms",
)


def summarise(op: str, got: list, case: str) -> dict:
    totals, headers = [g[0] for g in got], [g[1] for g in got]
    split = {
        k: statistics.median(h["timings"][k] for h in headers)
        for k in SPLIT
        if all(k in h["timings"] for h in headers)
    }
    transfer = [t - h["timings"]["server_ms"] for t, h in zip(totals, headers, strict=True)]
    split = {k: round(v, 2) for k, v in split.items()}
    split["transfer_ms"] = round(statistics.median(transfer), 2)
    record = {
        "bench": BENCH,
        "case": case,
        "impl": "viewer",
        "op": op,
        "median_ms": round(statistics.median(totals), 2),
        "min_ms": round(min(totals), 2),
        "max_ms": round(max(totals), 2),
        "repeats": len(totals),
        "split_ms": split,
        "incremental": sum(bool(h["timings"].get("incremental")) for h in headers),
        "levels": sorted({h.get("level", 0) for h in headers}),
        "sharp": sum(sharp(h) for h in headers),
        "frame_bytes": int(statistics.median(h["views"][0]["bytes"] for h in headers)),
        # the image size drawn (the server draws less than asked for when over its draw budget)
        "drawn": sorted({f"{h['views'][0]['width']}x{h['views'][0]['height']}" for h in headers}),
    }
    emit(record)
    return record


def full_split(chains: list[list[dict]]) -> dict:
    """What the server did for a sharp frame after a TF edit: per edit the sum of each timing
    over its frames (the first to the sharp one; null where the headers have none), and
    `integrate_level0_ms`, the full-resolution integration (in whichever frame it ran); medians
    over the edits."""
    keys = SPLIT
    rows = []
    for chain in chains:
        t = [h["timings"] for h in chain]
        row = {k: sum(x[k] for x in t) for k in keys if all(k in x for x in t)}
        level0 = [h["timings"]["integrate_ms"] for h in chain if h.get("level", 0) == 0]
        rows.append(row | {"integrate_level0_ms": sum(level0)})
    keys = (*keys, "integrate_level0_ms")
    got = {k: [row[k] for row in rows if k in row] for k in keys}
    return {k: round(statistics.median(v), 2) if v else None for k, v in got.items()}


def direct_baseline(path: Path, size: tuple[int, int], memory, repeats: int, case: str) -> dict:
    """The same edits without the server: a resident level-0 `Session` over the same window and
    budget, set_spec per edit, then the viewer's upload, a draw at the server's size, JPEG."""
    from chronocl.integration.interactive.costs import Costs
    from chronocl.integration.interactive.session import Session
    from chronocl.render.gl import gl_context
    from chronocl.render.views import raycaster
    from chronocl.viewer.fit import fitted_default
    from chronocl.viewer.frames import JPEG_QUALITY, encode, render_size
    from chronocl.viewer.slots import ViewSlot, upload
    from chronocl.viewer.view_state import default_state, describe_state, merge

    series = open_series(path)
    n = series.n_steps
    state = fitted_default(series, default_state(0, series))
    state = merge(state, {"size": list(size)}, n)
    edit = Edits(describe_state(state)["data_tf"])
    draw_size = render_size(state.size, 1, 1.0)
    rows = []
    options = {"display": True, "slide_costs": Costs()}  # as the viewer's sessions
    with gl_context(), Session(series, memory=memory, spec=state.spec(0), **options) as s:
        rc, slot = raycaster(), ViewSlot()
        s.show(state.selection(n))
        for k in range(repeats + 1):  # a warm-up first (the kernels are built by `show`)
            spec = merge(state, edit(), n).spec(0)
            t = [time.perf_counter()]
            cv = s.set_spec(spec)
            t.append(time.perf_counter())
            slot.volume, slot.uploaded = upload(rc, slot, cv), cv
            t.append(time.perf_counter())
            pixels = rc.draw(slot.volume, state.panel_camera(), draw_size)
            t.append(time.perf_counter())
            encode(pixels, JPEG_QUALITY["full"])
            t.append(time.perf_counter())
            moved = getattr(s.engine, "last_transfer", None)
            back = None if moved is None or moved.download_s is None else 1e3 * moved.download_s
            if k >= 1:
                ms = [1e3 * (b - a) for a, b in itertools.pairwise(t)]
                rows.append([sum(ms), *ms, back])
        slot.release_gl()
    cols = ("total_ms", "integrate_ms", "upload_ms", "render_ms", "encode_ms", "readback_ms")
    med = {
        k: None
        if any(r[i] is None for r in rows)
        else round(statistics.median(r[i] for r in rows), 2)
        for i, k in enumerate(cols)
    }
    record = {"bench": BENCH, "case": case, "impl": "direct", "op": "tf_edit_full_resolution"}
    emit(record | {"median_ms": med["total_ms"], "repeats": len(rows), "split_ms": med})
    return med


def drop_page_cache(path: Path) -> str:
    """The page cache emptied before an open where this process may (root): "dropped"; else
    "hot" (the store was read or written lately, and its reads come from memory)."""
    import os

    os.sync()
    try:
        with open("/proc/sys/vm/drop_caches", "w") as f:
            f.write("1")
    except OSError:
        return "hot"
    return "dropped"


def make_store(root: Path, n: int, steps: int, dtype) -> tuple[Path, str]:
    """The vortex at n^3 x `steps` as a chronocl store with levels (uint8: clipped to [0, 1]
    and scaled); one already at the path is reused."""
    from chronocl.data.writer import write_store

    name = f"{n}^3x{steps}-{np.dtype(dtype).name}-W{WINDOW}"
    path = root / f"vortex-{n}-{steps}-{np.dtype(dtype).name}.zarr"
    if path.exists():
        try:
            s = open_series(path)
            if s.shape == (steps, n, n, n) and s.dtype == np.dtype(dtype):
                return path, name
        except Exception:  # a store that does not open as written is written again
            pass

    def generate():
        for step in synthetic.steps("vortex", steps, (n, n, n)):
            u8 = np.dtype(dtype) == np.uint8
            yield np.round(np.clip(step, 0, 1) * 255).astype(np.uint8) if u8 else step

    write_store(
        path,
        generate(),
        n_steps=steps,
        volume_shape=(n, n, n),
        dtype=dtype,
        source=f"vortex {n}^3",
        progress=True,
        overwrite=True,
    )
    return path, name


def measure(path: Path, case: str, size, memory, edits: int, scrubs: int) -> dict:
    """Every timed action against a server on the store at `path`."""
    r: dict = {"page_cache": drop_page_cache(path)}
    series = open_series(path)
    server = ViewerServer(datasets=[Dataset("vortex", series)], memory=memory)
    server.start()
    try:
        c = Client(server)
        opened = c.open(size)
        edit = Edits(c.dataset["state"]["data_tf"])
        _, cold, _ = tf_edits(c, edit, COLD_EDITS)  # no warm-up: kernels, textures, levels
        firsts, fulls, chains = tf_edits(c, edit, edits)
        r["cold_ms"], r["warm_ms"] = [ms for ms, _ in cold], [ms for ms, _ in fulls]
        r["first"] = summarise("tf_edit_first_frame", firsts, case)
        r["full"] = summarise("tf_edit_full_resolution", fulls, case)
        got, r["stall"] = scrub(c, series.n_steps, scrubs)
        r["scrub"] = summarise("scrub_step", got, case)
        emit({"bench": BENCH, "case": case, "op": "scrub_stall", **r["stall"]})
        stops = scrub_stops(c, series.n_steps, max(2, scrubs // 8))
        r["stop"] = summarise("scrub_stop_full_resolution", stops, case)
        r["probes"] = refine_probes(c, edit)
        emit({"bench": BENCH, "case": case, "op": "refine_input", "probes": r["probes"]})
        # Every mode (issue 45): the switch, the first edit after it (the recoloured modes
        # prepare their winners there), then edits as before.
        r["modes"] = {}
        for mode in modes.names():
            switch_ms, _ = c.request(
                {"type": "update", "views": [{"mode": mode, "order": "forward"}]}, full=True
            )
            _, cold, _ = tf_edits(c, edit, 1)
            _, warm, chains_m = tf_edits(c, edit, min(3, edits))
            r[mode] = summarise(f"{mode}_tf_edit_full_resolution", warm, case)
            # a recolour's frames: the first (recolour, texture write, a draw within the draw
            # budget) and the full-size redraw; the sharp frame's own split holds only the last
            r[mode]["chain_split_ms"] = full_split(chains_m)
            r["modes"][mode] = {
                "switch_ms": round(switch_ms, 1),
                "first_edit_ms": round(cold[0][0], 1),
                "edit_ms": r[mode]["median_ms"],
            }
            if mode in RECOLOURED:  # the first edit after LOOK_S on the switch's picture
                for other in ("alpha", mode):
                    msg = {"type": "update", "views": [{"mode": other, "order": "forward"}]}
                    c.request(msg, full=True)
                time.sleep(LOOK_S)
                _, looked, _ = tf_edits(c, edit, 1)
                r["modes"][mode]["first_edit_after_look_ms"] = round(looked[0][0], 1)
        emit({"bench": BENCH, "case": case, "op": "every_mode", "modes": r["modes"]})
        r["open"] = summarise("open_full_resolution", [(opened["full_ms"], opened["header"])], case)
        r["open_first_ms"] = round(opened["first_ms"], 2)
        r["chains"] = chains
        r["rss_mb"] = round((resident_bytes() or 0) / 2**20)  # this process: server and client
        c.ws.close()
    finally:
        server.stop()
    return r


def record_case(summary: dict, key: str, r: dict, n: int, scrubs: int) -> None:
    """The case's figures into the summary's per-size maps."""
    probes = r["probes"]
    in_refine = [p["wait_ms"] for p in probes if p["in_refine"]]
    split = full_split(r["chains"])
    figures = {
        "first_frame_ms": r["first"]["median_ms"],
        "full_res_ms": r["full"]["median_ms"],
        "max_full_res_ms": r["max"]["median_ms"],
        "open_full_res_ms": r["open"]["median_ms"],
        "open_first_frame_ms": r["open_first_ms"],
        "page_cache": r["page_cache"],
        "cold_full_res_ms": percentiles(r["cold_ms"]),
        "warm_full_res_ms": percentiles(r["warm_ms"]),
        "all_full_res_ms": percentiles(r["cold_ms"] + r["warm_ms"]),
        "cold_over_warm": round(
            statistics.median(r["cold_ms"]) / statistics.median(r["warm_ms"]), 2
        ),
        "scrub_first_frame_ms": r["scrub"]["median_ms"],
        "scrub_incremental": f"{r['scrub']['incremental']}/{scrubs}",
        "scrub_stall_ms": r["stall"]["ms"],
        "scrub_stall_after_histogram": r["stall"]["after_histogram"],
        "scrub_stop_full_res_ms": r["stop"]["median_ms"],
        "refine_input_wait_ms": max(in_refine or [p["wait_ms"] for p in probes]),
        "refine_probes_in_refine": f"{len(in_refine)}/{len(probes)}",
        "first_frame_level": r["first"]["levels"],
        "full_res_split_ms": split,
        "integrate_gvoxel_steps_s": (
            round(WINDOW * n**3 / split["integrate_level0_ms"] / 1e6, 3)
            if split["integrate_level0_ms"]
            else None
        ),
        "split_ms": {k: r[k]["split_ms"] for k in ("first", "full", "scrub", "stop", "max")},
        "max_chain_split_ms": r["max"]["chain_split_ms"],  # recolour and texture write too
        "modes": r["modes"],  # per mode: switch, the first edit after it, later edits (ms)
        "drawn": {k: r[k]["drawn"] for k in ("first", "full", "scrub")},
        "rss_mb": r["rss_mb"],
    }
    for k, v in figures.items():
        summary.setdefault(k, {})[key] = v


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    ap.add_argument("--sizes", default="128,256,512", help="volume sides (default 128,256,512)")
    ap.add_argument(
        "--edits", type=int, default=None, help="TF edits per size (10/20; --users 512: 3/6)"
    )
    ap.add_argument("--keep", type=Path, default=None, help="folder to keep (and reuse) stores in")
    ap.add_argument("--image", default=None, help="panel size WxH (default 512x512)")
    ap.add_argument("--users", action="store_true", help="the users' case only (issue 32)")
    ap.add_argument("--users-side", type=int, default=512, help="its volume side (dry run: 256)")
    args = ap.parse_args()
    image = args.image or ("x".join(map(str, USERS_PANEL)) if args.users else "512x512")
    try:
        size = tuple(int(v) for v in image.lower().split("x"))
        assert len(size) == 2 and min(size) > 0
    except (ValueError, AssertionError):
        ap.error(f"--image {image!r}: give WxH, e.g. 512x512")
    label = f"{size[0]}^2" if size[0] == size[1] else f"{size[0]}x{size[1]}"
    edits = args.edits or (10 if args.quick else 20)
    if args.users and args.users_side >= 384 and not args.edits:  # a sharp frame takes seconds
        edits = 3 if args.quick else 6
    scrubs = 20 if args.quick else 40
    if args.users:  # float32, 20 steps, the viewer's default budget
        cases = [(args.users_side, 20, np.float32, None)]
    else:
        sides = [int(v) for v in args.sizes.split(",")]
        cases = [
            (n, 12, np.uint8, "12GB") if n >= 512 else (n, 20, np.float32, "12GB") for n in sides
        ]
    emit(env_record(BENCH, {"cases": [c[:2] for c in cases], "window": WINDOW, "image": size}))

    summary: dict = {}
    with ExitStack() as stack:
        root = args.keep or Path(
            stack.enter_context(tempfile.TemporaryDirectory(prefix="chronocl-latency-"))
        )
        root.mkdir(parents=True, exist_ok=True)
        for n, steps, dtype, memory in cases:
            path, name = make_store(root, n, steps, dtype)
            case = f"{'users-' if args.users else ''}{name}-{label}"
            r = measure(path, case, size, memory, edits, scrubs)
            out = summary.setdefault("users", {}) if args.users else summary
            record_case(out, str(n), r, n, scrubs)
            out.setdefault("memory", {})[str(n)] = memory or "the viewer's default"
            if args.users or n == 128:
                direct = direct_baseline(path, size, memory, max(2, edits // 3), case)
                suffix = "" if args.users else "_128"
                out[f"direct_tf_edit_ms{suffix}"] = direct["total_ms"]
                out[f"direct_split_ms{suffix}"] = direct
    emit({"bench": BENCH, "summary": {**summary, "targets": TARGETS}})


if __name__ == "__main__":
    main()
