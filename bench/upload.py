"""Display-texture upload: host conversion, texture write and draw time per texture format.

Chronovolumes of the built-in vortex and jet (alpha over 10 steps, made on the fly) at 128^3 and
256^3; for each format (f4 float32, f2 half float, f1 RGBA8) the host conversion with
`chronocl.render.upload.convert` (z-slab tasks on a thread pool into a reused staging buffer,
occupancy included), the in-place texture write (`ctx.finish()` counted), and a 512^2 draw of
the resulting texture (the viewer's camera; llvmpipe samples formats at different speeds), all
raced round-robin in one run so ratios are fair. "today" is the viewer's upload before this
change (float32 up to 2^23 voxels, else a single-threaded `astype(float16)`, a separate
occupied-box pass, then the write). Each format's 512^2 image is compared with float32's
(jitter off): the largest 8-bit difference and the PSNR.

    python bench/upload.py --quick

Summary keys (the mean of vortex and jet): `convert_ms`, `write_ms`, `upload_ms` (the two),
`draw_ms`, `total_ms` (upload + draw) as {size: {format: ms}}; `today_upload_ms` and
`today_total_ms` {size: ms}; `chosen` {size: format} (the lowest total, float32 when within
5 % of it: exact), `viewer_format` (what `display_format` sends) and `viewer_upload_ms` (the
viewer's `upload`, new texture data each time); `speedup_vs_today`
{size: today total / chosen total} and `upload_speedup_vs_today` (upload alone);
`max_diff_255` and `psnr_db` {size: {format: worst of the data sets}} (99 dB: identical).
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
from chronocl.render.camera import world_geometry
from chronocl.render.gl import gl_context
from chronocl.render.raycaster import occupied_box
from chronocl.render.upload import FORMATS, convert, display_format
from chronocl.render.views import raycaster
from chronocl.render.volume import Volume
from chronocl.viewer.slots import ViewSlot, upload

BENCH = "upload"
CAMERA = Camera(azimuth=30.0, elevation=20.0, zoom=1.2)  # the viewer's default view
IMAGE = (512, 512)
TODAY_FLOAT_VOXELS = 2**23  # the viewer sent float32 up to here, half floats above


def chronovolumes(n: int) -> dict[str, chronocl.Chronovolume]:
    out = {}
    for name in ("vortex", "jet"):
        series = chronocl.TimeSeries.from_array(np.stack(list(synthetic.steps(name, 10, (n,) * 3))))
        out[name] = chronocl.integrate(series, "0:10", "alpha")
    return out


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats (under 2 minutes)")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--sizes", default="128,256", help="volume sides (default 128,256)")
    args = ap.parse_args()
    repeats = args.repeats or (3 if args.quick else 7)
    sizes = [int(s) for s in args.sizes.split(",")]
    emit(env_record(BENCH, {"sizes": sizes, "steps": 10, "image": list(IMAGE), "mode": "alpha"}))

    ctx = gl_context()
    rc = raycaster()
    keys = ("convert_ms", "write_ms", "upload_ms", "draw_ms", "total_ms")
    per: dict[str, dict[int, dict[str, list[float]]]] = {k: {} for k in keys}
    today_up: dict[int, list[float]] = {}
    today_total: dict[int, list[float]] = {}
    viewer_up: dict[int, list[float]] = {}
    diffs: dict[int, dict[str, list[tuple[int, float]]]] = {}
    for n in sizes:
        t0 = time.perf_counter()
        cvs = chronovolumes(n)
        made_s = time.perf_counter() - t0
        for name, cv in cvs.items():
            extent, voxel = world_geometry(cv.shape, cv.spacing)
            staging: dict[str, np.ndarray | None] = dict.fromkeys(FORMATS)
            volumes: dict[str, Volume] = {}
            for fmt in FORMATS:
                data, occ = convert(cv.rgba, fmt)
                staging[fmt] = data
                volumes[fmt] = Volume.allocate(ctx, (n, n, n), fmt, data)
                volumes[fmt].place(cv.spacing, occ.bounds(), brick_grid.from_rgba(data))
            today_fmt = "f4" if n**3 <= TODAY_FLOAT_VOXELS else "f2"
            today_tex = volumes[today_fmt].texture
            slot = ViewSlot()

            def today(cv=cv, fmt=today_fmt, tex=today_tex, extent=extent, voxel=voxel):
                if fmt == "f4":
                    data = np.ascontiguousarray(cv.rgba, dtype=np.float32)
                else:
                    data = cv.rgba.astype(np.float16)
                tex.write(data)
                occupied_box(cv.rgba[..., 3], extent, voxel)
                ctx.finish()

            def viewer(cv=cv, slot=slot):
                slot.uploaded = None
                upload(rc, slot, cv)
                ctx.finish()

            fns = {"today": today, "viewer": viewer}
            for fmt in FORMATS:

                def conv(fmt=fmt, cv=cv, staging=staging):
                    staging[fmt], _ = convert(cv.rgba, fmt, staging[fmt])

                def write(fmt=fmt, staging=staging, volumes=volumes):
                    volumes[fmt].texture.write(staging[fmt])
                    ctx.finish()

                def draw(fmt=fmt, volumes=volumes):
                    rc.draw(volumes[fmt], CAMERA, IMAGE)

                fns.update({f"{fmt}:convert": conv, f"{fmt}:write": write, f"{fmt}:draw": draw})
            times = race(fns, repeats)
            ms = {k: round(1e3 * v[0], 2) for k, v in times.items()}
            reference = rc.draw(volumes["f4"], CAMERA, IMAGE, jitter=False)
            for fmt in FORMATS:
                c, w, d = ms[f"{fmt}:convert"], ms[f"{fmt}:write"], ms[f"{fmt}:draw"]
                image = rc.draw(volumes[fmt], CAMERA, IMAGE, jitter=False)
                gap = int(np.abs(image.astype(int) - reference.astype(int)).max())
                db = min(psnr(image, reference), 99.0)  # 99: identical (f4 itself)
                diffs.setdefault(n, {}).setdefault(fmt, []).append((gap, db))
                row = dict(zip(keys, (c, w, c + w, d, c + w + d), strict=True))
                for k, v in row.items():
                    per[k].setdefault(n, {}).setdefault(fmt, []).append(v)
                emit(
                    {
                        "bench": BENCH,
                        "case": f"{name}-{n}^3-512^2",
                        "impl": fmt,
                        **{k: round(v, 2) for k, v in row.items()},
                        "max_diff_255": gap,
                        "psnr_db": round(db, 2),
                        "repeats": repeats,
                    }
                )
            today_draw = ms[f"{today_fmt}:draw"]
            today_up.setdefault(n, []).append(ms["today"])
            today_total.setdefault(n, []).append(ms["today"] + today_draw)
            viewer_up.setdefault(n, []).append(ms["viewer"])
            emit(
                {
                    "bench": BENCH,
                    "case": f"{name}-{n}^3-512^2",
                    "impl": "today",
                    "format": today_fmt,
                    "upload_ms": ms["today"],
                    "total_ms": round(ms["today"] + today_draw, 2),
                    "viewer_upload_ms": ms["viewer"],
                    "made_s": round(made_s, 1),
                }
            )
            slot.release_gl()
            for vol in volumes.values():
                vol.release()

    def mean(d: dict) -> dict:
        return {
            str(n): {f: round(statistics.mean(v), 2) for f, v in by.items()} for n, by in d.items()
        }

    summary = {k: mean(per[k]) for k in keys}

    def pick(n: int) -> str:  # the fastest, but float32 (exact) when within 5 % of it
        totals = {f: statistics.mean(per["total_ms"][n][f]) for f in FORMATS}
        fastest = min(totals, key=totals.__getitem__)
        return "f4" if totals["f4"] <= 1.05 * totals[fastest] else fastest

    chosen = {str(n): pick(n) for n in sizes}
    best = {n: statistics.mean(per["total_ms"][n][chosen[str(n)]]) for n in sizes}
    best_up = {n: statistics.mean(per["upload_ms"][n][chosen[str(n)]]) for n in sizes}
    emit(
        {
            "bench": BENCH,
            "summary": {
                **summary,
                "today_upload_ms": {
                    str(n): round(statistics.mean(v), 2) for n, v in today_up.items()
                },
                "today_total_ms": {
                    str(n): round(statistics.mean(v), 2) for n, v in today_total.items()
                },
                "viewer_upload_ms": {
                    str(n): round(statistics.mean(v), 2) for n, v in viewer_up.items()
                },
                "chosen": chosen,
                "viewer_format": {str(n): display_format(n**3) for n in sizes},
                "speedup_vs_today": {
                    str(n): round(statistics.mean(today_total[n]) / best[n], 2) for n in sizes
                },
                "upload_speedup_vs_today": {
                    str(n): round(statistics.mean(today_up[n]) / best_up[n], 2) for n in sizes
                },
                "max_diff_255": {
                    str(n): {f: max(g for g, _ in v) for f, v in by.items()}
                    for n, by in diffs.items()
                },
                "psnr_db": {
                    str(n): {f: round(min(p for _, p in v), 2) for f, v in by.items()}
                    for n, by in diffs.items()
                },
            },
        }
    )


if __name__ == "__main__":
    main()
