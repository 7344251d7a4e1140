"""A max-mode TF edit at full resolution: integrating it vs recolouring it (issue 32).

The users' case: the built-in vortex, float32, `--side`^3 (default 512) x `--steps` (20), a
10-step window resident at level 0, a `--image` panel (930x640, a 1400x900 page), on this
process's GL context. Side by side, on the same session and textures, for `--edits` data-TF
and time-TF edits (each a value no edit before it had):

- before (what a TF edit costs without recolouring): `Session.set_spec` integrates the window
  (the viewer's display format, RGBA8 from the kernels), the viewer's `upload` writes it into
  the texture, the raycaster draws it;
- after: `LevelSession.recolours` (of `session.at(0)`) says the edit only recolours,
  `GLRecolourer.apply` rewrites the texture from the winners (kernels/glsl/recolour.comp),
  the raycaster draws it ("gl", the GPU path); or `BrickRecolourer.apply` writes RGBA8 on the
  OpenCL device over the bricks the edit may colour or the array held, and `recolour.show`
  writes what changed into a texture of its own ("bricks", the viewer's path on llvmpipe;
  `bricks_recoloured` the share of bricks). Preparing the winners (gathered by numpy and by
  OpenCL, the GL upload, the brick summaries) is timed on its own: it happens once per
  integrated window, at its first edit.

Each edit's recoloured picture is compared with the integrated one (max / 99th percentile
pixel difference). `--png DIR` saves the picture before the edits, each recoloured and the
last integrated one. The data is generated into a memory-mapped .npy (`--keep DIR` keeps and
reuses it), so only the window's resident steps take memory.

    python bench/recolour.py [--quick] [--side 512] [--png DIR] [--keep DIR]

Figures are bounded by the same 2-core llvmpipe for every path (compute shader and raycaster
on the CPU); on a GPU the recolour pass is a few milliseconds (not measured here).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import emit, env_record

from chronocl.core.tf import DataTF, TimeTF
from chronocl.data import synthetic
from chronocl.data.series import TimeSeries
from chronocl.integration.interactive.session import Session
from chronocl.integration.interactive.winners import winners
from chronocl.render.camera import Camera
from chronocl.render.raycaster import Raycaster
from chronocl.render.recolour import show
from chronocl.render.recolour.bricks import BrickRecolourer
from chronocl.render.recolour.gl import GLRecolourer
from chronocl.viewer.slots import ViewSlot, upload

TIME_COLOURS = ("warm-cool", "rgb", "lightness", "white")


def series_of(side: int, n_steps: int, keep: Path | None) -> TimeSeries:
    """The vortex (n_steps, side^3) float32 in a memory-mapped .npy, generated once."""
    root = keep or Path(tempfile.mkdtemp(prefix="chronocl-recolour-"))
    root.mkdir(parents=True, exist_ok=True)
    path = root / f"vortex_{side}_{n_steps}.npy"
    if not path.exists():
        part = path.with_suffix(".part.npy")
        out = np.lib.format.open_memmap(part, "w+", np.float32, (n_steps, side, side, side))
        for t, step in enumerate(synthetic.steps("vortex", n_steps, (side,) * 3)):
            out[t] = step
        out.flush()
        del out
        part.rename(path)
    return TimeSeries.from_array(np.load(path, mmap_mode="r"), source=f"vortex {side}^3")


def edit(i: int, fitted) -> tuple[DataTF, TimeTF]:
    """Edit i: an opacity control point moved and a time colour, never repeated."""
    x = 0.2 + 0.013 * i
    points = (
        (0.0, 1, 1, 1, 0.0),
        (0.05, 1, 1, 1, 0.0),
        (x, 1, 1, 1, 0.25 + 0.01 * i),
        (1, 1, 1, 1, 0.9),
    )
    return DataTF(points=points, value_range=fitted), TimeTF.preset(TIME_COLOURS[i % 4])


def _recoloured(s: Session, spec):
    """`spec` fixed for the window of `s`'s finest level, which it only recolours."""
    recolour = s.at(0).recolours(spec)
    assert not isinstance(recolour, str), recolour
    return recolour.spec


