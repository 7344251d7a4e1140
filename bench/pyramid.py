"""What the coarse levels cost at ingest: writing a store with and without its levels.

Writes the same series (256^3 x 8 steps of uint8 and of float32, generated on the fly with
chronocl.data.synthetic) with `write_series(levels=True)` and `levels=False`, round-robin in one
process, and times `add_levels` on a store written without them. Prints JSON lines and a
summary whose `levels_overhead` is the largest (with levels / without) - 1 over the dtypes
(target <= 0.25), with the per-dtype figures beside it.

    python bench/pyramid.py            # 256^3 x 8 steps, 5 repeats
    python bench/pyramid.py --quick    # 128^3 x 8 steps, 3 repeats
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import emit, env_record, race, volume_args

from chronocl.data import synthetic
from chronocl.data.level_writer import add_levels
from chronocl.data.series import write_series


def main() -> None:
    args, shape, repeats = volume_args(__doc__)
    n = shape[0]
    emit(env_record("pyramid", {"shape": list(shape), "steps": args.steps}))
    floats = [
        np.ascontiguousarray(s, np.float32) for s in synthetic.steps("vortex", args.steps, shape, 0)
    ]
    data = {
        "float32": floats,
        "uint8": [np.rint(np.clip(s, 0, 1) * 255).astype(np.uint8) for s in floats],
    }
    voxel_steps = n**3 * args.steps
    summary: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for dtype, steps in data.items():
            paths = {c: Path(tmp) / f"{dtype}-{c}.zarr" for c in ("plain", "levels")}

            def ingest(which: str, steps=steps, dtype=dtype, paths=paths) -> None:
                write_series(
                    paths[which],
                    iter(steps),
                    n_steps=args.steps,
                    volume_shape=shape,
                    dtype=dtype,
                    overwrite=True,
                    levels=which == "levels",
                )

            timed = race({c: (lambda c=c: ingest(c)) for c in paths}, repeats=repeats, warmup=1)
            for which, (median, least) in timed.items():
                emit(
                    {
                        "bench": "pyramid",
                        "case": f"{n}^3xT{args.steps}-{dtype}",
                        "stage": "ingest",
                        "impl": which,
                        "median_s": round(median, 4),
                        "min_s": round(least, 4),
                        "repeats": repeats,
                        "value": round(voxel_steps / median / 1e9, 3),
                        "unit": "Gvoxsteps/s",
                    }
                )
            summary[f"levels_overhead_{dtype}"] = round(
                timed["levels"][0] / timed["plain"][0] - 1, 3
            )
            added = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                add_levels(paths["plain"], force=True)
                added.append(time.perf_counter() - t0)
            add_s = float(np.median(added))
            emit(
                {
                    "bench": "pyramid",
                    "case": f"{n}^3xT{args.steps}-{dtype}",
                    "stage": "add_levels",
                    "median_s": round(add_s, 4),
                    "repeats": repeats,
                }
            )
            summary[f"add_levels_over_ingest_{dtype}"] = round(add_s / timed["plain"][0], 3)
            for p in paths.values():
                shutil.rmtree(p, ignore_errors=True)
    summary["levels_overhead"] = max(
        v for k, v in summary.items() if k.startswith("levels_overhead_")
    )
    emit({"bench": "pyramid", "summary": summary})


if __name__ == "__main__":
    main()
