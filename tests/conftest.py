"""Shared fixtures and hypothesis settings; a cold private kernel cache for every run (its
workers share it); the run's time budget."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import time

# Tests must not depend on what earlier runs left in the user's caches: every run gets
# empty ones, set before pyopencl is imported so subprocesses (the CLI tests) inherit them.
# pyopencl's compiler cache and pytools' PersistentDict live under XDG_CACHE_HOME (through
# platformdirs; pyopencl has no variable of its own), PoCL's kernel cache in POCL_CACHE_DIR.
# The run's workers (pytest -n) inherit the first process's, so each kernel builds once a run.
if "CHRONOCL_TEST_CACHE" not in os.environ:
    os.environ["CHRONOCL_TEST_CACHE"] = tempfile.mkdtemp(prefix="chronocl-test-cache-")
    atexit.register(shutil.rmtree, os.environ["CHRONOCL_TEST_CACHE"], ignore_errors=True)
_CACHE = os.environ["CHRONOCL_TEST_CACHE"]
os.environ["XDG_CACHE_HOME"] = os.path.join(_CACHE, "xdg")
# CI's second interpreter builds on the first's PoCL kernel binaries (.ci/run names a folder
# for both in CHRONOCL_TEST_POCL_CACHE): the same driver builds the same sources alike.
os.environ["POCL_CACHE_DIR"] = os.environ.get("CHRONOCL_TEST_POCL_CACHE") or os.path.join(
    _CACHE, "pocl"
)
os.makedirs(os.environ["XDG_CACHE_HOME"], exist_ok=True)
os.makedirs(os.environ["POCL_CACHE_DIR"], exist_ok=True)

import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile(
    "default",
    deadline=None,
    max_examples=int(os.environ.get("CHRONOCL_EXAMPLES", "60")),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.load_profile("default")


@pytest.fixture
def buffer_sizes(monkeypatch) -> list[int]:
    """The bytes of every device buffer chronocl asks for meanwhile (`buffers.check`, which
    every buffer passes: chronocl/engine/buffers.py), checked as usual."""
    from chronocl.engine import buffers

    sizes: list[int] = []
    checked = buffers.check

    def check(dc, nbytes: int, what: str) -> None:
        sizes.append(nbytes)
        checked(dc, nbytes, what)

    monkeypatch.setattr(buffers, "check", check)
    return sizes


@pytest.fixture
def drawn_text(monkeypatch) -> list[str]:
    """Every string the legend and caption code hands to Pillow's drawing (drawn as usual)."""
    from PIL import ImageDraw

    texts: list[str] = []
    original = ImageDraw.ImageDraw.text

    def text(self, xy, content, *args, **kwargs):
        texts.append(content)
        return original(self, xy, content, *args, **kwargs)

    monkeypatch.setattr(ImageDraw.ImageDraw, "text", text)
    return texts


# CI sets CHRONOCL_REQUIRE_BROWSER=1: a browser test that skips (no chromium, no playwright)
# then fails the run instead of passing unseen (issue 45).
_BROWSER_SKIPS: list[str] = []


def _note_browser_skip(report) -> None:
    if os.environ.get("CHRONOCL_REQUIRE_BROWSER") == "1" and report.skipped:
        if "_browser" in report.nodeid:
            _BROWSER_SKIPS.append(f"{report.nodeid}: {report.longrepr}")


def pytest_runtest_logreport(report) -> None:
    _note_browser_skip(report)


def pytest_collectreport(report) -> None:
    _note_browser_skip(report)


# CI sets CHRONOCL_SUITE_BUDGET_S: a run (all its workers together) that takes longer fails,
# and --durations names the slowest tests (issue 46).
_STARTED = time.monotonic()


def pytest_sessionfinish(session, exitstatus) -> None:
    if _BROWSER_SKIPS:
        print("\nbrowser tests skipped where CHRONOCL_REQUIRE_BROWSER=1 forbids it:")
        for line in _BROWSER_SKIPS[:20]:
            print(f"  {line}")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    budget = os.environ.get("CHRONOCL_SUITE_BUDGET_S")
    if budget and not hasattr(session.config, "workerinput"):  # the run's, not a worker's
        took = time.monotonic() - _STARTED
        print(f"\nsuite: {took:.0f} s of its budget of {float(budget):.0f} s")
        if took > float(budget):
            print("suite: over its time budget; --durations lists the slowest tests")
            session.exitstatus = pytest.ExitCode.TESTS_FAILED
