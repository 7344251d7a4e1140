"""Whether raw bytes read as data under the type and byte order given, and which reading they
clearly are otherwise: a wrong --endian or --dtype named before a store of junk is written.

A misread float step holds NaN, infinities or values beyond 1e30; a misread integer or float
step is rough: its x neighbours (consecutive values) jump by about as much as its values spread,
where a field a simulation or a microscope writes changes little from one voxel to the next.
`roughness` measures that on samples spread over the step: the mean step between neighbours
(both non-zero, capped at the spread) over the spread of the non-zero values (1st to 99th
percentile; zeros are left out so empty space, which reads as zeros in every type, neither
helps nor hides a misread). Measured on the vortex, plume and Gray-Scott fields as float32,
float64, uint16, int16 and uint8 (tests/test_ingest.py): read right 0.01-0.11; read in another
type or byte order 0.3-0.9, or implausible, but a 16-bit step in the other byte order 0.16-0.34,
3-12 times its right reading; a float64 step read as float32 0.16 or implausible; uniform white
noise 0.32-0.43 however read (no reading is smooth: nothing is said). Zero-mean Gaussian noise
read as float64 pairs measures 0.06: a wide type maps the narrow values' magnitudes onto its
exponents, which squeezes them, so a wider reading must be smooth by ranks too
(`rank_roughness`). Over those fields in both byte orders, two sizes, as read and misread in
every other type and order (tests/test_ingest.py and the review's Gaussian cases): no right
reading refused, no wrong reading named, 884 of 1134 misreads named (the rest: 16-bit types
that read the same values, float32 read as float64 pairs, noise, sparse fields read wider).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chronocl.core.tuning import TUNING
from chronocl.data.metadata import SUPPORTED_DTYPES

# The check's thresholds (a value beyond which floats are misread, how smooth is data, how much
# smoother another reading must be) are TUNING's misread_* fields, measured together.
ENDIANS = ("little", "big")
SAMPLES, RUN = 64, 4096  # runs of consecutive values sampled per step


@dataclass(frozen=True)
class Reading:
    """A type and byte order to read a raw step in, with the dims that fit its bytes."""

    dtype: str
    endian: str
    dims: tuple[int, int, int]

    def flags(self, given: Reading) -> str:
        """The command-line flags that differ from `given`."""
        parts = []
        if self.dtype != given.dtype:
            parts.append(f"--dtype {self.dtype}")
        if self.endian != given.endian:
            parts.append(f"--endian {self.endian}")
        if self.dims != given.dims:
            parts.append(f"--dims {' '.join(map(str, self.dims))}")
        return " ".join(parts)

    def numpy(self) -> np.dtype:
        return np.dtype(self.dtype).newbyteorder("<" if self.endian == "little" else ">")


def roughness(values: np.ndarray) -> float | None:
    """How rough the flat step `values` is (see the module docstring); None where it cannot be
    data (NaN, infinite or beyond 1e30), NaN where there is nothing to judge (too few non-zero
    neighbours, or one value)."""
    n = values.size
    if n > SAMPLES * RUN:
        starts = np.linspace(0, n - RUN, SAMPLES).astype(np.int64)
        parts = [values[s : s + RUN] for s in starts]
    else:
        parts = [values]
    with np.errstate(all="ignore"):
        parts = [np.asarray(p).astype(np.float64) for p in parts]
    flat = np.concatenate(parts)
    if flat.size == 0:
        return float("nan")
    beyond = TUNING.misread_beyond
    if values.dtype.kind == "f" and not (np.isfinite(flat).all() and np.abs(flat).max() <= beyond):
        return None
    steps = np.concatenate([np.abs(np.diff(p))[(p[1:] != 0) & (p[:-1] != 0)] for p in parts])
    if steps.size < TUNING.misread_min_pairs:
        return float("nan")
    lo, hi = np.percentile(flat[flat != 0], [1, 99])
    spread = hi - lo
    if spread <= 0:
        return float("nan")  # one value (a constant, or a pattern read as pairs): no say
    return float(np.mean(np.minimum(steps, spread)) / spread)


def rank_roughness(values: np.ndarray) -> float:
    """`roughness` on the ranks of the non-zero values instead of the values: blind to a
    monotone squeeze (a wide type reading the bits of a narrow one maps the narrow values'
    magnitudes onto its exponents, and white noise read so looks smooth by value) but
    rougher on sparse fields (their non-zero neighbours lie at the edges)."""
    n = values.size
    starts = np.linspace(0, max(0, n - RUN), SAMPLES).astype(np.int64) if n > SAMPLES * RUN else [0]
    with np.errstate(all="ignore"):
        parts = [np.asarray(values[s : s + RUN] if n > SAMPLES * RUN else values, np.float64)
                 for s in starts]  # fmt: skip
    flat = np.concatenate(parts)
    order = np.sort(flat[flat != 0])
    steps = [
        np.abs(np.diff(np.searchsorted(order, p)))[(p[1:] != 0) & (p[:-1] != 0)] for p in parts
    ]
    pairs = np.concatenate(steps)
    if pairs.size < TUNING.misread_min_pairs:
        return float("nan")
    return float(np.mean(pairs) / order.size)


def readings(given: Reading, nbytes: int) -> list[Reading]:
    """Every other type and byte order whose whole values fill `nbytes` with the given x and y
    sizes (z scaled by the type's width)."""
    nx, ny, nz = given.dims
    width = np.dtype(given.dtype).itemsize
    out = []
    for dtype in SUPPORTED_DTYPES:
        size = np.dtype(dtype).itemsize
        if (nz * width) % size:
            continue
        dims = (nx, ny, nz * width // size)
        if nx * ny * dims[2] * size != nbytes:
            continue
        for endian in ENDIANS:
            if (dtype, endian) != (given.dtype, given.endian):
                if size == 1 and endian != ENDIANS[0]:
                    continue  # bytes have no order
                out.append(Reading(dtype, endian, dims))
    return out


def likelier_reading(raw: np.ndarray, given: Reading) -> tuple[Reading, str] | None:
    """(the reading the step's bytes `raw` (uint8) clearly are, why the given one is not) where
    another reads them as smooth data and the given one as implausible or several times rougher
    (a 16-bit step in the wrong byte order is only moderately rough: its low byte changes
    slowly too), or where a narrower type reads them as smooth data (a wide type then reads
    pairs of values, smooth as well); else None."""
    r_given = roughness(raw.view(given.numpy()))
    scores = {c: roughness(raw.view(c.numpy())) for c in readings(given, raw.size)}
    width = np.dtype(given.dtype).itemsize
    t = TUNING

    def smooth(c: Reading, bound: float) -> bool:
        r = scores[c]
        return r is not None and r < bound

    if r_given is None:
        found = [c for c in scores if smooth(c, t.misread_smooth)]
        why = f"values NaN, infinite or beyond {t.misread_beyond:.0e}".replace("e+", "e")
    elif r_given >= t.misread_smooth:  # not data-like: another reading that is, clearly smoother
        clearly = min(t.misread_smooth, r_given / t.misread_clearly)
        found = [c for c in scores if smooth(c, clearly)]
        # a wider one by ranks too: white noise read in a wider type looks smooth by value
        wider = {c for c in found if np.dtype(c.dtype).itemsize > width}
        found = [
            c
            for c in found
            if c not in wider or rank_roughness(raw.view(c.numpy())) < t.misread_smooth
        ]
        why = "rough values"
    else:  # smooth, but a reading as wide is several times smoother, or a narrower one smooth
        # (a wider type reads pairs of smooth values as smooth: never suggested here)
        size = {c: np.dtype(c.dtype).itemsize for c in scores}
        smoother = r_given / t.misread_smoother
        found = [c for c in scores if size[c] == width and smooth(c, smoother)]
        found += [c for c in scores if size[c] < width and smooth(c, t.misread_narrower_smooth)]
        why = "values rougher than another reading's"
    if not found:
        return None
    # the narrowest type first (a wider one can read pairs of smooth values as smooth),
    # then the given type, then the smoothest
    best = min(
        found,
        key=lambda c: (np.dtype(c.dtype).itemsize, c.dtype != given.dtype, scores[c]),
    )
    return best, why
