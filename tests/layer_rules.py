"""The layer rules, as functions of a package's source, so that tests/test_layers.py runs the
same checks on chronocl and on the known-bad fixture (tests/layer_fixtures/badpkg).

Every import counts: those inside functions, and those under `if TYPE_CHECKING:` (for
annotations only, never run), which are marked type-only. A cycle through a type-only import is
still a cycle: the modules cannot be read apart. The rules:
- no import cycle (runtime, or one that needs a type-only import);
- no upward import (a module imports only its own layer and those below);
- no `from x import _name` from another module;
- no attribute reach `x._name` into another module's private name, where `x` is not `self`,
  `cls`, `super()`, `type(self)` or a class of the module itself, `_name` is not a dunder, and
  the module does not define `_name` itself (as a function, method, class attribute, module
  variable or `self._name = ...`): another instance of the module's own class may be read.
"""

from __future__ import annotations

import ast
from collections import deque
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

Layers = tuple[tuple[str, tuple[str, ...]], ...]

# Names that start with "_" but are public API (namedtuple's methods and fields).
PUBLIC_UNDERSCORE = frozenset({"_replace", "_asdict", "_fields", "_make", "_field_defaults"})
OWN = frozenset({"self", "cls", "mcs"})


@dataclass(frozen=True)
class Import:
    target: str  # the imported module
    name: str | None  # the name taken from it (None: the module itself)
    line: int
    type_only: bool  # under `if TYPE_CHECKING:`: for annotations, never run


@dataclass(frozen=True)
class Finding:
    """One broken rule: where, and what (without line numbers, so a known list can name it)."""

    file: str
    line: int
    what: str
    detail: str = ""

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.what}" + (
            f" ({self.detail})" if self.detail else ""
        )


def _is_type_checking(test: ast.expr) -> bool:
    if isinstance(test, ast.Name):
        return test.id == "TYPE_CHECKING"
    return (
        isinstance(test, ast.Attribute)
        and test.attr == "TYPE_CHECKING"
        and isinstance(test.value, ast.Name)
        and test.value.id == "typing"
    )


def type_only_nodes(tree: ast.AST) -> set[int]:
    """ids of the nodes a type checker alone reads: the body of `if TYPE_CHECKING:` and the
    `else:` of `if not TYPE_CHECKING:` (that `if`'s body runs)."""
    found: set[int] = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.If):
            continue
        if _is_type_checking(node.test):
            branch = node.body
        elif (
            isinstance(node.test, ast.UnaryOp)
            and isinstance(node.test.op, ast.Not)
            and _is_type_checking(node.test.operand)
        ):
            branch = node.orelse
        else:
            continue
        found.update(id(n) for stmt in branch for n in ast.walk(stmt))
    return found


def _is_private(name: str) -> bool:
    dunder = name.startswith("__") and name.endswith("__")
    return name.startswith("_") and not dunder and name not in PUBLIC_UNDERSCORE


class Package:
    """A package's modules, their layers and their imports."""

    def __init__(self, root: Path, layers: Layers):
        self.root = root
        self.name = root.name
        self.layers = layers

    @cached_property
    def modules(self) -> dict[str, Path]:
        found = {}
        for path in sorted(self.root.rglob("*.py")):
            parts = list(path.relative_to(self.root.parent).with_suffix("").parts)
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
        return found

    @cached_property
    def trees(self) -> dict[str, ast.Module]:
        return {m: ast.parse(p.read_text(), str(p)) for m, p in self.modules.items()}

    def file(self, module: str) -> str:
        return self.modules[module].relative_to(self.root.parent).as_posix()

    def layer(self, module: str) -> int | None:
        """The rank of the longest prefix naming `module`; the package's own name names its
        face (`__init__`) alone, so a new subpackage is in no layer until it is placed."""
        best = None
        for rank, (_, prefixes) in enumerate(self.layers):
            for prefix in prefixes:
                inside = prefix != self.name and module.startswith(prefix + ".")
                if module == prefix or inside:
                    if best is None or len(prefix) > best[1]:
                        best = (rank, len(prefix))
        return None if best is None else best[0]

    def _imports(self, module: str) -> list[Import]:
        is_pkg = self.modules[module].name == "__init__.py"
        tree = self.trees[module]
        type_only = type_only_nodes(tree)
        found = []
        for node in ast.walk(tree):
            typed = id(node) in type_only
            if isinstance(node, ast.Import):
                found += [Import(a.name, None, node.lineno, typed) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = module.split(".")
                    parts = parts if is_pkg else parts[:-1]
                    parts = parts[: len(parts) - (node.level - 1)]
                    base = ".".join(parts + ([base] if base else []))
                for a in node.names:
                    target = f"{base}.{a.name}"
                    if target in self.modules:
                        found.append(Import(target, None, node.lineno, typed))
                    else:
                        found.append(Import(base, a.name, node.lineno, typed))
        mine = self.name
        return [i for i in found if i.target == mine or i.target.startswith(mine + ".")]

    @cached_property
    def imports(self) -> dict[str, list[Import]]:
        return {m: self._imports(m) for m in self.modules}


def unlayered(pkg: Package) -> list[str]:
    return [m for m in pkg.modules if pkg.layer(m) is None]


def upward_imports(pkg: Package) -> list[Finding]:
    found = []
    for m, edges in pkg.imports.items():
        for i in edges:
            low, high = pkg.layer(m), pkg.layer(i.target)
            if low is not None and high is not None and high > low:
                kind = "type-only import" if i.type_only else "imports"
                layers = f"{pkg.layers[high][0]} is above {pkg.layers[low][0]}"
                found.append(Finding(pkg.file(m), i.line, f"{kind} {i.target}", layers))
    return found


def borrowed_private_names(pkg: Package) -> list[Finding]:
    return [
        Finding(pkg.file(m), i.line, f"imports {i.name} from {i.target}")
        for m, edges in pkg.imports.items()
        for i in edges
        if i.name and _is_private(i.name) and i.target != m
    ]


def _own_private_names(tree: ast.Module) -> set[str]:
    """The private names a module defines itself."""
    own = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            own.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            own.add(node.id)
        elif (
            isinstance(node, ast.Attribute)
            and isinstance(node.ctx, ast.Store)
            and isinstance(node.value, ast.Name)
            and node.value.id in OWN
        ):
            own.add(node.attr)
        elif isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__slots__" for t in node.targets
        ):
            own.update(
                c.value
                for c in ast.walk(node.value)
                if isinstance(c, ast.Constant) and isinstance(c.value, str)
            )
    return {name for name in own if _is_private(name)}


