"""Reading the physical times of a series' steps from the command line (`ingest --times`).

A value is one of:

- a comma list: ``0,0.5,1.5`` or ``2024-01-01T00:00,2024-01-01T06:00``;
- a text file with one time per line (blank lines and ``#`` comments skipped);
- a JSON file holding a list, or ``FILE.json:KEY`` naming the list inside an object, with dots
  for nesting (``meta.json:run.times``): the metadata a simulation writes beside its steps.

Numbers become numbers (ints stay ints), anything else stays text (ISO datetimes are shown as
dates and times). How many there must be is checked where the steps are counted
(`chronocl.data.metadata.parse_times`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from chronocl.core.errors import InputNotFoundError, InvalidParameterError

FORMS = "a comma list (0,0.5,1), a file with one time per line, or FILE.json[:KEY]"


def read_times(value: str) -> list:
    """The times `value` gives (see the module docstring), one per step."""
    text = value.strip()
    if not text:
        raise InvalidParameterError(f"--times is empty; give {FORMS}")
    path, key = _json_reference(text)
    if path is not None:
        return _from_json(path, key)
    if _is_file(text):
        lines = Path(text).read_text(encoding="utf-8", errors="replace").splitlines()
        items = [ln.strip() for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
        if not items:
            raise InvalidParameterError(f"times file {text!r} holds no times; one per line")
        return [_scalar(item, text) for item in items]
    if _looks_like_a_file(text):
        raise InputNotFoundError(f"times file {text!r} does not exist; give {FORMS}")
    return [_scalar(item.strip(), "--times") for item in text.split(",")]


def times_file(value: str) -> Path | None:
    """The file `value` (a --times) reads, where it names one (a JSON file, with or without a
    key, or a file of times); None for times given inline."""
    text = value.strip()
    path, _ = _json_reference(text) if text else (None, None)
    if path is None and text and _is_file(text):
        path = Path(text)
    return path


def _json_reference(text: str) -> tuple[Path | None, str | None]:
    """(the JSON file, the key) when `text` names an existing .json file, else (None, None)."""
    if text.lower().endswith(".json") and _is_file(text):
        return Path(text), None
    head, sep, key = text.rpartition(":")
    if sep and head.lower().endswith(".json"):
        if not _is_file(head):
            raise InputNotFoundError(f"times file {head!r} does not exist; give {FORMS}")
        return Path(head), key
    return None, None


def _from_json(path: Path, key: str | None) -> list:
    try:
        node = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidParameterError(f"times file {str(path)!r} is not JSON ({exc})") from None
    where = str(path)
    for part in key.split(".") if key else ():
        if not isinstance(node, dict) or part not in node:
            keys = ", ".join(map(str, node)) if isinstance(node, dict) else "none"
            raise InvalidParameterError(
                f"{where} has no key {part!r} (keys: {keys}); name the list as {path}:KEY"
            )
        node, where = node[part], f"{where}:{part}" if where == str(path) else f"{where}.{part}"
    if isinstance(node, dict):
        raise InvalidParameterError(
            f"{where} is a JSON object; name the list of times in it: {path}:KEY "
            f"(keys: {', '.join(map(str, node))})"
        )
    if not isinstance(node, list) or not node:
        raise InvalidParameterError(f"{where} is not a list of times; give a JSON list")
    out = []
    for item in node:
        if isinstance(item, bool) or not isinstance(item, int | float | str):
            raise InvalidParameterError(f"{where} holds {item!r}; times are numbers or text")
        if isinstance(item, float) and not math.isfinite(item):
            raise InvalidParameterError(f"{where} holds {item!r}; times must be finite")
        out.append(item)
    return out


def _scalar(item: str, where: str) -> int | float | str:
    """A number where `item` reads as one, else the text itself."""
    if not item:
        raise InvalidParameterError(f"{where} has an empty time; give {FORMS}")
    for kind in (int, float):
        try:
            number = kind(item)
        except ValueError:
            continue
        if isinstance(number, float) and not math.isfinite(number):
            raise InvalidParameterError(f"{where} holds {item!r}; times must be finite")
        return number
    return item


def _is_file(text: str) -> bool:
    """Whether `text` names a file (False for a comma list too long to be a file name)."""
    try:
        return Path(text).is_file()
    except (OSError, ValueError):
        return False


def _looks_like_a_file(text: str) -> bool:
    """A single item with a path separator or a file suffix: a missing file, not a time."""
    return "," not in text and ("/" in text or Path(text).suffix.lower() in (".txt", ".json"))
