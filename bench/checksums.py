"""What the crc32c chunk checksums cost: ingest and integration with and without them.

Writes the same series (256^3 float32 steps, generated on the fly) with each compressor, with
and without the checksum, then times, round-robin in one process: writing the store (ingest)
and integrating a window from it (alpha, OpenCL). Prints JSON lines and a summary with the
ratios `ingest_checksum_over_plain` and `integrate_checksum_over_plain` per compressor.

    python bench/checksums.py            # 256^3 x 8 steps, 5 repeats
    python bench/checksums.py --quick    # 128^3 x 8 steps, 3 repeats
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import emit, env_record, race, volume_args

import chronocl
from chronocl.data import synthetic
from chronocl.data.series import write_series
from chronocl.engine import get_engine


def main() -> None:
    args, shape, repeats = volume_args(__doc__)
    n = shape[0]
    emit(env_record("checksums", {"shape": list(shape), "steps": args.steps}))
    steps = [
        np.ascontiguousarray(s, np.float32) for s in synthetic.steps("vortex", args.steps, shape, 0)
    ]
    voxel_steps = n**3 * args.steps
    summary = {}
    with tempfile.TemporaryDirectory() as tmp:
        for compressor in ("zstd", "blosc-lz4", "none"):
            paths = {c: Path(tmp) / f"{compressor}-{c}.zarr" for c in ("plain", "checksum")}

            def ingest(which: str, compressor=compressor, paths=paths) -> None:
                write_series(
                    paths[which],
                    iter(steps),
                    n_steps=args.steps,
                    volume_shape=shape,
                    dtype="float32",
                    overwrite=True,
                    compressor=compressor,
                    checksum=which == "checksum",
                )

            timed = race({c: (lambda c=c: ingest(c)) for c in paths}, repeats=repeats, warmup=1)
            series = {c: chronocl.open(p) for c, p in paths.items()}
            engine = get_engine("opencl")
            integrated = race(
                {
                    c: (lambda s=s, e=engine: chronocl.integrate(s, None, "alpha", engine=e))
                    for c, s in series.items()
                },
                repeats=repeats,
                warmup=1,
            )
            for stage, result in (("ingest", timed), ("integrate", integrated)):
                for which, (median, least) in result.items():
                    emit(
                        {
                            "bench": "checksums",
                            "case": f"{n}^3xT{args.steps}-f32",
                            "stage": stage,
                            "compressor": compressor,
                            "impl": which,
                            "median_s": round(median, 4),
                            "min_s": round(least, 4),
                            "repeats": repeats,
                            "value": round(voxel_steps / median / 1e9, 3),
                            "unit": "Gvoxsteps/s",
                        }
                    )
                ratio = result["checksum"][0] / result["plain"][0]
                summary[f"{stage}_checksum_over_plain_{compressor}"] = round(ratio, 3)
            for p in paths.values():
                shutil.rmtree(p, ignore_errors=True)
    emit({"bench": "checksums", "summary": summary})


if __name__ == "__main__":
    main()
