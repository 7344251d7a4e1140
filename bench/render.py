"""Raycaster frame times: ours (all features on) against a minimal raymarcher, side by side.

Chronovolumes of the built-in vortex (alpha over 10 steps) at 128^3 and 256^3 with a
translucent (default) and an opaque data TF, rendered at 512^2 and 1024^2 by the process's
GL context (llvmpipe here, a GPU driver where present), frames raced round-robin; plus the
texture upload time. Summary keys: `ms_512_128`, `ms_512_256` (our median frame times at 512^2,
the mean of the opaque and translucent TFs), the same at 1024^2, and the baseline's figures.

    python bench/render.py --quick
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record, race

import chronocl
from chronocl.data import synthetic
from chronocl.demo import SURFACE
from chronocl.render import Camera
from chronocl.render.gl import gl_context, shader_source
from chronocl.render.views import raycaster

OPAQUE = SURFACE  # opacity 1 above the feature threshold
HERE = Path(__file__).resolve().parent


def chronovolumes(n: int) -> dict[str, chronocl.Chronovolume]:
    steps = np.stack(list(synthetic.steps("vortex", 10, (n, n, n))))
    series = chronocl.TimeSeries.from_array(steps)
    return {
        "translucent": chronocl.integrate(series, "0:10", "alpha"),
        "opaque": chronocl.integrate(series, "0:10", "alpha", data_tf=OPAQUE),
    }


class Minimal:
    """The baseline raymarcher on the same context, texture and camera."""

    def __init__(self) -> None:
        ctx = gl_context()
        self.ctx = ctx
        self.prog = ctx.program(
            vertex_shader=shader_source("raycast.vert"),
            fragment_shader=(HERE / "minimal_raymarch.frag").read_text(),
        )
        self.vao = ctx.vertex_array(self.prog, [])
        self.fbos: dict = {}

    def draw(self, volume, camera: Camera, size: tuple[int, int]) -> np.ndarray:
        fbo = self.fbos.get(size) or self.fbos.setdefault(
            size, self.ctx.simple_framebuffer(size, components=4)
        )
        fbo.use()
        fbo.clear(0, 0, 0, 1)
        view, proj = camera.matrices(volume.extent, size[0] / size[1])
        self.prog["inv_view_proj"].write(np.linalg.inv(proj @ view).T.astype("f4").tobytes())
        self.prog["box_min"].value = tuple(-volume.extent / 2)
        self.prog["box_max"].value = tuple(volume.extent / 2)
        self.prog["step_world"].value = volume.unit
        self.prog["max_steps"].value = int(np.linalg.norm(volume.extent) / volume.unit) + 2
        volume.texture.use(location=0)
        self.vao.render(vertices=3)
        return np.frombuffer(fbo.read(components=3, alignment=1), dtype=np.uint8)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats; under 2 minutes")
    parser.add_argument("--repeats", type=int, default=None)
    args = parser.parse_args()
    repeats = args.repeats or (5 if args.quick else 9)

    ctx = gl_context()
    emit(
        env_record(
            "render", {"gl_renderer": ctx.info["GL_RENDERER"], "gl_version": ctx.info["GL_VERSION"]}
        )
    )
    rc, minimal = raycaster(), Minimal()
    camera = Camera(30, 20)
    results: dict[tuple, float] = {}
    for n in (128, 256):
        cvs = chronovolumes(n)
        t0 = time.perf_counter()
        volumes = {name: rc.upload(cv) for name, cv in cvs.items()}
        ctx.finish()
        upload_ms = (time.perf_counter() - t0) / len(volumes) * 1e3
        emit(
            {
                "bench": "render",
                "case": f"{n}^3",
                "impl": "upload-rgba16f",
                "mode": "upload",
                "median_s": round(upload_ms / 1e3, 6),
                "value": round(upload_ms, 2),
                "unit": "ms",
            }
        )
        contenders = {}
        for px in (512, 1024):
            size = (px, px)
            for tf_name, volume in volumes.items():
                contenders[(n, px, "chronocl", tf_name)] = lambda v=volume, s=size: rc.draw(
                    v, camera, s, jitter=True, outline=True
                )
                contenders[(n, px, "minimal", tf_name)] = lambda v=volume, s=size: minimal.draw(
                    v, camera, s
                )
        timings = race({"/".join(map(str, k)): fn for k, fn in contenders.items()}, repeats)
        for (n_, px, impl, tf_name), (med, best) in zip(contenders, timings.values(), strict=True):
            results[(n_, px, impl, tf_name)] = med * 1e3
            emit(
                {
                    "bench": "render",
                    "case": f"{n_}^3-{px}^2-{tf_name}",
                    "impl": impl,
                    "mode": "frame",
                    "median_s": round(med, 6),
                    "min_s": round(best, 6),
                    "repeats": repeats,
                    "value": round(med * 1e3, 2),
                    "unit": "ms/frame",
                }
            )
        for volume in volumes.values():
            volume.release()

    def mean(n, px, impl):
        return round(
            (results[(n, px, impl, "translucent")] + results[(n, px, impl, "opaque")]) / 2, 1
        )

    emit(
        {
            "bench": "render",
            "summary": {
                "ms_512_128": mean(128, 512, "chronocl"),
                "ms_512_256": mean(256, 512, "chronocl"),
                "ms_1024_128": mean(128, 1024, "chronocl"),
                "ms_1024_256": mean(256, 1024, "chronocl"),
                "minimal_ms_512_128": mean(128, 512, "minimal"),
                "minimal_ms_512_256": mean(256, 512, "minimal"),
                "ratio_512_128_vs_minimal": round(
                    mean(128, 512, "chronocl") / mean(128, 512, "minimal"), 2
                ),
                "ratio_512_256_vs_minimal": round(
                    mean(256, 512, "chronocl") / mean(256, 512, "minimal"), 2
                ),
                "renderer": ctx.info["GL_RENDERER"],
            },
        }
    )


if __name__ == "__main__":
    main()
