"""A failure at any device call of a frame's work (integrate, gather, recolour, the sliding
kernels) reaches its caller, frees nothing the enqueued work still uses, and leaves the next
result equal to a fresh one (issue 45: a gather whose second enqueue failed freed the array its
first kernel was writing, and the viewer's process died in that kernel).

The work runs in a child process (tests/device_faults.py), so that a segfault fails this test
and not the suite. At 256^3 the gather's step indices are a memory map of their own, unmapped
when freed: the tree before the fix dies there at every run (exit code -11).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parent.parent
WORKS = {"gather", "integrate_max", "integrate_alpha", "bricks", "bricks_edited", "fixed_add"}
BRICKS = {"bricks", "bricks_edited"}
# 48^3: one step's u is 442 KB, a row of 8^3 bricks of it 74 KB: capped, every array is over
# the cap and the brick recolouring runs in a z-span a row of bricks
CAP = "96KB"


def _run(*args: str, **env: str) -> list[dict]:
    proc = subprocess.run(
        [sys.executable, "-m", "tests.device_faults", *args],
        cwd=ROOT,
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stdout}{proc.stderr[-3000:]}"
    return [json.loads(line) for line in proc.stdout.splitlines()]


def _check(rows: list[dict], names: set[str]) -> None:
    assert {r["work"] for r in rows} == names
    for r in rows:  # every kind of work makes several device calls, each failed in turn (a
        # later run may make more than the first: those too)
        assert r["calls"] >= 3 and r["failures"] >= r["calls"], r


def test_a_failure_at_any_device_call_of_the_gather_frees_nothing_in_use():
    _check(_run("256", "gather"), {"gather"})


@pytest.mark.parametrize("cap", [None, CAP], ids=["whole", "capped"])
def test_a_failure_at_any_device_call_of_a_frame_leaves_the_next_result_right(cap):
    """Each kind of work, in one buffer per array and (capped) in many, every call failed:
    capped, the brick recolouring in its six z-spans, the one after a failed call equal to
    a run that never failed."""
    rows = _run("48", **({"CHRONOCL_MAX_ALLOC": cap} if cap else {}))
    _check(rows, WORKS)
    spans = {r["work"]: r.get("spans") for r in rows if r["work"] in BRICKS}
    assert spans == dict.fromkeys(BRICKS, 6 if cap else 1), spans
