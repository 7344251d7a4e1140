"""The users' case soak (issue 45): one client making hundreds of random actions against
`chronocl view` on the vortex at 512^3 float32 x 20 steps with the default memory budget.

The server is the CLI in a child process (`chronocl view STORE --no-browser`, no --memory:
half the memory free), its stderr kept; the client is bench/latency_client.py's. Each
action is drawn at random (seeded) from: a mode change (any of the 8 modes), a data-TF edit, a
time-TF edit, a one-step slide, a jump of the window, a second view added or taken away, a drag
(slides at preview quality, coarse levels, then let go) and a reconnect (a new socket, the page
opened again); after each the client waits for its sharp frame (level 0, full quality, the
panel's full size). Only loopback traffic; every wait is bounded.

Measured: internal errors (error replies and the server's log lines that say "internal
error"), crashes (the server gone: its exit code), the server's peak RSS (the kernel's VmHWM)
against the budget, and per kind of action the p50, p95 and max ms to the sharp frame.

    python bench/users_soak.py [--actions 500] [--side 512] [--seed 1] [--keep DIR] [--memory 8GB]

Summary keys: `actions`, `internal_errors` (target 0), `crashes` (target 0), `peak_rss_mb`,
`budget_mb`, `peak_rss_over_budget` (target <= 1.1), `sharp_ms` per kind (p50, p95, max),
`peak_rise_mb` per kind (how far the peak rose during actions of that kind, in all: which
actions set the peak) and `peak_after` (the action that set it, and its number).
"""

from __future__ import annotations

import argparse
import json
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record, percentiles
from latency_client import WINDOW, Client, Edits, sharp
from viewer_latency import make_store

from chronocl import modes
from chronocl.core.budget import interactive_memory, parse_memory

BENCH = "users_soak"
STEPS = 20
PANEL = (930, 640)
KINDS = ("mode", "data_tf", "time_tf", "slide", "jump", "views", "drag", "reconnect")
TIME_COLORS = ("rgb", "warm-cool", "lightness", "luminance")
WAIT_S = 300.0  # the longest any one action may take before the soak says so and stops


def vm_hwm_mb(pid: int, key: str = "VmHWM") -> float:
    """The peak resident memory of process `pid` so far, in MB (Linux's VmHWM; `key` VmRSS:
    the resident memory now)."""
    text = Path(f"/proc/{pid}/status").read_text()
    return int(re.search(key + r":\s+(\d+) kB", text).group(1)) / 1024


class Server:
    """`chronocl view STORE --no-browser` in a child process, its stderr in a file."""

    def __init__(self, store: Path, log: Path, memory: str | None = None) -> None:
        self.log = log
        self._err = open(log, "w")  # closed in stop()
        cmd = [sys.executable, "-m", "chronocl", "view", str(store), "--no-browser"]
        cmd += ["--memory", memory] if memory else []
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self._err, text=True)
        line = self.proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)/\?token=([\w-]+)", line)
        if not m:
            self.stop()
            raise RuntimeError(f"'chronocl view' printed {line!r}: {log.read_text()[-2000:]}")
        self.address = SimpleNamespace(port=int(m.group(1)), token=m.group(2))

    def internal_errors(self) -> list[str]:
        return [
            ln for ln in self.log.read_text(errors="replace").splitlines() if "internal error" in ln
        ]

    def stop(self) -> int | None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(60)
        self._err.close()
        return self.proc.returncode


