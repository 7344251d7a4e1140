"""The package reads top-down: no import cycles (runtime or type-only), no upward imports, no
private names borrowed or reached into from another module (the rules: tests/layer_rules.py).

Layers, lowest first (docs/architecture.md): core <- modes <- data <- engine <- integration
<- events <- render <- viewer <- notebook <- report <- the command line (cli, demo, the
package's face).
Each rule runs on chronocl and on a known-bad fixture package, which it must reject at the
named lines (a broken parser would otherwise pass everything).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from .js_layer_rules import Scripts, js_import_cycles, shared_state_imports
from .layer_rules import (
    Package,
    borrowed_private_names,
    import_cycles,
    private_reaches,
    unlayered,
    upward_imports,
)

TESTS = Path(__file__).parent
CHRONOCL = Package(
    TESTS.parent / "chronocl",
    (
        ("core", ("chronocl.core",)),
        ("modes", ("chronocl.modes", "chronocl.reference")),
        ("data", ("chronocl.data",)),
        ("engine", ("chronocl.engine",)),
        ("integration", ("chronocl.integration",)),
        ("events", ("chronocl.events",)),
        ("render", ("chronocl.render",)),
        ("viewer", ("chronocl.viewer",)),
        ("notebook", ("chronocl.notebook",)),
        ("report", ("chronocl.report",)),
        (
            "cli",
            (
                "chronocl.cli",
                "chronocl.demo",
                "chronocl.demo_defaults",
                "chronocl.__main__",
                "chronocl",
            ),
        ),
    ),
)
BAD = Package(
    TESTS / "layer_fixtures" / "badpkg",
    (("low", ("badpkg.low",)), ("high", ("badpkg.high",)), ("top", ("badpkg",))),
)
VIEWER_JS = TESTS.parent / "chronocl" / "viewer" / "static"
BAD_JS = TESTS / "layer_fixtures" / "badjs"
RULES = {
    "upward imports": upward_imports,
    "private names borrowed": borrowed_private_names,
    "private attributes reached": private_reaches,
    "import cycles": import_cycles,
}


def test_every_module_has_a_layer():
    missing = unlayered(CHRONOCL)
    assert not missing, f"in no layer (add them to CHRONOCL's layers): {missing}"


@pytest.mark.parametrize("rule", RULES)
def test_chronocl_keeps_the_rule(rule):
    broken = [str(f) for f in RULES[rule](CHRONOCL)]
    assert not broken, f"{rule}:\n" + "\n".join(broken)


def _found(check) -> set[tuple[str, int, str]]:
    return {(f.file, f.line, f.what) for f in check(BAD)}


def test_the_fixture_has_a_layer_each():
    assert unlayered(BAD) == []
    assert "badpkg.low.ring_a" in BAD.modules  # the parser sees the fixture at all


def test_a_subpackage_left_out_of_the_layers_is_in_none():
    """The package's own name places its face alone, not every module under it."""
    without_high = Package(BAD.root, (("low", ("badpkg.low",)), ("top", ("badpkg",))))
    assert unlayered(without_high) == ["badpkg.high", "badpkg.high.top"]


def test_an_upward_import_is_rejected():
    assert _found(upward_imports) == {
        ("badpkg/low/climbs.py", 3, "imports badpkg.high.top"),
    }


def test_a_borrowed_private_name_is_rejected():
    assert _found(borrowed_private_names) == {
        ("badpkg/low/borrows.py", 3, "imports _secret from badpkg.low.owner"),
    }


def test_attribute_reaches_into_another_modules_private_names_are_rejected():
    """A module's `_secret`, another module's object's `_slot` read and `_hidden` written; not
    `self`, `cls`, `super()`, `type(self)`, the module's own class and names, dunders or
    namedtuple's `_replace` (badpkg/low/reaches.py and owner.py use each)."""
    assert _found(private_reaches) == {
        ("badpkg/low/reaches.py", 11, "reaches owner._secret"),
        ("badpkg/low/reaches.py", 12, "reaches thing._slot"),
        ("badpkg/low/reaches.py", 16, "reaches thing._hidden"),
    }


