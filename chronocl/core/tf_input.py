"""Checking transfer-function input (numbers, control points, JSON objects), one line per fault.

Every transfer-function constructor and JSON loader validates through these, so a bad value
is reported with what it is and where, as an InvalidTransferFunctionError.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from chronocl.core.errors import InvalidTransferFunctionError


def bad(msg: str) -> InvalidTransferFunctionError:
    return InvalidTransferFunctionError(msg)


_JSON_TYPES = {str: "the string", list: "the list", tuple: "the list", dict: "the object"}


def show(value: object, most: int = 60) -> str:
    """A value for a one-line message: its repr, shortened."""
    try:
        text = repr(value).replace("\n", " ")
    except RecursionError:
        return "(nested too deeply to show)"
    return text if len(text) <= most else text[: most - 3] + "..."


def got(value: object) -> str:
    """What a JSON value is, for 'must be ..., got <this>'."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return f"the number {show(value)}"
    return f"{_JSON_TYPES.get(type(value), type(value).__name__)} {show(value)}"


def number(value: object, what: str) -> float:
    """A finite number (int or float, not a string or true/false) as float."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise bad(f"{what} must be a number, got {got(value)}")
    try:
        x = float(value)
    except OverflowError:  # an int beyond float
        x = math.inf
    if not math.isfinite(x):
        raise bad(f"{what} is {show(value)}; every transfer-function value must be finite")
    return x


def finite_unit(value: object, what: str) -> float:
    x = number(value, what)
    if not 0.0 <= x <= 1.0:
        raise bad(f"{what} is {x}, outside [0, 1]; transfer-function values lie in [0, 1]")
    return x


def parse_points(points: object, n: int, what: str, names: str) -> tuple[tuple[float, ...], ...]:
    """Validate control points: each n numbers in [0, 1], strictly increasing first entries."""
    if isinstance(points, np.ndarray):
        points = points.tolist()
    if not isinstance(points, Sequence) or isinstance(points, str) or len(points) == 0:
        raise bad(f"{what} needs a non-empty list of control points ({names})")
    out = []
    for i, pt in enumerate(points):
        if isinstance(pt, np.ndarray):
            pt = pt.tolist()
        if not isinstance(pt, Sequence) or isinstance(pt, str):
            raise bad(f"{what} point {i} must be a list of {n} numbers ({names}), got {got(pt)}")
        if len(pt) != n:
            raise bad(f"{what} point {i} has {len(pt)} entries, expected {n} ({names})")
        out.append(tuple(finite_unit(v, f"{what} point {i} entry {j}") for j, v in enumerate(pt)))
    for i in range(1, len(out)):
        if out[i][0] <= out[i - 1][0]:
            raise bad(
                f"{what} points must be sorted by position without repeats: point {i} at "
                f"{out[i][0]} follows {out[i - 1][0]}"
            )
    return tuple(out)


def interp_points(points: tuple[tuple[float, ...], ...], x: np.ndarray) -> np.ndarray:
    """Piecewise-linear evaluation, constant beyond the first and last point."""
    pts = np.asarray(points, dtype=np.float64)
    return np.stack([np.interp(x, pts[:, 0], pts[:, j]) for j in range(1, pts.shape[1])], axis=-1)


def reject_constant(name: str) -> float:
    raise bad(f"{name} is not allowed in a transfer function; use finite numbers")


def check_keys(d: object, what: str, allowed: set[str]) -> None:
    if not isinstance(d, dict):
        raise bad(f"{what} must be a JSON object {{...}}, got {got(d)}")
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise bad(f"{what} has unknown key {unknown[0]!r}; allowed: {', '.join(sorted(allowed))}")
