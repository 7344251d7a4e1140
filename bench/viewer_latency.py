"""Viewer latency at 128^3, 256^3 and 512^3: from a client's edit to the frame in its hands.

For each size the built-in vortex is generated on the fly into a chronocl store with its
coarse levels (float32, 20 steps; 512^3: uint8, 12 steps, about 1.7 GB on disk) and served
by a viewer server on a thread of this process; a WebSocket client sets a 10-step window and
a 512^2 view, then times

- data-TF edits (an opacity control point moved): to the first frame (a coarse level when
  full resolution would miss the viewer's latency target) and to the full-resolution frame
  that follows once input stops;
- scrub steps (the window slid by one step, one after the other as a drag sends them): to
  the first frame, and whether the session updated incrementally.

The server's own timings come with each frame (the median split is reported). The baseline,
measured in the same run at 128^3, is the same edit done directly in-process at full
resolution (integrate + upload + draw + JPEG), without server or socket.

    python bench/viewer_latency.py --quick
    python bench/viewer_latency.py --quick --sizes 128,256
    python bench/viewer_latency.py --quick --sizes 128 --image 1024x733   # a panel's size

`--image` is the panel size the client asks for (default 512x512); the server draws it within
its pixel budget (chronocl/viewer/frames.py::render_size), as it does for the page.

Summary keys (per size): `first_frame_ms` (TF edit -> first frame), `full_res_ms` (TF edit
-> full-resolution frame), `scrub_first_frame_ms`, `scrub_incremental` ("k/n"),
`first_frame_level`, `split_ms`; `direct_tf_edit_ms` at 128^3 and the targets.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record

from chronocl.data import synthetic
from chronocl.data.series import TimeSeries
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.protocol import unpack_frame
from chronocl.viewer.server import ViewerServer

BENCH = "viewer_latency"
TARGETS = {"first_frame_ms": 200, "first_frame_ms_128": 150, "full_res_ms_256": 1500}
SPLIT = ("integrate_ms", "upload_ms", "render_ms", "encode_ms", "server_ms")


class Client:
    def __init__(self, server: ViewerServer) -> None:
        from websockets.sync.client import connect

        # Entered as a context manager: websockets 17.1 deprecates a bare connect().
        self._stack = ExitStack()
        self.ws = self._stack.enter_context(
            connect(
                f"ws://127.0.0.1:{server.port}/ws?token={server.token}",
                compression=None,
                max_size=2**26,
            )
        )
        self.rid = 0
        self.t0 = 0.0
        self.kind = ""
        json.loads(self.ws.recv())  # info

    def request(self, msg: dict) -> tuple[float, dict]:
        """Send `msg`; returns (ms until its first frame arrived, the frame header)."""
        self.rid += 1
        msg = {**msg, "id": self.rid}
        self.t0 = time.perf_counter()
        self.kind = msg["type"]
        self.ws.send(json.dumps(msg))
        return self.frame()

    def full_resolution(self) -> tuple[float, dict]:
        """Wait for the last request's full-resolution frame: (ms since it was sent, header)."""
        while True:
            ms, header = self.frame()
            if header.get("level", 0) == 0:
                return ms, header

    def frame(self) -> tuple[float, dict]:
        t0 = self.t0
        while True:
            m = self.ws.recv(timeout=120)
            if isinstance(m, bytes):
                header, _ = unpack_frame(m)
                if header["id"] == self.rid:
                    return 1e3 * (time.perf_counter() - t0), header
            else:
                d = json.loads(m)
                if d["type"] == "error":
                    raise RuntimeError(d["message"])
                if d["type"] == "dataset" and self.kind == "open":
                    continue