def test_runtime_and_type_only_cycles_are_rejected():
    cycles = {f.what: f for f in import_cycles(BAD)}
    assert set(cycles) == {
        "runtime import cycle badpkg.low.ring_a <-> badpkg.low.ring_b",
        "type-only import cycle badpkg.low.typed_a <-> badpkg.low.typed_b",
        "runtime import cycle badpkg.low.guard_a <-> badpkg.low.guard_b",
    }
    ring = cycles["runtime import cycle badpkg.low.ring_a <-> badpkg.low.ring_b"]
    assert "badpkg/low/ring_b.py:5 imports badpkg.low.ring_a" in ring.detail  # in a function
    typed = cycles["type-only import cycle badpkg.low.typed_a <-> badpkg.low.typed_b"]
    assert "badpkg/low/typed_b.py:8 type-only imports badpkg.low.typed_a" in typed.detail


def test_if_not_type_checking_runs_and_its_else_does_not():
    """`if not TYPE_CHECKING:` ends in TYPE_CHECKING too; its body runs (a runtime import),
    its `else:` is for type checkers (a type-only import)."""
    edges = {(i.target, i.line, i.type_only) for i in BAD.imports["badpkg.low.guard_a"]}
    assert edges == {
        ("badpkg.low.guard_b", 8, False),
        ("badpkg.low.typed_b", 10, True),
        ("badpkg.low.typed_b", 13, False),
        ("badpkg.low.typed_a", 15, True),
    }


def test_the_viewer_modules_have_no_import_cycle():
    scripts = Scripts(VIEWER_JS)
    assert len(scripts.imports["app.js"]) > 10  # the parser reads the modules' imports
    cycles = js_import_cycles(scripts)
    assert not cycles, "\n".join(map(str, cycles))


def test_the_viewer_modules_are_passed_their_state():
    """app.js makes the page's state (state.js: pageState) and gives it to each module's bind
    function; no module imports state another module changes."""
    found = shared_state_imports(Scripts(VIEWER_JS))
    assert not found, "shared mutable state imported:\n" + "\n".join(map(str, found))


def test_a_js_import_cycle_is_rejected():
    (cycle,) = js_import_cycles(Scripts(BAD_JS))
    assert (cycle.file, cycle.line, cycle.what) == (
        "badjs/ring_a.js",
        2,
        "import cycle ring_a.js <-> ring_b.js",
    )
    assert "badjs/ring_b.js:2 imports ring_a.js" in cycle.detail


def test_shared_mutable_js_state_is_rejected():
    """`store` is mutated by writer.js (under another name), `list` by pusher.js through a
    method, `count` is an `export let`; `fixed` is only read and `tick` is a function."""
    found = {(f.file, f.line, f.what) for f in shared_state_imports(Scripts(BAD_JS))}
    assert found == {
        ("badjs/writer.js", 2, "imports shared mutable store from store.js"),
        ("badjs/pusher.js", 2, "imports shared mutable list from store.js"),
        ("badjs/reader.js", 2, "imports shared mutable store from store.js"),
        ("badjs/reader.js", 2, "imports shared mutable count from store.js"),
    }


@pytest.mark.parametrize(
    "line",
    [
        "import thing from './x.js';",
        "import * as x from './x.js';",
        "import './x.js';",
        'import { a } from "./x.js";',
        "export { a } from './x.js';",
    ],
)
def test_an_import_the_js_parser_does_not_read_fails(tmp_path, line):
    (tmp_path / "m.js").write_text("// a module\n" + line + "\n")
    with pytest.raises(ValueError, match=r"m\.js:2: an import form not read"):
        Scripts(tmp_path)


