"""Viewer latency: from a client's edit to the new frame in its hands, over a real socket.

A viewer server runs on a thread of this process, serving the built-in vortex at 128^3
(20 steps, made on the fly); a WebSocket client sets a 10-step window and a 512^2 view, then
times (a) data-TF edits (an opacity control point moved: re-integrate + upload + render +
encode + transfer) and (b) scrub steps (the window slid by one step: `Session.slide`). The
server's own timings come with each frame, so the median split is reported too; "transfer"
is what remains of the round trip (socket, framing, queueing). The baseline, measured in the
same run, is the same work called directly in-process (integrate + upload + draw + JPEG),
without server or socket.

    python bench/viewer_latency.py --quick

Summary keys: `tf_edit_to_frame_ms`, `scrub_step_to_frame_ms` (medians), their splits,
`direct_tf_edit_ms` (the baseline) and `tf_edit_vs_direct` (ratio).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
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
SPLIT = ("integrate_ms", "upload_ms", "render_ms", "encode_ms", "server_ms")


class Client:
    def __init__(self, server: ViewerServer) -> None:
        from websockets.sync.client import connect

        self.ws = connect(
            f"ws://127.0.0.1:{server.port}/ws?token={server.token}",
            compression=None,
            max_size=2**26,
        )
        self.rid = 0
        json.loads(self.ws.recv())  # info

    def request(self, msg: dict) -> tuple[float, dict]:
        """Send `msg`; returns (ms until its frame arrived, the frame header)."""
        self.rid += 1
        msg = {**msg, "id": self.rid}
        t0 = time.perf_counter()
        self.ws.send(json.dumps(msg))
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
                if d["type"] == "dataset" and msg["type"] == "open":
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
        "frame_bytes": int(statistics.median(h["views"][0]["bytes"] for h in headers)),
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats (under 2 minutes)")
    ap.add_argument("--size", type=int, default=128, help="volume side (default 128)")
    ap.add_argument("--edits", type=int, default=None, help="TF edits to time (default 40/20)")
    args = ap.parse_args()
    edits = args.edits or (20 if args.quick else 40)
    scrubs = 20 if args.quick else 40
    n = args.size
    case = f"{n}^3xW10-512^2"

    data = np.stack(list(synthetic.steps("vortex", 20, (n, n, n))))
    series = TimeSeries.from_array(data, source="vortex")
    emit(env_record(BENCH, {"case": case, "steps": 20, "window": 10, "image": [512, 512]}))

    server = ViewerServer(datasets=[Dataset("vortex", series)])
    server.start()
    try:
        client = Client(server)
        client.request({"type": "open", "dataset": 0})
        client.request(
            {
                "type": "update",
                "size": [512, 512],
                "window": {"t0": 0, "t1": 10, "stride": 1},
                "time_tf": {"color": "rgb", "positions": "absolute"},
            }
        )
        from chronocl.viewer.view_state import DEFAULT_POINTS

        points = [list(p) for p in DEFAULT_POINTS]

        def tf_edit(k: int, quality: str = "full"):
            pts = [list(p) for p in points]
            pts[2][4] = 0.3 + 0.02 * (k % 10)  # a drag of one control point
            return client.request(
                {"type": "update", "data_tf": {"points": pts}, "quality": quality}
            )

        for k in range(3):  # warm-up: kernels built, textures allocated
            tf_edit(k)
        totals, headers = [], []
        for k in range(edits):
            t, h = tf_edit(k + 1)
            totals.append(t)
            headers.append(h)
        tf = summarise("tf_edit", totals, headers, case)

        totals, headers = [], []
        for k in range(edits // 2):
            t, h = tf_edit(k + 1, "preview")
            totals.append(t)
            headers.append(h)
        preview = summarise("tf_drag_preview", totals, headers, case)

        totals, headers = [], []
        t0, step = 0, 1
        for _ in range(scrubs):
            if not 0 <= t0 + step <= 10:
                step = -step
            t0 += step
            window = {"t0": t0, "t1": t0 + 10, "stride": 1}
            t, h = client.request({"type": "update", "window": window, "quality": "full"})
            totals.append(t)
            headers.append(h)
        scrub = summarise("scrub_step", totals, headers, case)
        client.ws.close()
    finally:
        server.stop()

    direct = direct_baseline(series, points, max(5, edits // 4))
    direct_ms = statistics.median(direct)
    emit(
        {
            "bench": BENCH,
            "case": case,
            "impl": "direct",
            "op": "tf_edit",
            "median_ms": round(direct_ms, 2),
            "min_ms": round(min(direct), 2),
            "repeats": len(direct),
        }
    )
    emit(
        {
            "bench": BENCH,
            "summary": {
                "tf_edit_to_frame_ms": tf["median_ms"],
                "tf_edit_split_ms": tf["split_ms"],
                "scrub_step_to_frame_ms": scrub["median_ms"],
                "scrub_step_split_ms": scrub["split_ms"],
                "scrub_incremental_frames": f"{scrub['incremental']}/{scrub['repeats']}",
                "tf_drag_preview_to_frame_ms": preview["median_ms"],
                "direct_tf_edit_ms": round(direct_ms, 2),
                "tf_edit_vs_direct": round(tf["median_ms"] / direct_ms, 2),
                "target_tf_edit_ms": 150,
            },
        }
    )


if __name__ == "__main__":
    main()