def summarise(op: str, totals: list[float], headers: list[dict], case: str) -> dict:
    split = {k: statistics.median(h["timings"][k] for h in headers) for k in SPLIT}
    transfer = [t - h["timings"]["server_ms"] for t, h in zip(totals, headers, strict=True)]
    split["transfer_ms"] = statistics.median(transfer)
    split = {k: round(v, 2) for k, v in split.items()}
    record = {
        "bench": BENCH,
        "case": case,
        "impl": "viewer",
        "op": op,
        "median_ms": round(statistics.median(totals), 2),
        "min_ms": round(min(totals), 2),
        "repeats": len(totals),
        "split_ms": split,
        "incremental": sum(bool(h["timings"].get("incremental")) for h in headers),
        "levels": sorted({h.get("level", 0) for h in headers}),
        "frame_bytes": int(statistics.median(h["views"][0]["bytes"] for h in headers)),
        # the image size drawn (the server draws less than asked for when over its draw budget)
        "drawn": sorted({f"{h['views'][0]['width']}x{h['views'][0]['height']}" for h in headers}),
    }
    emit(record)
    return record


def direct_baseline(series: TimeSeries, points: list, repeats: int) -> list[float]:
    """The same edit's work without the server: integrate, upload, draw, encode."""
    import chronocl
    from chronocl import modes
    from chronocl.core.tf import DataTF
    from chronocl.render import Camera
    from chronocl.render.gl import gl_context
    from chronocl.render.views import raycaster
    from chronocl.viewer.frames import encode

    times = []
    cam = Camera(azimuth=30.0, elevation=20.0, zoom=1.2)
    with gl_context():
        rc = raycaster()
        for k in range(repeats + 2):
            pts = [list(p) for p in points]
            pts[2][4] = 0.3 + 0.02 * (k % 10)
            t0 = time.perf_counter()
            cv = chronocl.integrate(
                series, "0:10", modes.names()[0], data_tf=DataTF(points=pts), time_tf="rgb"
            )  # the viewer's default view: the first registered mode
            vol = rc.upload(cv)
            pixels = rc.draw(vol, cam, (512, 512))
            encode(pixels, 88)
            vol.release()
            if k >= 2:
                times.append(1e3 * (time.perf_counter() - t0))
    return times


def make_store(root: Path, n: int) -> tuple[Path, str]:
    """The vortex at n^3 as a chronocl store with levels (512^3 and up: uint8, 12 steps)."""
    from chronocl.data.writer import write_store

    big = n >= 512
    steps, dtype = (12, np.uint8) if big else (20, np.float32)

    def generate():
        for step in synthetic.steps("vortex", steps, (n, n, n)):
            yield np.round(np.clip(step, 0, 1) * 255).astype(np.uint8) if big else step

    path = root / f"vortex-{n}.zarr"
    write_store(
        path,
        generate(),
        n_steps=steps,
        volume_shape=(n, n, n),
        dtype=dtype,
        source=f"vortex {n}^3",
        progress=True,
    )
    return path, f"{n}^3x{steps}-{np.dtype(dtype).name}-W10"


