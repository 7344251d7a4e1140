"""The layer rules for the viewer's plain ES modules (chronocl/viewer/static/*.js), read from
their `import` and `export` lines, so that tests/test_layers.py runs them on the viewer and on
the known-bad fixture (tests/layer_fixtures/badjs).

- No import cycle.
- No shared mutable state imported: an export is shared mutable state when it is an
  `export let` (or `var`), or an exported object that a module importing it mutates (assigns
  to a member, `delete`s one, `++`/`--`, or calls a mutating method such as `push` on it or on
  a member of it). Every import of such an export breaks the rule, reads included: the state
  is made by one module (app.js) and passed to the others.
An `import` statement of a form the parser does not know fails the check, so a parser that
misses imports cannot pass everything.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from .layer_rules import Finding, strong_components

NAMED = re.compile(r"import\s*\{([^}]*)\}\s*from\s*'(\./[\w.-]+\.js)'\s*;?", re.S)
# Every import, and every re-export (`export ... from`), which this parser does not read.
STATEMENT = re.compile(r"^(?:import\b|export\s*(?:\*|\{[^}]*\})\s*from\b)[^;]*;?", re.M | re.S)
LET = re.compile(r"^export\s+(?:let|var)\s+(\w+)", re.M)
MUTATING = "push|pop|shift|unshift|splice|sort|reverse|fill|set|delete|clear|add"


@dataclass(frozen=True)
class JsImport:
    source: str  # the module the name comes from (file name)
    name: str  # the name it exports
    local: str  # the name it has here
    line: int


def _strip_comments(text: str) -> str:
    """Comments blanked, lines kept (strings holding // or /* are not in these modules' imports)."""
    text = re.sub(r"/\*.*?\*/", lambda m: re.sub(r"[^\n]", " ", m.group()), text, flags=re.S)
    return re.sub(r"(^|[^:'\"\\])//[^\n]*", r"\1", text)


def _line(text: str, at: int) -> int:
    return text.count("\n", 0, at) + 1


class Scripts:
    """A folder of ES modules, their imports and their exports."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.files = {p.name: p for p in sorted(folder.glob("*.js"))}
        self.text = {name: _strip_comments(p.read_text()) for name, p in self.files.items()}
        self.imports = {name: self._imports(name) for name in self.files}

    def file(self, name: str) -> str:
        return f"{self.folder.name}/{name}"

    def _imports(self, name: str) -> list[JsImport]:
        text = self.text[name]
        found = []
        for stmt in STATEMENT.finditer(text):
            m = NAMED.fullmatch(stmt.group().strip())
            if not m:
                line = _line(text, stmt.start())
                raise ValueError(
                    f"{self.file(name)}:{line}: an import form not read: {stmt.group()}"
                )
            source, line = m.group(2)[2:], _line(text, stmt.start())
            for item in filter(None, (s.strip() for s in m.group(1).split(","))):
                exported, _, local = (part.strip() for part in item.partition(" as "))
                found.append(JsImport(source, exported, local or exported, line))
        return found

    def mutations(self, name: str, local: str) -> list[int]:
        """The lines where module `name` mutates its imported binding `local`."""
        root = r"(?<![\w.$])" + re.escape(local)
        member = r"(?:\s*\.\s*[\w$]+|\s*\[[^\]\n]*\])"
        patterns = (
            root + member + r"+\s*(?:[-+*/%|&^]|\*\*|<<|>>>?|\|\||&&|\?\?)?=(?![=>])",
            root + member + r"+\s*(?:\+\+|--)",
            r"(?:\+\+|--|\bdelete\s+)\s*" + root + member,
            root + member + r"*\s*\.\s*(?:" + MUTATING + r")\s*\(",
            r"\bObject\.assign\(\s*" + root + r"(?![\w$])",
        )
        text = self.text[name]
        return sorted({_line(text, m.start()) for p in patterns for m in re.finditer(p, text)})


def js_import_cycles(scripts: Scripts) -> list[Finding]:
    edges = {
        name: {i.source for i in scripts.imports[name] if i.source in scripts.files}
        for name in scripts.files
    }
    found = []
    for component in strong_components(edges):
        members = set(component)
        steps = [
            f"{scripts.file(m)}:{i.line} imports {i.source}"
            for m in component
            for i in scripts.imports[m]
            if i.source in members
        ]
        first = component[0]
        line = min(i.line for i in scripts.imports[first] if i.source in members)
        what = "import cycle " + " <-> ".join(component)
        found.append(Finding(scripts.file(first), line, what, "; ".join(sorted(set(steps)))))
    return found


def shared_mutable_exports(scripts: Scripts) -> dict[tuple[str, str], str]:
    """(module, exported name) -> why it is shared mutable state."""
    shared = {}
    for name, text in scripts.text.items():
        for m in LET.finditer(text):
            shared[name, m.group(1)] = (
                f"export let at {scripts.file(name)}:{_line(text, m.start())}"
            )
    for name, imports in scripts.imports.items():
        for i in imports:
            lines = scripts.mutations(name, i.local)
            if lines and (i.source, i.name) not in shared:
                shared[i.source, i.name] = f"mutated at {scripts.file(name)}:{lines[0]}"
    return shared


def shared_state_imports(scripts: Scripts) -> list[Finding]:
    shared = shared_mutable_exports(scripts)
    return [
        Finding(
            scripts.file(name),
            i.line,
            f"imports shared mutable {i.name} from {i.source}",
            shared[i.source, i.name],
        )
        for name, imports in scripts.imports.items()
        for i in imports
        if (i.source, i.name) in shared
    ]
