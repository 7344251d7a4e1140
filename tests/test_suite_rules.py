"""The suite's own rules hold: deprecations from our code fail it, every property test takes
CHRONOCL_EXAMPLES, and no test reaches into another package's private names."""

from __future__ import annotations

import ast
import os
import re
import tomllib
import warnings
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from .strategies import examples

TESTS = Path(__file__).parent
PACKAGES = ("zarr", "numcodecs", "dask", "distributed", "pyopencl", "moderngl", "numpy", "np")
# The names this project imports them as (`import pyopencl as cl`): private names through those
# count too (issue 46: `cl._x` passed the rule).
ALIASES = ("cl", "cla", "da", "xr", "pd", "plt")


@pytest.mark.parametrize("category", [DeprecationWarning, PendingDeprecationWarning, FutureWarning])
@pytest.mark.parametrize("module", ["chronocl.data.level_writer", "tests.test_pyramid"])
def test_a_deprecation_attributed_to_our_code_fails_the_suite(category, module):
    """pyproject's filterwarnings turns them into errors (a library's warning about how we call
    it is attributed to our frame), so the next API change fails a test before it crashes."""
    with pytest.raises(category):
        warnings.warn_explicit("old API", category, module.replace(".", "/") + ".py", 1, module)


def test_a_librarys_own_deprecation_stays_a_warning():
    with warnings.catch_warnings(record=True) as caught:  # keeps the suite's filters
        warnings.warn_explicit("old API", DeprecationWarning, "zarr/core.py", 1, "zarr.core")
    assert [w.category for w in caught] == [DeprecationWarning]


def _settings_calls(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "settings":
            yield node


def test_every_property_test_takes_chronocl_examples(monkeypatch):
    """A property test that fixes its own max_examples does so through `examples(n)`, so
    CHRONOCL_EXAMPLES reaches it; the others take the profile conftest loads, which reads it."""
    fixed = []
    for path in sorted(TESTS.glob("test_*.py")):
        for call in _settings_calls(ast.parse(path.read_text())):
            for kw in call.keywords:
                value = kw.value
                if kw.arg == "max_examples" and not (
                    isinstance(value, ast.Call) and getattr(value.func, "id", None) == "examples"
                ):
                    fixed.append(f"{path.name}:{call.lineno}")
    assert not fixed, f"max_examples fixed without examples(): {fixed}"
    monkeypatch.delenv("CHRONOCL_EXAMPLES", raising=False)
    assert examples(14) == 14
    monkeypatch.setenv("CHRONOCL_EXAMPLES", "500")
    assert examples(14) == 500


def test_no_private_names_of_other_packages():
    """chronocl, bench and tests use other packages' public APIs (zarr's private objects
    changed under us once: zarr 3.2 turned BloscCodec.cname from an enum into a string)."""
    names = "|".join(PACKAGES + ALIASES)
    private = re.compile(
        r"\b(?:" + names + r")(?:\.[A-Za-z]\w*)*\._(?!_)\w*|"
        r"\bfrom (?:" + "|".join(PACKAGES) + r")(?:\.\w+)*\._\w+|"
        r"\bfrom (?:" + "|".join(PACKAGES) + r")(?:\.\w+)* import \(?(?:[\w ]+,\s*)*_(?!_)\w+|"
        r"\b(?:zarr|numcodecs|dask|distributed|pyopencl|moderngl)\.core\.|"
        r"\._async_array\b"
    )
    root = TESTS.parent
    found = [
        f"{path.relative_to(root)}:{n}: {line.strip()}"
        for folder in ("chronocl", "bench", "tests")
        for path in sorted((root / folder).rglob("*.py"))
        if path != Path(__file__)
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if private.search(line)
    ]
    assert not found, "\n".join(found)


def test_installed_versions_are_within_pyproject_ranges():
    """Every dependency installed is within its range in pyproject.toml; in CI's run on the
    lower bounds (CHRONOCL_LOWEST=1, .ci/lowest.py's constraints) each is at its lower bound,
    so the bounds chronocl claims are the versions it tests."""
    project = tomllib.loads((TESTS.parent / "pyproject.toml").read_text())["project"]
    lowest = os.environ.get("CHRONOCL_LOWEST") == "1"
    wrong = []
    for text in [*project["dependencies"], *project["optional-dependencies"]["dev"]]:
        req = Requirement(text)
        have = version(req.name)
        if have not in req.specifier:
            wrong.append(f"{req.name} {have} is outside {req.specifier}")
        floor = next(s.version for s in req.specifier if s.operator == ">=")
        if lowest and Requirement(f"{req.name}=={floor}").specifier.contains(have) is False:
            wrong.append(f"{req.name} {have} is not its lower bound {floor}")
    assert not wrong, wrong


def test_device_buffers_are_made_in_one_place():
    """Every OpenCL buffer of chronocl and its benches is made by chronocl.engine.buffers, which
    keeps each within the device's largest allocation and alive until its work has finished
    (issue 45: a buffer made elsewhere escaped both). Tests may make their own."""
    made = re.compile(r"\b(?:cl|pyopencl)\.Buffer\s*\(|\bBuffer\(\s*(?:ctx|dc\.context|context)")
    root = TESTS.parent
    home = root / "chronocl" / "engine" / "buffers.py"
    found = [
        f"{path.relative_to(root)}:{n}: {line.strip()}"
        for folder in ("chronocl", "bench")
        for path in sorted((root / folder).rglob("*.py"))
        if path != home
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if made.search(line)
    ]
    assert not found, "\n".join(found)
    assert made.search(home.read_text()), "the rule's pattern no longer finds the one place"


def test_environment_variables_are_read_in_one_place():
    """chronocl reads the environment only through chronocl.core.env, whose list names and
    documents every variable (issue 47: twelve were read in twelve modules)."""
    read = re.compile(r"\benviron\b|\bgetenv\b")  # os.environ, from os import environ, ...
    root = TESTS.parent
    home = root / "chronocl" / "core" / "env.py"
    found = [
        f"{path.relative_to(root)}:{n}: {line.strip()}"
        for path in sorted((root / "chronocl").rglob("*.py"))
        if path != home
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if read.search(line)
    ]
    assert not found, "\n".join(found)
    assert read.search(home.read_text()), "the rule's pattern no longer finds the one place"
    from chronocl.core import env

    named = set(
        re.findall(
            r"\b((?:CHRONOCL|POCL|PYOPENCL)_[A-Z_]+)\b",
            "".join(p.read_text() for p in (root / "chronocl").rglob("*.py") if p != home),
        )
    )
    assert named <= set(env.VARIABLES), named - set(env.VARIABLES)


def test_no_bench_script_hides_a_module():
    """A bench script puts bench/ first on sys.path (for common.py), for itself and the
    processes it spawns: one named as a module they import hides it (bench/distributed.py hid
    dask.distributed, so a LocalCluster's spawned workers failed to start after it ran)."""
    import importlib.util
    import sys

    bench = str(TESTS.parent / "bench")
    for script in sorted((TESTS.parent / "bench").glob("*.py")):
        spec = importlib.util.find_spec(script.stem)
        origin = spec and spec.origin and os.path.dirname(os.path.abspath(spec.origin))
        assert spec is None or origin == bench, f"bench/{script.name} hides {spec.origin}"
    assert bench not in sys.path  # what a test that loads a bench script must take out again
