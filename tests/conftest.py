"""Shared fixtures and hypothesis settings; a cold private kernel cache for every session."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

# Tests must not depend on what earlier runs left in the user's caches: every session gets
# empty ones, set before pyopencl is imported so subprocesses (the CLI tests) inherit them.
# pyopencl's compiler cache and pytools' PersistentDict live under XDG_CACHE_HOME (through
# platformdirs; pyopencl has no variable of its own), PoCL's kernel cache in POCL_CACHE_DIR.
_CACHE = tempfile.mkdtemp(prefix="chronocl-test-cache-")
os.environ["XDG_CACHE_HOME"] = os.path.join(_CACHE, "xdg")
os.environ["POCL_CACHE_DIR"] = os.path.join(_CACHE, "pocl")
os.makedirs(os.environ["XDG_CACHE_HOME"])
os.makedirs(os.environ["POCL_CACHE_DIR"])
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)

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


def pytest_sessionfinish(session, exitstatus) -> None:
    if _BROWSER_SKIPS:
        print("\nbrowser tests skipped where CHRONOCL_REQUIRE_BROWSER=1 forbids it:")
        for line in _BROWSER_SKIPS[:20]:
            print(f"  {line}")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