def measure(
    path: Path, case: str, edits: int, scrubs: int, image: tuple[int, int] = (512, 512)
) -> dict:
    """TF edits and scrub steps against a server on the store at `path`."""
    from chronocl.data.series import open_series
    from chronocl.viewer.view_state import DEFAULT_POINTS

    series = open_series(path)
    server = ViewerServer(datasets=[Dataset("vortex", series)], memory="12GB")
    server.start()
    try:
        client = Client(server)
        client.request({"type": "open", "dataset": 0})
        client.request(
            {
                "type": "update",
                "size": list(image),
                "window": {"t0": 0, "t1": 10, "stride": 1},
                "time_tf": {"color": "rgb", "positions": "absolute"},
            }
        )
        client.full_resolution()
        points = [list(p) for p in DEFAULT_POINTS]

        def tf_edit(k: int) -> tuple[tuple[float, dict], tuple[float, dict]]:
            pts = [list(p) for p in points]
            pts[2][4] = 0.3 + 0.02 * (k % 10)  # a drag of one control point
            first = client.request({"type": "update", "data_tf": {"points": pts}})
            full = first if first[1].get("level", 0) == 0 else client.full_resolution()
            return first, full

        for k in range(2):  # warm-up: kernels built, textures allocated, the levels measured
            tf_edit(k)
        edits_done = [tf_edit(k + 1) for k in range(edits)]
        first = summarise(
            "tf_edit_first_frame", *zip(*[e[0] for e in edits_done], strict=True), case
        )
        full = summarise(
            "tf_edit_full_resolution", *zip(*[e[1] for e in edits_done], strict=True), case
        )

        totals, headers = [], []
        t0, step = 0, 1
        n = series.n_steps
        for _ in range(scrubs):
            if not 0 <= t0 + step <= n - 10:
                step = -step
            t0 += step
            window = {"t0": t0, "t1": t0 + 10, "stride": 1}
            t, h = client.request({"type": "update", "window": window})
            totals.append(t)
            headers.append(h)
        scrub = summarise("scrub_step", totals, headers, case)
        client.ws.close()
    finally:
        server.stop()
    return {"first": first, "full": full, "scrub": scrub}


def main() -> None:
    import tempfile

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    ap.add_argument("--sizes", default="128,256,512", help="volume sides (default 128,256,512)")
    ap.add_argument("--edits", type=int, default=None, help="TF edits per size (default 10/20)")
    ap.add_argument("--keep", type=Path, default=None, help="folder to keep the stores in")
    ap.add_argument("--image", default="512x512", help="panel size WxH (default 512x512)")
    args = ap.parse_args()
    image = tuple(int(v) for v in args.image.lower().split("x"))
    if len(image) != 2:
        ap.error(f"--image {args.image!r}: give WxH, e.g. 512x512")
    label = f"{image[0]}^2" if image[0] == image[1] else f"{image[0]}x{image[1]}"
    edits = args.edits or (10 if args.quick else 20)
    scrubs = 20 if args.quick else 40
    sizes = [int(v) for v in args.sizes.split(",")]
    emit(env_record(BENCH, {"sizes": sizes, "window": 10, "image": list(image)}))

    summary: dict = {k: {} for k in ("first_frame_ms", "full_res_ms", "scrub_first_frame_ms")}
    summary |= {"scrub_incremental": {}, "first_frame_level": {}, "split_ms": {}}
    with tempfile.TemporaryDirectory(prefix="chronocl-latency-", dir=args.keep) as tmp:
        for n in sizes:
            path, case = make_store(Path(tmp), n)
            r = measure(path, f"{case}-{label}", edits, scrubs, image)
            key = str(n)
            summary["first_frame_ms"][key] = r["first"]["median_ms"]
            summary["full_res_ms"][key] = r["full"]["median_ms"]
            summary["scrub_first_frame_ms"][key] = r["scrub"]["median_ms"]
            summary["scrub_incremental"][key] = f"{r['scrub']['incremental']}/{scrubs}"
            summary["first_frame_level"][key] = r["first"]["levels"]
            summary.setdefault("drawn", {})[key] = {
                k: r[k]["drawn"] for k in ("first", "full", "scrub")
            }
            summary["split_ms"][key] = {
                "first": r["first"]["split_ms"],
                "full": r["full"]["split_ms"],
                "scrub": r["scrub"]["split_ms"],
            }
            if n == 128:
                from chronocl.data.series import open_series
                from chronocl.viewer.view_state import DEFAULT_POINTS

                points = [list(p) for p in DEFAULT_POINTS]
                direct = direct_baseline(open_series(path), points, max(5, edits // 2))
                summary["direct_tf_edit_ms_128"] = round(statistics.median(direct), 2)
            shutil.rmtree(path)
    emit({"bench": BENCH, "summary": {**summary, "targets": TARGETS}})


if __name__ == "__main__":
    main()
