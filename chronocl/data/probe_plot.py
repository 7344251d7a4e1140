"""Plotting a probe's `TimeCurve` with matplotlib (no display, no pyplot): the values against
the time labels (dates, numbers, or named steps), a box's min-max band, the window shaded."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from chronocl.core.selection import Selection
from chronocl.core.time_labels import check_prefer, display_labels, has_labels


class Curve(Protocol):
    """What a plot reads of a probe's curve (`chronocl.data.probe.TimeCurve`, which plots
    itself through this module)."""

    steps: np.ndarray
    times: tuple
    values: np.ndarray
    min: np.ndarray | None
    max: np.ndarray | None
    source: str
    time_unit: str | None

    @property
    def is_box(self) -> bool: ...
    def __len__(self) -> int: ...
    def describe(self) -> str: ...
    def window_steps(self, window: object) -> tuple[int, ...]: ...


def figure(curve: Curve, window: object = None, title: str | None = None, time_labels="labels"):
    """The curve against its time labels (`time_labels="steps"`: the step numbers): a voxel's
    values as a line; a box's mean as a line over its min-max band; the window's span shaded
    and its steps marked."""
    from matplotlib.figure import Figure  # no pyplot: no display, no global state

    chosen = curve.window_steps(window)
    x, xlabel, names = time_axis(curve.times, curve.steps, time_labels, curve.time_unit)
    fig = Figure(figsize=(8, 4.5), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    if chosen:
        text = window if isinstance(window, str) else Selection(chosen, len(x)).describe()
        label = f"window {text}" + _span(x, xlabel, names, chosen, curve.time_unit)
        if len(x) == 1:
            ax.axvline(x[0], color="C1", alpha=0.5, linewidth=3, label=label)
        else:  # from half a step before the window's first step to half one after its last
            mids = x[:-1] + (x[1:] - x[:-1]) / 2
            lo = mids[chosen[0] - 1] if chosen[0] > 0 else x[0]
            hi = mids[chosen[-1]] if chosen[-1] < len(x) - 1 else x[-1]
            ax.axvspan(lo, hi, color="C1", alpha=0.15, linewidth=0, label=label, zorder=0)
    marker = "o" if len(curve) <= 60 else None
    if curve.is_box:
        ax.fill_between(
            x, curve.min, curve.max, color="C0", alpha=0.25, linewidth=0, label="min to max"
        )
        ax.plot(x, curve.values, color="C0", marker=marker, markersize=3, label="mean")
    else:
        ax.plot(x, curve.values, color="C0", marker=marker, markersize=3, label="value")
    if chosen:
        idx = np.asarray(chosen)
        ax.plot(x[idx], curve.values[idx], "o", color="C1", markersize=4, label="window steps")
    if names is not None:
        _label_ticks(ax, names)
    elif np.issubdtype(x.dtype, np.datetime64):
        from matplotlib.dates import AutoDateLocator, ConciseDateFormatter

        locator = AutoDateLocator()
        ax.xaxis.set_major_locator(locator)
        ax.xaxis.set_major_formatter(ConciseDateFormatter(locator))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("mean, min and max over the box" if curve.is_box else "value")
    where = f" of {Path(curve.source).name}" if curve.source else ""
    ax.set_title(title if title is not None else f"{curve.describe()}{where}")
    ax.grid(alpha=0.3)
    ax.margins(x=0.02)
    ax.legend(loc="best", fontsize="small")
    return fig


def _span(x: np.ndarray, xlabel: str, names, chosen, unit: str | None) -> str:
    """The window's first and last time as the axis shows them (nothing on a 'step' axis):
    the legend names the window in steps, as the user wrote it, and in the axis's units."""
    if xlabel == "step":
        return ""
    a, b = chosen[0], chosen[-1]
    if names is not None:
        first, last = names[a], names[b]
    elif np.issubdtype(x.dtype, np.datetime64):
        first, last = (np.datetime_as_string(x[i], unit="auto") for i in (a, b))
    else:
        first, last = f"{x[a]:.6g}", f"{x[b]:.6g}"
    text = f": {first}" if a == b else f": {first} to {last}"
    return text + (f" {unit}" if unit and names is None and x.dtype.kind == "f" else "")


def time_axis(
    times: Sequence, steps: np.ndarray, prefer: str = "labels", unit: str | None = None
) -> tuple[np.ndarray, str, list[str] | None]:
    """(x positions, axis label, tick names) for plotting against the time labels.

    Increasing numbers are their own positions; increasing ISO dates (strings such as
    '2024-01-01T06:00') are datetime64 positions; any other labels sit at their steps, the
    ticks named by their display labels. Labels that are the step numbers (and have no
    `unit`), or `prefer` "steps", give an axis named 'step'; numbers with a unit, 'time (s)'.
    """
    labels = list(times)
    steps = np.asarray(steps)
    if check_prefer(prefer) == "steps" or not has_labels([int(s) for s in steps], labels, unit):
        return steps.astype(np.float64), "step", None
    if all(isinstance(t, int | float) and not isinstance(t, bool) for t in labels):
        x = np.asarray(labels, np.float64)
        if np.all(np.diff(x) > 0):
            return x, f"time ({unit})" if unit else "time", None
    elif all(isinstance(t, str) for t in labels):
        dates = _dates(labels)
        if dates is not None and np.all(np.diff(dates) > np.timedelta64(0, "s")):
            return dates, "time", None
    return steps.astype(np.float64), "time", display_labels(list(steps), labels, unit=unit)


def _dates(labels: list[str]) -> np.ndarray | None:
    """The labels as datetime64 when every one is an ISO date (YYYY-MM...), else None."""
    if not all(len(t) >= 7 and t[4:5] == "-" and t[:4].isdigit() for t in labels):
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # numpy warns on time zones: keep them as names
            dates = np.array(labels, dtype="datetime64[ns]")
    except (ValueError, TypeError, Warning):
        return None
    return None if np.isnat(dates).any() else dates


def _label_ticks(ax, names: list[str]) -> None:
    """Ticks at whole steps, named by the steps' time labels."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    def name(v: float, _pos: int) -> str:
        i = round(v)
        return names[i] if abs(v - i) < 1e-6 and 0 <= i < len(names) else ""

    ax.xaxis.set_major_locator(MaxNLocator(nbins=8, integer=True))
    ax.xaxis.set_major_formatter(FuncFormatter(name))
    if max(len(n) for n in names) > 6:
        ax.tick_params(axis="x", labelrotation=30)
