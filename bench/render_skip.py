"""Empty-space skipping: samples per ray and draw time with and without it, side by side.

Sparse chronovolumes as the viewer shows them: the built-in vortex and jet (float32 steps,
integrated in max mode under the viewer's data TF) at 256^3 and 512^3, converted to RGBA8 and
uploaded by the viewer's own path (chronocl/viewer/slots.py, which builds the brick grid),
drawn at 930x640 (the panel of a 1400x900 page) from the viewer's default view and a second
one. For each: the mean volume samples per ray (over the rays that enter the occupied box, and
over all pixels), brick-grid reads per ray, the largest pixel difference between the two
pictures (0: the same), and the draw times raced round-robin; ratios are before / after.
Bound: the raycaster's per-sample texture reads (llvmpipe: the CPU cores; a GPU driver where
present), so the draw ratio follows the samples ratio less what the grid reads cost.

    python bench/render_skip.py --quick   # the vortex at 256^3 and 512^3, 2 steps: ~2 min here
    python bench/render_skip.py           # vortex and jet, 6 steps, 7 repeats
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record, race

import chronocl
from chronocl.data import synthetic
from chronocl.render import Camera, brick_grid
from chronocl.render.upload import convert
from chronocl.render.views import raycaster
from chronocl.viewer.slots import ViewSlot, upload

VIEWS = {
    "default": Camera(azimuth=30.0, elevation=20.0, zoom=1.2),  # the viewer's first view
    "low": Camera(azimuth=120.0, elevation=-35.0, zoom=1.0),
}


def chronovolume(name: str, n: int, steps: int) -> chronocl.Chronovolume:
    data = np.stack(list(synthetic.steps(name, steps, (n, n, n))))
    series = chronocl.TimeSeries.from_array(data)
    tf = chronocl.DataTF(value_range="global")  # as the viewer shows a series
    return chronocl.integrate(series, f"0:{steps}", "max", data_tf=tf)


def measure(name: str, n: int, steps: int, size: tuple[int, int], repeats: int) -> list[dict]:
    t0 = time.perf_counter()
    cv = chronovolume(name, n, steps)
    made_s = time.perf_counter() - t0
    rc = raycaster()
    slot = ViewSlot()
    vol = upload(rc, slot, cv)
    rgba8, _ = convert(cv.rgba, "f1")
    grid_ms = race({"grid": lambda: brick_grid.from_rgba(rgba8)}, repeats)["grid"][0] * 1e3
    bricks = brick_grid.from_rgba(rgba8)
    record = {
        "data": name,
        "size": n,
        "steps": steps,
        "mode": "max",
        "image": f"{size[0]}x{size[1]}",
        "brick": brick_grid.BRICK,
        "occupied_voxels": round(float((rgba8[..., 3] > 0).mean()), 4),
        "occupied_bricks": round(float((bricks > 0).mean()), 4),
        "grid_ms": round(grid_ms, 1),
        "make_s": round(made_s, 1),
    }
    rows = []
    for view, camera in VIEWS.items():
        before = rc.samples(vol, camera, size, skip=False)
        after = rc.samples(vol, camera, size, skip=True)
        hit = before[..., 0] > 0
        images = {s: rc.draw(vol, camera, size, skip=s) for s in (False, True)}
        diff = int(np.abs(images[True].astype(int) - images[False]).max())
        times = race(
            {
                "before": lambda c=camera: rc.draw(vol, c, size, skip=False),
                "after": lambda c=camera: rc.draw(vol, c, size, skip=True),
            },
            repeats,
        )
        spr_before = float(before[..., 0][hit].mean()) if hit.any() else 0.0
        spr_after = float(after[..., 0][hit].mean()) if hit.any() else 0.0
        rows.append(
            {
                **record,
                "view": view,
                "rays_hit": round(float(hit.mean()), 4),
                "samples_per_ray_before": round(spr_before, 1),
                "samples_per_ray_after": round(spr_after, 1),
                "samples_per_pixel_before": round(float(before[..., 0].mean()), 1),
                "samples_per_pixel_after": round(float(after[..., 0].mean()), 1),
                "brick_reads_per_ray": round(float(after[..., 1][hit].mean()), 1)
                if hit.any()
                else 0.0,
                "samples_ratio": round(spr_before / max(spr_after, 1e-9), 2),
                "draw_ms_before": round(times["before"][0] * 1e3, 1),
                "draw_ms_after": round(times["after"][0] * 1e3, 1),
                "draw_ratio": round(times["before"][0] / times["after"][0], 2),
                "max_pixel_diff": diff,
            }
        )
        emit(rows[-1])
    slot.release_gl()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="vortex, 2 steps, 3 repeats")
    parser.add_argument("--sizes", default="256,512", help="volume edges, comma separated")
    parser.add_argument(
        "--data", default=None, help="built-in data sets (vortex,jet; quick: vortex)"
    )
    parser.add_argument("--steps", type=int, default=None, help="steps integrated (max mode)")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--image", default="930x640", help="W x H of the drawn panel")
    args = parser.parse_args()
    steps = args.steps or (2 if args.quick else 6)
    repeats = args.repeats or (3 if args.quick else 7)
    size = tuple(int(v) for v in args.image.lower().split("x"))
    emit(env_record("render_skip", {"gl": raycaster().ctx.info["GL_RENDERER"]}))
    rows = []
    for n in (int(v) for v in args.sizes.split(",")):
        for name in (args.data or ("vortex" if args.quick else "vortex,jet")).split(","):
            rows += measure(name, n, steps, size, repeats)
    by_size: dict[str, list[dict]] = {}
    for row in rows:
        by_size.setdefault(str(row["size"]), []).append(row)
    summary = {
        "bound": "per-sample texture reads of the raycaster (llvmpipe: CPU cores; else the GPU)",
        "gl": raycaster().ctx.info["GL_RENDERER"],
        "image": args.image,
        "brick": brick_grid.BRICK,
        **{
            key: {n: round(statistics.median(r[field] for r in rs), 2) for n, rs in by_size.items()}
            for key, field in (
                ("samples_per_ray_before", "samples_per_ray_before"),
                ("samples_per_ray_after", "samples_per_ray_after"),
                ("samples_ratio", "samples_ratio"),
                ("draw_ratio", "draw_ratio"),
                ("grid_ms", "grid_ms"),
            )
        },
        "max_pixel_diff": max((r["max_pixel_diff"] for r in rows), default=0),
    }
    emit({"bench": "render_skip", "summary": summary})


if __name__ == "__main__":
    main()
