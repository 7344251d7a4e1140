"""The physical times of a run's steps from the metadata its simulation wrote
(`ingest --times-from-meta FILE`), and the unit those times are in (`--time-unit`).

A simulation writes its own description beside its output: a JSON object holding either the
list of output times, or the time step and how often a step was written. `times_from_meta`
looks for, at any depth:

- a list of numbers under a time key (``times``, ``time``, ``t``, ``output_times``, ...):
  the steps' times as they are;
- else a time step (``dt``, ``time_step``, ...), optionally with an output interval in solver
  steps (``save_every``, ``output_interval``, ...) and a start (``t0``, ``t_start``, ...):
  the steps are at ``t0 + k * dt * every``, k = 0, 1, ... (a `Cadence`, counted where the
  steps are);
- a unit beside either (``time_unit``, ``time_units``, ``t_unit``, or ``units: {"time": ...}``).

Two candidate lists, or two time steps, are ambiguous: the error names them so the user picks
one with ``--times FILE.json:KEY``. Nothing is guessed from keys that are not listed here.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from chronocl.core.errors import InputNotFoundError, InvalidParameterError

LIST_KEYS = ("times", "time", "t", "output_times", "save_times", "sim_times", "time_points")
DT_KEYS = ("dt", "time_step", "timestep", "delta_t")
EVERY_KEYS = ("save_every", "output_every", "output_interval", "save_interval", "steps_per_output")
START_KEYS = ("t0", "t_start", "start_time", "time_start")
UNIT_KEYS = ("time_unit", "time_units", "t_unit")
UNIT_MOST = 16


@dataclass(frozen=True)
class Cadence:
    """Steps written at a fixed interval: step k is at ``start + k * interval``."""

    start: float
    interval: float

    def times(self, n_steps: int) -> list[float]:
        # round away the float noise of k * interval (0.30000000000000004 -> 0.3)
        return [float(f"{self.start + k * self.interval:.12g}") for k in range(n_steps)]


@dataclass(frozen=True)
class MetaTimes:
    """What a metadata file says: the times (a `FoundTimes` list or a `Cadence`), their unit as
    the file writes it (None when it names none; checked by `unit_of` when it is used) and
    where in the file they were found, for the ingest summary."""

    times: list | Cadence
    unit: str | None
    found: str

    def unit_of(self) -> str | None:
        """The file's unit, checked: one that is not a short name names the file and key."""
        if self.unit is None:
            return None
        try:
            return check_time_unit(self.unit)
        except InvalidParameterError:
            raise InvalidParameterError(
                f"{self.found} gives the time unit {self.unit!r}, not a short unit name; "
                "give one with --time-unit (e.g. s, ms, days)"
            ) from None


class FoundTimes(list):
    """A list of times read from a metadata file, with `found` saying where, for messages."""

    found: str = ""


def check_time_unit(unit: str) -> str:
    """A unit as legends write it after a time ('s', 'ms', 'days'): short, printable text."""
    text = unit.strip() if isinstance(unit, str) else ""
    if not text or len(text) > UNIT_MOST or not text.isprintable() or "," in text:
        raise InvalidParameterError(
            f"time unit {unit!r} is not a short unit name; give e.g. s, ms, min, h, days "
            f"(at most {UNIT_MOST} characters, no commas)"
        )
    return text


def load_meta(path: str | Path, flag: str = "--times-from-meta"):
    """The JSON a metadata file holds; one line naming the file where it is missing or not
    JSON (`flag`: the option that named it)."""
    p = Path(path)
    if not p.is_file():
        raise InputNotFoundError(f"metadata file {str(p)!r} does not exist; check the path")
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidParameterError(
            f"metadata file {str(p)!r} is not JSON ({exc}); {flag} reads JSON"
        ) from None


def times_from_meta(path: str | Path, required: bool = True, root=None) -> MetaTimes | None:
    """The steps' times a simulation's JSON metadata file gives (see the module docstring);
    None where it names none and they are not `required`. `root`: the file's JSON, loaded."""
    p = Path(path)
    root = load_meta(p) if root is None else root
    objects = list(objects_in(root, ""))
    lists = [
        (f"{where}{key}", obj[key], obj)
        for where, obj in objects
        for key in LIST_KEYS
        if numbers(obj.get(key))
    ]
    if len(lists) > 1:
        names = [f"{p}:{name}" for name, _, _ in lists]
        raise InvalidParameterError(
            f"{p} holds {len(lists)} lists of times ({', '.join(names)}); choose one with "
            f"--times {names[0]}"
        )
    if lists:
        name, times, obj = lists[0]
        found = FoundTimes(times)
        found.found = f"{p}:{name}"
        return MetaTimes(found, _unit(obj), found.found)
    steps = [
        (where, obj, key)
        for where, obj in objects
        for key in DT_KEYS
        if finite(obj.get(key)) is not None
    ]
    if len(steps) > 1:
        names = ", ".join(f"{where}{key}" for where, _, key in steps)
        raise InvalidParameterError(
            f"{p} holds {len(steps)} time steps ({names}); name the list of times with "
            f"--times {p}:KEY, or give --times"
        )
    if not steps and not required:
        return None
    if not steps:
        raise InvalidParameterError(
            f"{p} names no times: no list under {', '.join(LIST_KEYS)} and no time step under "
            f"{', '.join(DT_KEYS)}; give --times {p}:KEY or a list with --times"
        )
    where, obj, key = steps[0]
    interval = float(obj[key])
    found = f"{p}:{where}{key}"
    every = [k for k in EVERY_KEYS if finite(obj.get(k)) is not None]
    if every:
        interval *= float(obj[every[0]])
        found += f" × {where}{every[0]}"
    start = [k for k in START_KEYS if finite(obj.get(k)) is not None]
    if interval <= 0:
        raise InvalidParameterError(
            f"{found} gives an output interval of {interval:g}; it must be > 0"
        )
    cadence = Cadence(float(obj[start[0]]) if start else 0.0, interval)
    return MetaTimes(cadence, _unit(obj), found)


def objects_in(node: object, where: str):
    """(path prefix, object) for every JSON object in `node`, outermost first."""
    if isinstance(node, dict):
        yield where, node
        for key, value in node.items():
            yield from objects_in(value, f"{where}{key}.")


def finite(value: object) -> float | None:
    """`value` as a finite number, None when it is not one (booleans are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def numbers(value: object) -> bool:
    return isinstance(value, list) and bool(value) and all(finite(v) is not None for v in value)


def _unit(obj: dict) -> str | None:
    """The unit the object names beside its times, as written (checked where it is used)."""
    for key in UNIT_KEYS:
        if isinstance(obj.get(key), str):
            return obj[key]
    units = obj.get("units")
    if isinstance(units, dict):
        for key in ("time", "t"):
            if isinstance(units.get(key), str):
                return units[key]
    return None
