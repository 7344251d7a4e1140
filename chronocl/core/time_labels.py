"""Time labels for display: what legends, panel captions, the viewer's timeline and probe plots
write for a step.

A store may label its steps (NetCDF datetimes, physical times from ingest `--times` or a
DataArray's coordinate); one without labels has its step numbers as labels. `display_labels`
turns step indices and the labels of those steps into short strings: the labels where the
store has them and `prefer` is "labels" (the default), else the step numbers. ISO datetimes
lose their zero seconds and fractions ('2024-01-01T06:00:00.000000000' -> '2024-01-01 06:00'),
and their midnight when every label is a midnight; numbers are written compactly ('%g').
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from chronocl.core.errors import UnknownNameError

TIME_LABEL_CHOICES = ("labels", "steps")
_ISO = re.compile(r"^(\d{4}-\d{2}-\d{2})[T ](\d{2}:\d{2})(:\d{2}(\.\d+)?)?(Z|[+-]\d{2}:?\d{2})?$")


def check_prefer(prefer: str) -> str:
    """'labels' or 'steps'; anything else raises naming the choices."""
    if prefer not in TIME_LABEL_CHOICES:
        raise UnknownNameError(
            f"unknown time labels {prefer!r}; choose labels (the store's times) or steps"
        )
    return prefer


def has_labels(steps: Sequence[int], labels: Sequence | None, unit: str | None = None) -> bool:
    """Whether `labels` (one per step) say more than the step numbers themselves: times with
    a `unit` always do, even where they equal the step numbers."""
    if not labels or len(labels) != len(steps):
        return False
    return bool(unit) or any(
        isinstance(t, bool) or not isinstance(t, int | float) or t != s
        for s, t in zip(steps, labels, strict=True)
    )


def display_labels(
    steps: Sequence[int], labels: Sequence | None, prefer: str = "labels", unit: str | None = None
) -> list[str]:
    """One display string per step: its time label, or its number when the store has no
    labels or `prefer` is 'steps'. A `unit` follows each numeric label ('0.5 s')."""
    check_prefer(prefer)
    if prefer == "steps" or not has_labels(steps, labels, unit):
        return [str(int(s)) for s in steps]
    assert labels is not None
    texts = [_text(t) + unit_suffix(t, unit) for t in labels]
    # Every ISO datetime at midnight: the dates say it all.
    if all(_ISO.match(str(t)) for t in labels) and all(t.endswith(" 00:00") for t in texts):
        texts = [t[:-6] for t in texts]
    return texts


def unit_suffix(label: object, unit: str | None) -> str:
    """' s' after a numeric time label when the store names a unit; nothing otherwise."""
    numeric = isinstance(label, int | float) and not isinstance(label, bool)
    return f" {unit}" if unit and numeric else ""


def compact(texts: Sequence[str]) -> list[str]:
    """Display labels with the date dropped where it is the first label's (any of them may
    be shown alone): a legend's '2024-01-01 06:00', '10:00', '14:00', '2024-01-02 02:00'."""
    if not texts:
        return []
    date, _, clock = texts[0].partition(" ")
    if not clock or not _ISO.match(texts[0]):
        return list(texts)
    return [texts[0]] + [t[len(date) + 1 :] if t.startswith(date + " ") else t for t in texts[1:]]


def span_text(texts: Sequence[str]) -> str:
    """'first .. last' of display labels, the last without the date the two share:
    '2024-01-01 06:00 .. 18:00'."""
    if not texts:
        return ""
    first, last = texts[0], texts[-1]
    if len(texts) == 1 or first == last:
        return first
    date_a, _, time_a = first.partition(" ")
    date_b, _, time_b = last.partition(" ")
    if time_a and time_b and date_a == date_b and _ISO.match(f"{date_a} {time_a}"):
        last = time_b
    return f"{first} .. {last}"


def _text(label: object) -> str:
    if isinstance(label, float):
        return f"{label:g}" if math.isfinite(label) else str(label)
    text = str(label)
    m = _ISO.match(text)
    if not m:
        return text
    date, hm, seconds, _, zone = m.groups()
    keep = seconds if seconds and float(seconds[1:]) != 0 else ""
    if keep and "." in keep:
        keep = keep.rstrip("0").rstrip(".")
    return f"{date} {hm}{keep}{zone or ''}"