def _is_own(value: ast.expr, classes: set[str]) -> bool:
    """`self`, `cls`, `super()`, `type(self)` or one of the module's own classes."""
    if isinstance(value, ast.Name):
        return value.id in OWN or value.id in classes
    if isinstance(value, ast.Call) and isinstance(value.func, ast.Name):
        if value.func.id == "super":
            return True
        return value.func.id == "type" and [ast.unparse(a) for a in value.args] == ["self"]
    return False


def private_reaches(pkg: Package) -> list[Finding]:
    found = []
    for m, tree in pkg.trees.items():
        own = _own_private_names(tree)
        classes = {n.name for n in ast.walk(tree) if isinstance(n, ast.ClassDef)}
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and _is_private(node.attr)
                and node.attr not in own
                and not _is_own(node.value, classes)
            ):
                reach = f"{ast.unparse(node.value)}.{node.attr}"
                found.append(Finding(pkg.file(m), node.lineno, f"reaches {reach}"))
    return sorted(found, key=lambda f: (f.file, f.line, f.what))


def strong_components(edges: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components with two or more members (each is a cycle)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges[v]):
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
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def _loop(pkg: Package, component: list[str], runtime: bool) -> list[str]:
    """One shortest way round the cycle from its first module, edge by edge with its line."""
    start, members = component[0], set(component)
    came: dict[str, tuple[str, Import]] = {}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        for i in pkg.imports[v]:
            if i.target not in members or i.target == v or (runtime and i.type_only):
                continue
            if i.target == start or i.target not in came:
                came.setdefault(i.target, (v, i))
                if i.target == start:
                    queue.clear()
                    break
                queue.append(i.target)
    steps, at = [], start
    while True:
        v, i = came[at]
        steps.append(f"{pkg.file(v)}:{i.line} {'type-only ' if i.type_only else ''}imports {at}")
        at = v
        if at == start:
            return steps[::-1]


def import_cycles(pkg: Package) -> list[Finding]:
    """Each cycle once, as its modules; runtime if it closes without a type-only import.

    The package's face (its `__init__`, which re-exports the API) is left out: its importers
    are the command line, which sits beside it in the top layer."""

    def graph(type_only: bool) -> dict[str, set[str]]:
        return {
            m: {
                i.target
                for i in pkg.imports[m]
                if i.target in pkg.modules
                and i.target not in (m, pkg.name)
                and (type_only or not i.type_only)
            }
            for m in pkg.modules
        }

    runtime = strong_components(graph(False))
    every = runtime + [c for c in strong_components(graph(True)) if c not in runtime]
    found = []
    for component in every:
        kind = "runtime" if component in runtime else "type-only"
        steps = _loop(pkg, component, component in runtime)
        file, line = steps[0].split(" ")[0].rsplit(":", 1)
        what = f"{kind} import cycle " + " <-> ".join(component)
        found.append(Finding(file, int(line), what, " -> ".join(steps)))
    return found
