"""Integration engines: ``numpy`` (the reference) and ``opencl`` (PoCL on CPUs, any GPU driver).

Both keep the contract in `engine.base` (`Engine`); `chronocl.integrate` streams the
bricks through one.
"""

from __future__ import annotations

from chronocl.core.errors import UnknownNameError
from chronocl.engine.base import FIXED_ONE, Engine
from chronocl.engine.numpy import NumpyEngine

__all__ = ["ENGINES", "FIXED_ONE", "Engine", "NumpyEngine", "check_engine", "get_engine"]

ENGINES = ("opencl", "numpy")

_engines: dict[tuple[str, str | None], Engine] = {}


def check_engine(name: str) -> str:
    """An engine name chronocl has (checked before any work, nothing built)."""
    if name not in ENGINES:
        raise UnknownNameError(f"unknown engine {name!r}; choose one of {', '.join(ENGINES)}")
    return name


def get_engine(name: str = "opencl", device: str | None = None) -> Engine:
    """A cached engine by name (the OpenCL one per device)."""
    key = (check_engine(name), device)
    if key not in _engines:
        if name == "numpy":
            _engines[key] = NumpyEngine()
        else:
            from chronocl.engine.opencl import OpenCLEngine

            _engines[key] = OpenCLEngine(device)
    return _engines[key]