def save(pixels: np.ndarray, path: Path) -> None:
    from PIL import Image

    Image.fromarray(pixels).save(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=512)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--window", type=int, default=10)
    ap.add_argument("--image", default="930x640")
    ap.add_argument("--edits", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="2 edits")
    ap.add_argument("--png", type=Path, default=None)
    ap.add_argument("--keep", type=Path, default=None)
    ap.add_argument(
        "--paths",
        default="integrate,bricks,gl",
        help="which of integrate, bricks, gl to time (gl: the winners in GL textures too)",
    )
    args = ap.parse_args()
    edits = 2 if args.quick else args.edits
    w, h = (int(v) for v in args.image.split("x"))
    emit(env_record("recolour", {"side": args.side, "steps": args.steps, "window": args.window}))

    t = time.perf_counter()
    series = series_of(args.side, args.steps, args.keep)
    generated_s = time.perf_counter() - t
    rc = Raycaster()
    rec = GLRecolourer(rc.ctx)
    camera = Camera(30, 20, zoom=1.2)
    t0 = (args.steps - args.window) // 2
    s = Session(series, engine="opencl", mode="max", memory="12GB", display=True)
    cv = s.set_window(t0, t0 + args.window)
    fitted = tuple(cv.metadata["value_range"])
    s.set_spec(data_tf=DataTF(value_range=fitted), time_tf=TimeTF(positions="absolute"))
    slot = ViewSlot()
    upload(rc, slot, s.current())
    first = rc.draw(slot.volume, camera, (w, h))
    if args.png:
        args.png.mkdir(parents=True, exist_ok=True)
        save(first, args.png / "max_before.png")

    # The kernels wrote this window's winners (`LevelSession.kept_winners`): both gathers are
    # timed on it, from the steps where the window manager's slots hold them, as the viewer's,
    # whole (the viewer's preparation at idle gathers in pieces it may give up).
    full, shown, sel = s.at(0), s.current(), s.selection
    arrays = full.manager.hold(sel.steps)
    vr = tuple(shown.metadata["value_range"])
    window = (shown.t_index, arrays, sel.steps, series.n_steps, vr, s.spec)
    winners(*window, full.engine)  # its kernels built and loaded: the viewer warms them too
    a = time.perf_counter()
    winners(*window)  # numpy's gather (reads every step of the window)
    b = time.perf_counter()
    won = winners(*window, full.engine)  # the OpenCL engine's: each voxel reads its winner
    c = time.perf_counter()
    del arrays, window
    paths = tuple(args.paths.split(","))
    if "integrate" not in paths or not set(paths) <= {"integrate", "bricks", "gl"}:
        raise SystemExit("--paths: integrate (the reference) and any of bricks, gl")
    rv = rec.prepare(won) if "gl" in paths else None
    d = time.perf_counter()
    prepare = {
        "gather_numpy_ms": round(1e3 * (b - a), 1),
        "gather_opencl_ms": round(1e3 * (c - b), 1),
        "upload_winners_ms": round(1e3 * (d - c), 1),
    }

    shown = s.current()
    e = time.perf_counter()
    # as the viewer: the first edit writes into the RGBA8 shown, which its texture holds
    brick_recolourer = BrickRecolourer()
    bricks = brick_recolourer.prepare(won, start=shown.rgba) if "bricks" in paths else None
    prepare["summarise_bricks_ms"] = round(1e3 * (time.perf_counter() - e), 1)
    emit({"path": "recolour", "prepare": prepare})
    own = ViewSlot()  # the bricks path's texture: it writes what changed since its last edit
    if bricks is not None:
        upload(rc, own, shown)
    held = bricks.output[1] if bricks is not None else None
    rows: dict[str, list] = {p: [] for p in paths}
    rewritten: dict[int, float] = {}  # the bricks path's share of bricks recoloured per edit
    for i in range(edits):  # each edit three ways, in a rotating order (a shared machine)
        data_tf, time_tf = edit(i, fitted)
        spec = dataclasses.replace(s.asked, data_tf=data_tf, time_tf=time_tf)
        pictures = {}
        for path in paths[i % len(paths) :] + paths[: i % len(paths)]:
            a = time.perf_counter()
            if path == "integrate":  # the session integrates, the viewer's upload sends it
                cv = s.set_spec(spec)
                b = time.perf_counter()
                vol = upload(rc, slot, cv)
            elif path == "bricks":  # PoCL recolours the bricks that may be coloured
                new = _recoloured(s, spec)
                changed = brick_recolourer.apply(bricks, new, own.volume)
                b = time.perf_counter()
                vol = own.volume
                show(changed, series.spacing, held)
                held = changed.coloured
                rewritten[i] = changed.rewritten / changed.coloured.size
            else:  # the compute pass rewrites the texture: nothing uploaded
                new = _recoloured(s, spec)
                changed = rec.apply(rv, new, slot.volume)
                show(changed, series.spacing)
                vol = changed.volume
                b = time.perf_counter()
            c = time.perf_counter()
            pictures[path] = rc.draw(vol, camera, (w, h))
            d = time.perf_counter()
            work = "integrate_ms" if path == "integrate" else "recolour_ms"
            times = {work: b - a, "upload_ms": c - b, "render_ms": d - c}
            rows[path].append({"total_ms": 1e3 * (d - a), **{k: 1e3 * v for k, v in times.items()}})
        for path in paths:
            row = {"path": path, "edit": i, **{k: round(v, 1) for k, v in rows[path][-1].items()}}
            diff = np.abs(pictures[path].astype(int) - pictures["integrate"].astype(int))
            row.update(max_diff=int(diff.max()), p99_diff=float(np.percentile(diff, 99)))
            if path == "bricks":
                row["bricks_recoloured"] = round(rewritten[i], 3)
            emit(row)
            if args.png:
                save(pictures[path], args.png / f"max_edit_{i}_{path}.png")

    med = lambda rows, k: round(statistics.median(r[k] for r in rows), 1)  # noqa: E731
    summary = {f"tf_edit_{path}_ms": med(rows[path], "total_ms") for path in paths}
    summary["split_ms"] = {
        path: {k: med(rows[path], k) for k in rows[path][0] if k != "total_ms"} for path in paths
    }
    summary.update(
        prepare_once_ms=prepare,
        generated_s=round(generated_s, 1),
        bound="2-core llvmpipe: compute pass and raycast on the CPU (every path)",
        target="max-mode TF edit at 512^3 full resolution <= 500 ms (issue 32)",
    )
    emit({"summary": summary})
    if rv is not None:
        rv.release()
    if bricks is not None:
        bricks.release()
    s.close()


if __name__ == "__main__":
    main()
