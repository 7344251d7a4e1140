"""The widget's front end as one ES module (anywidget's `_esm`): `widget.js` with the browser
viewer's own files in it (chronocl/viewer/static: its ES modules, index.html's body, its style
sheet), which it links in the browser through blob URLs (widget.js says how). Nothing of the
viewer is copied or rewritten here: the widget runs the page's code.

The modules are ordered so that each comes after those it imports (the viewer's modules have
no import cycle: tests/test_layers.py), read from their `import ... from './x.js'` lines.
"""

from __future__ import annotations

import functools
import json
import re
from importlib import resources

from chronocl.core.errors import InvalidParameterError

IMPORT = re.compile(r"\bfrom\s*'\./([\w.-]+\.js)'")
BODY = re.compile(r"<body[^>]*>(.*?)<script\b", re.S)
# The widget's own layout: a box of the cell output's width and the widget's height (its
# `height`), not the window's; the side panel a little narrower.
WIDGET_CSS = """
.chronocl.widget { height: 620px; width: 100%; --side: 300px; outline: none;
  border: 1px solid var(--line); border-radius: 4px; }
"""
ENTRY = "app.js"  # the module that starts the viewer (main.js starts the page; not shipped)


def _static() -> resources.abc.Traversable:
    return resources.files("chronocl.viewer") / "static"


def link_order(modules: dict[str, str], entry: str = ENTRY) -> list[str]:
    """The modules `entry` needs, each after the modules it imports; InvalidParameterError on
    a cycle or a missing module."""
    order: list[str] = []
    visiting: set[str] = set()

    def visit(name: str) -> None:
        if name in order:
            return
        if name not in modules:
            raise InvalidParameterError(f"viewer module {name} is imported but missing")
        if name in visiting:
            raise InvalidParameterError(f"viewer modules import each other in a cycle at {name}")
        visiting.add(name)
        for dep in IMPORT.findall(modules[name]):
            visit(dep)
        visiting.discard(name)
        order.append(name)

    visit(entry)
    return order


def markup(html: str) -> str:
    """index.html's body, without its script (the widget starts the viewer itself)."""
    found = BODY.search(html)
    if found is None:
        raise InvalidParameterError("the viewer's index.html has no <body> with a <script>")
    return found.group(1)


def bundle() -> dict:
    """The viewer's files the front end needs: modules (by file name), their link order, the
    markup and the style sheets."""
    static = _static()
    modules = {f.name: f.read_text() for f in static.iterdir() if f.name.endswith(".js")}
    order = link_order(modules)
    return {
        "order": order,
        "modules": {name: modules[name] for name in order},
        "markup": markup((static / "index.html").read_text()),
        "css": (static / "style.css").read_text(),
        "widget_css": WIDGET_CSS,
    }


@functools.cache
def esm() -> str:
    """widget.js with the bundle in it (made once a process)."""
    template = (resources.files("chronocl.notebook") / "widget.js").read_text()
    placeholder = "/* BUNDLE */ null"
    if template.count(placeholder) != 1:
        raise InvalidParameterError("widget.js must hold its bundle's placeholder once")
    # json.dumps escapes nothing that would end a script; the module is not inline HTML.
    return template.replace(placeholder, json.dumps(bundle()))
