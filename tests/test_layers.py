"""The package reads top-down: no import cycles, no upward imports, no private names borrowed.

Every import in every module counts, including those inside functions (those under
`if TYPE_CHECKING:`, for annotations only, never run). Layers, lowest first
(docs/architecture.md): core <- modes <- data <- engine <- integration <- render <- viewer
<- the command line (cli, demo, the package's face).
"""

from __future__ import annotations

import ast
from pathlib import Path

import chronocl

PACKAGE = Path(chronocl.__file__).parent
LAYERS = (
    ("core", ("chronocl.core",)),
    ("modes", ("chronocl.modes", "chronocl.reference")),
    ("data", ("chronocl.data",)),
    ("engine", ("chronocl.engine",)),
    ("integration", ("chronocl.integration",)),
    ("render", ("chronocl.render",)),
    ("viewer", ("chronocl.viewer",)),
    ("cli", ("chronocl.cli", "chronocl.demo", "chronocl.__main__", "chronocl")),
)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _layer(module: str) -> int:
    best = None
    for rank, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if module == prefix or module.startswith(prefix + "."):
                if best is None or len(prefix) > best[1]:
                    best = (rank, len(prefix))
    assert best is not None, f"{module} is in no layer: add it to LAYERS"
    return best[0]


def _imports(module: str) -> list[tuple[str, str | None, int]]:
    """(imported module, imported name or None, line) for every import in `module`."""
    path = MODULES[module]
    is_pkg = path.name == "__init__.py"
    found = []
    tree = ast.parse(path.read_text())
    # Imports under `if TYPE_CHECKING:` are for annotations only and never run.
    typing_only = {
        id(n)
        for block in ast.walk(tree)
        if isinstance(block, ast.If) and ast.unparse(block.test).endswith("TYPE_CHECKING")
        for stmt in block.body
        for n in ast.walk(stmt)
    }
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            found += [(a.name, None, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = module.split(".")
                parts = parts if is_pkg else parts[:-1]
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join(parts + ([base] if base else []))
            for a in node.names:
                target = f"{base}.{a.name}"
                if target in MODULES:
                    found.append((target, None, node.lineno))
                else:
                    found.append((base, a.name, node.lineno))
    return [(m, n, line) for m, n, line in found if m == "chronocl" or m.startswith("chronocl.")]


GRAPH = {m: _imports(m) for m in MODULES}


def test_every_module_has_a_layer():
    for module in MODULES:
        _layer(module)


def test_no_upward_imports():
    upward = [
        f"{m}:{line} imports {target} ({LAYERS[_layer(target)][0]} is above {LAYERS[_layer(m)][0]})"
        for m, edges in GRAPH.items()
        for target, _, line in edges
        if _layer(target) > _layer(m)
    ]
    assert not upward, "\n".join(upward)


def test_no_private_names_from_other_modules():
    borrowed = [
        f"{m}:{line} imports {name} from {target}"
        for m, edges in GRAPH.items()
        for target, name, line in edges
        if name and name.startswith("_") and target != m
    ]
    assert not borrowed, "\n".join(borrowed)


def test_no_import_cycles():
    edges = {
        m: {t for t, _, _ in GRAPH[m] if t in MODULES and t != m and t != "chronocl"}
        for m in MODULES
    }
    # Tarjan's strongly connected components: any with two or more modules is a cycle.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)