def test_no_engine_capability_is_guessed():
    """Every engine declares its capabilities (`chronocl.engine.base.Engine`: reads_in_place,
    copies_to_device, writes_display, writes_winners, device_format); no caller guesses one
    with `getattr` and a default of its own (issue 47: defaults of True here and False there)."""
    import re
    from pathlib import Path

    from chronocl.engine.base import Engine
    from chronocl.engine.numpy import NumpyEngine
    from chronocl.engine.opencl import OpenCLEngine

    names = (
        "reads_in_place",
        "copies_to_device",
        "writes_display",
        "writes_winners",
        "device_format",
        "dc",
    )
    guess = re.compile(r"getattr\([^)]*[\"'](" + "|".join(names) + r")[\"']")
    root = Path(__file__).resolve().parents[1] / "chronocl"
    found = [
        f"{p.relative_to(root.parent)}:{n}: {line.strip()}"
        for p in sorted(root.rglob("*.py"))
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if guess.search(line)
    ]
    assert not found, "\n".join(found)
    declared = [n for n in Engine.__annotations__ if n != "name"]
    assert set(declared) == set(names) - {"dc"}
    for engine in (NumpyEngine(), OpenCLEngine()):
        assert all(hasattr(engine, n) for n in declared), engine


# Numeric ALL-CAPS module constants in viewer/render/data (`NAME = 3`, `NAME: int = 2**20`), as
# `grep -rnE "^[A-Z][A-Z0-9_]{2,}\s*(:\s*[^=]+)?=\s*[-0-9]"` counts them: 118 before the tuning
# constants moved to chronocl/core/tuning.py (issue 47), 71 before the heuristics' thresholds
# joined them and the server's limits (`chronocl.viewer.protocol.LIMITS`) and the annotations'
# sizes (`chronocl.render.layout.LAYOUT`) got a home each. The rest size the code beside them
# (kernel-fixed sizes, GL enums and units, file formats, tolerances, the events panel's sizes).
# Lower this as constants go; a tuning constant belongs in `Tuning`, with its measurement.
MAX_NUMERIC_CONSTANTS = 28
NUMERIC_CONSTANT = re.compile(r"^[A-Z][A-Z0-9_]{2,}\s*(:\s*[^=]+)?=\s*[-0-9]")


def test_numeric_constants_do_not_grow_back():
    """Tuning constants live in `chronocl.core.tuning.Tuning`; the count of the others in
    viewer/render/data stays at or under MAX_NUMERIC_CONSTANTS (issue 47)."""
    root = TESTS.parent / "chronocl"
    found = [
        f"{p.relative_to(root.parent)}:{n}: {line.strip()}"
        for package in ("viewer", "render", "data")
        for p in sorted((root / package).rglob("*.py"))
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if NUMERIC_CONSTANT.match(line)
    ]
    assert len(found) > 10  # the pattern matches at all
    assert len(found) <= MAX_NUMERIC_CONSTANTS, (
        f"{len(found)} numeric ALL-CAPS constants in viewer/render/data, at most "
        f"{MAX_NUMERIC_CONSTANTS}: a tuning constant goes in chronocl/core/tuning.py's `Tuning` "
        "with a comment saying how it was measured\n" + "\n".join(found)
    )


def test_every_tuning_field_says_what_it_tunes_and_how_it_was_measured():
    """Each field of `Tuning` has a comment right above it (what it tunes, and the machine,
    command and figure it was measured with, or "not measured" and why the value)."""
    import ast
    import dataclasses

    from chronocl.core.tuning import TUNING, Tuning

    path = TESTS.parent / "chronocl" / "core" / "tuning.py"
    lines = path.read_text().splitlines()
    (cls,) = [
        node
        for node in ast.parse("\n".join(lines)).body
        if isinstance(node, ast.ClassDef) and node.name == "Tuning"
    ]
    fields = [node for node in cls.body if isinstance(node, ast.AnnAssign)]
    assert [f.target.id for f in fields] == [f.name for f in dataclasses.fields(Tuning)]
    bare = [f.target.id for f in fields if not lines[f.lineno - 2].strip().startswith("#")]
    assert not bare, f"Tuning fields without a comment above them: {bare}"
    assert not Tuning.__dataclass_params__.frozen  # tests set a field of the one instance
    assert isinstance(TUNING, Tuning)
