"""Nice-number ticks for legends and colour bars: multiples of 1, 2 or 5 times a power of ten.

A legend over steps 3..27 is read at 5, 10, 15, 20, 25, not at whichever steps happened to fit
(2, 8, 16, 26); a colour bar over 0..0.83 at 0, 0.2, 0.4, 0.6, 0.8.
"""

from __future__ import annotations

import math

MANTISSAS = (1, 2, 5)


def nice_step(lo: float, hi: float, most: int, integer: bool = False) -> float:
    """The smallest 1-2-5 step whose multiples in [lo, hi] number at most `most` (at least one
    tick); `integer` keeps the step at 1 or more (step numbers)."""
    span = abs(hi - lo)
    most = max(1, int(most))
    if span == 0:
        return 1.0
    exponent = math.floor(math.log10(span / most))
    for e in range(exponent - 1, exponent + 3):
        for m in MANTISSAS:
            step = m * 10.0**e
            if integer and step < 1:
                continue
            if len(_indices(lo, hi, step)) <= most:
                return float(step)
    return float(10.0 ** (exponent + 3))


def multiples(lo: float, hi: float, step: float) -> list[float]:
    """The multiples of `step` in [lo, hi], in increasing order."""
    decimals = _decimals(step) + 1  # rounds away the float noise of k * step (0.3000...04)
    return [round(k * step, decimals) for k in _indices(lo, hi, step)]


def nice_ticks(lo: float, hi: float, most: int, integer: bool = False) -> list[float]:
    """The multiples of `nice_step` in [lo, hi], in increasing order."""
    return multiples(lo, hi, nice_step(lo, hi, most, integer))


def tick_text(value: float, step: float) -> str:
    """A tick's label with as many decimals as the step needs (0.2 -> '0.2', 5 -> '5')."""
    text = f"{value:.{_decimals(step) if step > 0 else 0}f}"
    return "0" if text.strip("-0.") == "" else text


def _indices(lo: float, hi: float, step: float) -> range:
    """k for each multiple k * step in [lo, hi]."""
    a, b = min(lo, hi), max(lo, hi)
    return range(math.ceil(a / step - 1e-9), math.floor(b / step + 1e-9) + 1)


def _decimals(step: float) -> int:
    """Decimals a multiple of `step` needs (0.2 -> 1, 0.05 -> 2, 5 -> 0)."""
    return max(0, -math.floor(math.log10(step) + 1e-9))
