"""Viewer soak: 20 clients scrubbing and editing at once for 60 s; errors, latency and memory.

A viewer server runs in a child process (this script with --serve-child) on 127.0.0.1,
serving two built-in synthetic series made on the fly (vortex and jet, 64^3, 24 steps). This
process runs 20 WebSocket clients on threads; each opens a data set at 128^2 and, until the
time is up, in turn slides its 8-step window by one step (scrub), moves a data-TF control
point, changes the time TF and orbits the camera, waiting for the frame of each request;
every 25th request it switches data set (all its views and textures are released and made
anew). It stops by itself: after --seconds (60; 15 with --quick) no new request is sent, and
every wait is bounded. Only loopback traffic.

Measured: frame latency (request sent to its frame received), error replies and failures
(plus tracebacks on the server's stderr, which count as errors), and the server process's RSS,
sampled every 0.5 s. The soak proper starts after a warm-up (every client has its first frame,
then 10 s, 5 with --quick, of the same traffic: kernels built, textures allocated, sliding
state filled). The working set swings by hundreds of MB within seconds, as 20 sessions drop
and rebuild their sliding state, so growth is read from the trend: `rss_start_mb` and
`rss_end_mb` are the least-squares line through every sample of the soak at its start and
end, `rss_growth_mb` their difference (a leak is a slope; the swings average out). The
medians of the first and last 10 s (5 with --quick), the least and the most RSS are reported
beside them. `rss_after_close_mb` once every client has gone; `heap_cleanups` counts the
server's garbage collections + malloc_trim (`HeapKeeper`).

    python bench/viewer_soak.py --quick

Summary keys: `errors` (target 0), `p50_ms`, `p95_ms`, `rss_start_mb`, `rss_end_mb`,
`rss_growth_mb` (target <= 50), `clients` (20), `seconds` (>= 60 without --quick).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record

BENCH = "viewer_soak"
CLIENTS = 20
SIDE, STEPS, WIDTH, IMAGE = 64, 24, 8, 128
SWITCH_EVERY = 25
RECV_TIMEOUT_S = 120.0


# --------------------------------------------------------------------------- the server


def serve_child(side: int, steps: int) -> None:
    """The server process: synthetic data, a viewer on 127.0.0.1; stops when stdin closes."""
    import numpy as np

    from chronocl.data import synthetic
    from chronocl.data.series import TimeSeries
    from chronocl.viewer.datasets import Dataset
    from chronocl.viewer.server import ViewerServer

    datasets = []
    for name in ("vortex", "jet"):
        data = np.stack(list(synthetic.steps(name, steps, (side, side, side))))
        datasets.append(Dataset(name, TimeSeries.from_array(data, source=name)))
    server = ViewerServer(datasets=datasets, max_clients=CLIENTS + 4)
    server.start()
    print(json.dumps({"port": server.port, "token": server.token}), flush=True)
    sys.stdin.read()  # until the parent closes it (or dies)
    server.stop()
    heap = server.app.heap
    stats = {"cleanups": heap.cleanups, "collect_s": heap.collect_s, "trim_s": heap.trim_s}
    print(json.dumps(stats), flush=True)


# --------------------------------------------------------------------------- a client


class Client:
    """One scrubbing and editing client; its latencies and errors go to `stats`."""

    def __init__(self, port: int, token: str, index: int) -> None:
        from websockets.sync.client import connect

        # Entered as a context manager: websockets 17.1 deprecates a bare connect().
        self._stack = ExitStack()
        self.ws = self._stack.enter_context(
            connect(
                f"ws://127.0.0.1:{port}/ws?token={token}",
                compression=None,
                max_size=2**26,
                open_timeout=RECV_TIMEOUT_S,
            )
        )
        self.index = index
        self.rid = 0
        self.latencies: list[float] = []
        self.errors: list[str] = []
        self.dataset = index % 2
        self.first_frame = threading.Event()
        json.loads(self.ws.recv(timeout=RECV_TIMEOUT_S))  # info

    def request(self, msg: dict, wait_for: str = "frame") -> float:
        """Send `msg`; wait for its frame (or reply of type `wait_for`); the ms it took."""
        from chronocl.viewer.protocol import unpack_frame

        self.rid += 1
        t0 = time.perf_counter()
        self.ws.send(json.dumps({**msg, "id": self.rid}))
        deadline = time.monotonic() + RECV_TIMEOUT_S
        while True:
            m = self.ws.recv(timeout=max(0.1, deadline - time.monotonic()))
            if isinstance(m, bytes):
                header, _ = unpack_frame(m)
                if wait_for == "frame" and (header["id"] or 0) >= self.rid:
                    return 1e3 * (time.perf_counter() - t0)
                continue
            d = json.loads(m)
            if d["type"] == "error":
                self.errors.append(d["message"])
                if d.get("id") == self.rid:
                    return 1e3 * (time.perf_counter() - t0)
            elif d["type"] == wait_for and d.get("id") == self.rid:
                return 1e3 * (time.perf_counter() - t0)

    def open(self, dataset: int) -> None:
        self.dataset = dataset
        self.request({"type": "open", "dataset": dataset}, wait_for="dataset")
        self.t0, self.step = (self.index * 3) % (STEPS - WIDTH), 1
        self.request(
            {
                "type": "update",
                "size": [IMAGE, IMAGE],
                "window": {"t0": self.t0, "t1": self.t0 + WIDTH, "stride": 1},
                "time_tf": {"positions": "absolute"},
            }
        )

    def action(self, k: int) -> dict:
        """The k-th edit: scrub, data-TF point, time TF, camera, in turn."""
        kind = k % 4
        if kind == 0:
            if not 0 <= self.t0 + self.step <= STEPS - WIDTH:
                self.step = -self.step
            self.t0 += self.step
            return {"type": "update", "window": {"t0": self.t0, "t1": self.t0 + WIDTH}}
        if kind == 1:
            a = 0.2 + 0.05 * ((k + self.index) % 10)
            points = [
                [0.0, 1, 1, 1, 0.0],
                [0.3, 1, 0.8, 0.5, 0.0],
                [0.7, 1, 1, 1, a],
                [1.0, 1, 1, 1, 0.9],
            ]
            return {"type": "update", "data_tf": {"points": points}}
        if kind == 2:
            colors = ("rgb", "warm-cool", "luminance", "white")
            return {"type": "update", "time_tf": {"color": colors[(k // 4) % 4]}}
        return {
            "type": "update",
            "camera": {"azimuth": (7.0 * k + 13 * self.index) % 360, "elevation": (k % 40) - 20.0},
        }

    def run(self, stop: threading.Event) -> None:
        try:
            self.open(self.dataset)
            self.first_frame.set()
            k = 0
            while not stop.is_set():
                k += 1
                if k % SWITCH_EVERY == 0:
                    self.open(1 - self.dataset)
                    continue
                self.latencies.append(self.request(self.action(k)))
        except Exception as exc:  # counted as an error; the others go on
            self.errors.append(f"client {self.index} failed: {exc!r}")
        finally:
            self.first_frame.set()
            try:
                self._stack.close()
            except Exception as exc:
                self.errors.append(f"client {self.index} close failed: {exc!r}")


# --------------------------------------------------------------------------- the run


def rss_mb(pid: int) -> float:
    import psutil

    return psutil.Process(pid).memory_info().rss / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="15 s instead of 60 (still 20 clients)")
    ap.add_argument("--seconds", type=float, default=None, help="soak time (default 60; 15)")
    ap.add_argument("--serve-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.serve_child:
        serve_child(SIDE, STEPS)
        return
    seconds = args.seconds or (15.0 if args.quick else 60.0)
    warmup = 5.0 if args.quick else 10.0
    window = min(warmup, seconds / 3)
    if not 0 < seconds <= 3600:
        ap.error("--seconds must lie in (0, 3600]")

    emit(
        env_record(
            BENCH,
            {
                "clients": CLIENTS,
                "seconds": seconds,
                "warmup_s": warmup,
                "data": f"vortex+jet {SIDE}^3 x{STEPS}",
                "window": WIDTH,
                "image": [IMAGE, IMAGE],
            },
        )
    )
    err_log = tempfile.NamedTemporaryFile("w+", suffix=".log", prefix="viewer-soak-")
    child = subprocess.Popen(
        [sys.executable, __file__, "--serve-child"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=err_log,
        text=True,
    )
    try:
        addr = json.loads(child.stdout.readline() or "{}")
        if "port" not in addr:
            raise SystemExit(f"the server did not start: {Path(err_log.name).read_text()}")
        clients = [Client(addr["port"], addr["token"], i) for i in range(CLIENTS)]
        stop = threading.Event()
        threads = [threading.Thread(target=c.run, args=(stop,), daemon=True) for c in clients]
        t_start = time.monotonic()
        for t in threads:
            t.start()
        for c in clients:
            c.first_frame.wait(RECV_TIMEOUT_S)
        emit(
            {
                "bench": BENCH,
                "event": "first_frames",
                "after_s": round(time.monotonic() - t_start, 1),
                "rss_mb": round(rss_mb(child.pid), 1),
            }
        )
        time.sleep(warmup)
        t_warm = time.monotonic()
        emit({"bench": BENCH, "event": "warm", "rss_mb": round(rss_mb(child.pid), 1)})
        samples: list[tuple[float, float]] = []
        next_report, seen = t_warm + 5.0, 0
        while time.monotonic() - t_warm < seconds:
            time.sleep(0.5)
            samples.append((time.monotonic() - t_warm, rss_mb(child.pid)))
            if time.monotonic() >= next_report:
                next_report += 5.0
                lat = [x for c in clients for x in c.latencies]
                recent = lat[seen:] if seen < len(lat) else lat
                emit(
                    {
                        "bench": BENCH,
                        "event": "progress",
                        "t_s": round(time.monotonic() - t_warm, 1),
                        "frames": len(lat),
                        "p50_ms": round(statistics.median(recent), 1) if recent else None,
                        "rss_mb": round(samples[-1][1], 1),
                        "errors": sum(len(c.errors) for c in clients),
                    }
                )
                seen = len(lat)
        soaked = time.monotonic() - t_warm
        first = statistics.median(r for t, r in samples if t <= window)
        last = statistics.median(r for t, r in samples if t >= soaked - window)
        slope, intercept = statistics.linear_regression(*zip(*samples, strict=True))
        rss_start, rss_end = intercept, intercept + slope * soaked
        stop.set()
        for t in threads:
            t.join(RECV_TIMEOUT_S)
        stuck = sum(t.is_alive() for t in threads)
        time.sleep(1.0)  # the server releases the closed clients' views
        rss_closed = rss_mb(child.pid)
    finally:
        if child.stdin:
            child.stdin.close()
        try:
            heap = json.loads(child.stdout.readline() or "{}")
            child.wait(30)
        except (subprocess.TimeoutExpired, ValueError):
            heap = {}
            child.kill()
            child.wait(30)
    err_log.seek(0)
    server_err = err_log.read()
    tracebacks = server_err.count("Traceback")

    lat = sorted(x for c in clients for x in c.latencies)
    errors = [e for c in clients for e in c.errors]
    for e in errors[:10]:
        emit({"bench": BENCH, "event": "error", "message": e})
    per_client = [len(c.latencies) for c in clients]
    p95 = lat[min(len(lat) - 1, int(0.95 * len(lat)))] if lat else None
    emit(
        {
            "bench": BENCH,
            "case": f"{CLIENTS} clients, {SIDE}^3 x{STEPS}, window {WIDTH}, {IMAGE}^2",
            "impl": "viewer",
            "frames": len(lat),
            "frames_per_client_min": min(per_client),
            "frames_per_s": round(len(lat) / soaked, 1),
            "median_ms": round(statistics.median(lat), 1) if lat else None,
            "min_ms": round(lat[0], 1) if lat else None,
            "max_ms": round(lat[-1], 1) if lat else None,
            "rss_first_window_median_mb": round(first, 1),
            "rss_last_window_median_mb": round(last, 1),
            "rss_slope_mb_per_min": round(60 * slope, 1),
            "rss_min_mb": round(min(r for _, r in samples), 1),
            "rss_max_mb": round(max(r for _, r in samples), 1),
            "heap_cleanups": heap.get("cleanups"),
            "heap_collect_ms": round(1e3 * heap.get("collect_s", 0.0)),
            "heap_trim_ms": round(1e3 * heap.get("trim_s", 0.0)),
            "server_tracebacks": tracebacks,
            "stuck_clients": stuck,
        }
    )
    emit(
        {
            "bench": BENCH,
            "summary": {
                "errors": len(errors) + tracebacks + stuck,
                "p50_ms": round(statistics.median(lat), 1) if lat else None,
                "p95_ms": round(p95, 1) if p95 is not None else None,
                "rss_start_mb": round(rss_start, 1),
                "rss_end_mb": round(rss_end, 1),
                "rss_growth_mb": round(rss_end - rss_start, 1),
                "rss_after_close_mb": round(rss_closed, 1),
                "clients": CLIENTS,
                "seconds": round(soaked, 1),
                "warmup_s": warmup,
                "frames": len(lat),
                "target_errors": 0,
                "target_rss_growth_mb": 50,
            },
        }
    )


if __name__ == "__main__":
    main()