class Soak:
    """One client's random actions; the ms to each one's sharp frame, by kind."""

    def __init__(self, server: Server, rng: random.Random) -> None:
        self.server, self.rng = server, rng
        self.times: dict[str, list[float]] = {k: [] for k in KINDS}
        self.errors: list[str] = []
        self.connect()

    def connect(self) -> None:
        self.c = Client(self.server.address)
        self.c.open(PANEL)
        state = self.c.dataset["state"]
        self.n = STEPS
        self.views = [{"mode": v["mode"], "order": v["order"]} for v in state["views"]]
        self.edit = Edits(state["data_tf"])

    def message(self, kind: str) -> list[dict]:
        """The messages of one action of `kind` (a drag's are several)."""
        c, rng = self.c, self.rng
        if kind == "mode":
            i = rng.randrange(len(self.views))
            self.views[i] = {"mode": rng.choice(modes.names()), "order": "forward"}
            return [{"type": "update", "views": self.views}]
        if kind == "data_tf":
            return [self.edit()]
        if kind == "time_tf":
            tf = {"color": rng.choice(TIME_COLORS), "focus": round(rng.random(), 3)}
            return [{"type": "update", "time_tf": tf}]
        if kind == "slide":
            return [c.slide(self.n, "full")]
        if kind == "jump":
            c.t0 = rng.randrange(0, self.n - WINDOW + 1)
            return [{"type": "update", "window": {"t0": c.t0, "t1": c.t0 + WINDOW}}]
        if kind == "views":
            if len(self.views) == 1:
                self.views.append({"mode": rng.choice(modes.names()), "order": "forward"})
            else:
                self.views.pop()
            return [{"type": "update", "views": self.views}]
        if kind == "drag":  # coarse frames while dragging, the sharp one when let go
            slides = [c.slide(self.n) for _ in range(rng.randint(2, 5))]
            return [*slides, c.slide(self.n, "full")]
        raise ValueError(kind)

    def act(self, kind: str) -> None:
        t = time.perf_counter()
        if kind == "reconnect":
            self.c._stack.close()
            self.connect()
            self.times[kind].append(1e3 * (time.perf_counter() - t))
            return
        msgs = self.message(kind)
        for msg in msgs[:-1]:
            self.c.request(msg)  # a drag's slides: their first frames
        rid = self.c.send(msgs[-1])
        try:
            while True:
                _, kind_got, h = self.c.next(timeout=WAIT_S)
                if kind_got == "frame" and h["id"] == rid and sharp(h):
                    break
        except RuntimeError as exc:  # an error reply
            self.errors.append(f"{kind}: {exc}")
            return
        self.times[kind].append(1e3 * (time.perf_counter() - self.c.sent[rid]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--actions", type=int, default=500, help="random actions (500)")
    ap.add_argument("--side", type=int, default=512, help="the volume's side (512; 128: a dry run)")
    ap.add_argument("--seed", type=int, default=1, help="the actions' random seed")
    ap.add_argument("--keep", type=Path, default=None, help="keep the store in this folder")
    ap.add_argument(
        "--memory",
        default=None,
        help="the server's --memory (default: none, the viewer's default limit)",
    )
    ap.add_argument(
        "--trace",
        type=Path,
        default=None,
        help="a JSON line per action here (its kind, the views, resident and peak MB after it), "
        "and the server's log beside it (NAME.server.log)",
    )
    args = ap.parse_args()
    # A soak stopped (SIGTERM) stops its server too: the `finally` below runs
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        store, case = make_store(root, args.side, STEPS, "float32")
        # what the child computes, a moment later
        budget = interactive_memory() if args.memory is None else parse_memory(args.memory)
        trace = None if args.trace is None else open(args.trace, "w")  # before the server
        server = Server(store, Path(tmp) / "server.log", args.memory)
        soak, crashed, t0 = None, None, time.perf_counter()
        rises: dict[str, float] = dict.fromkeys(KINDS, 0.0)
        peak_after = None
        try:
            soak = Soak(server, random.Random(args.seed))
            for k in range(args.actions):
                kind = soak.rng.choice(KINDS)
                before = vm_hwm_mb(server.proc.pid)
                soak.act(kind)
                if server.proc.poll() is not None:
                    crashed = f"after action {k} ({kind}): exit {server.proc.returncode}"
                    break
                rise = vm_hwm_mb(server.proc.pid) - before
                if trace is not None:
                    line = {"k": k, "kind": kind, "views": [v["mode"] for v in soak.views]}
                    line["rss_mb"] = round(vm_hwm_mb(server.proc.pid, "VmRSS"))
                    line["peak_mb"] = round(before + rise)
                    trace.write(json.dumps(line) + "\n")
                    trace.flush()
                rises[kind] += rise
                if rise > 0:
                    peak_after = f"{kind} (action {k})"
                if k % 25 == 0:
                    print(
                        f"{k}/{args.actions} actions, {time.perf_counter() - t0:.0f} s",
                        file=sys.stderr,
                    )
        except Exception as exc:  # the server gone mid-action, or a wait past WAIT_S
            crashed = f"{type(exc).__name__}: {exc}; server exit {server.proc.poll()}"
        finally:
            peak = vm_hwm_mb(server.proc.pid) if server.proc.poll() is None else None
            logged = server.internal_errors()
            code = server.stop()
            if trace is not None:
                trace.close()
                shutil.copyfile(server.log, args.trace.with_name(args.trace.name + ".server.log"))
        errors = (soak.errors if soak else []) + logged
        record = {
            "bench": BENCH,
            "case": case,
            "actions": sum(len(v) for v in soak.times.values()) if soak else 0,
            "internal_errors": sum("internal error" in e for e in errors),
            "errors": errors[:20],
            "crashes": int(crashed is not None or (code not in (0, -15, None))),
            "crash": crashed,
            "peak_rss_mb": peak and round(peak),
            "budget_mb": round(budget / 2**20),
            "peak_rss_over_budget": peak and round(peak * 2**20 / budget, 3),
            "sharp_ms": {k: percentiles(v) for k, v in (soak.times.items() if soak else [])},
            "peak_rise_mb": {k: round(v) for k, v in rises.items()},
            "peak_after": peak_after,
            "seconds": round(time.perf_counter() - t0),
        }
        emit(env_record(BENCH))
        emit(record)


if __name__ == "__main__":
    main()
