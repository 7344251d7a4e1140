"""The optional libraries feature tracking needs (the ``events`` extra), imported when first used.

`chronocl.events` labels components with connected-components-3d (``cc3d``) and holds the event
graph in networkx. Both come with ``pip install 'chronocl[events]'``; the rest of chronocl runs
without them, so they are imported here, on first use, and a missing one is one line naming
that install.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from chronocl.core.errors import ChronoclError

INSTALL = "pip install 'chronocl[events]'"
# module name -> the distribution that provides it
PACKAGES = {"cc3d": "connected-components-3d", "networkx": "networkx"}


class MissingExtraError(ChronoclError, ImportError):
    """A library of an optional extra (here ``events``) is not installed."""


def require(module: str) -> ModuleType:
    """The module `module` (one of `PACKAGES`), or MissingExtraError naming the install."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"feature tracking needs {PACKAGES[module]}, which is not installed; "
            f"install it with {INSTALL}"
        ) from None


def cc3d() -> ModuleType:
    """connected-components-3d, which labels the components of a step."""
    return require("cc3d")


def networkx() -> ModuleType:
    """networkx, which holds the event graph and finds the global tracks."""
    return require("networkx")
