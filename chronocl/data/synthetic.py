"""Deterministic synthetic time-varying scalar fields for the demo and the tests.

Woodring & Shen (2003) show chronovolumes of a turbulent *vortex* data set (tube and
ring shaped features that move, twist and merge) and of a *jet* (a plume that
advances and spreads). Those data sets are not freely available, so this module
builds smooth analytic stand-ins in their spirit:

* ``vortex``: Gaussian-profile vortex rings that travel along curved paths, tilt,
  spin and grow; two of them approach each other and merge into one ring at the
  end; a twisting vortex tube precesses beside them.
* ``jet``: a round jet entering through the x = -1 face whose front crosses the
  box over time, widening downstream, with swirling ripples and "puffs" that
  grow with distance from the inlet.

Time is normalised as ``tau = t / max(n_steps - 1, 1)``, so any number of steps
spans the same motion. Each axis of the box is normalised to [-1, 1] (voxel
centres), so any shape works and features stay inside the box; a non-cubic box
stretches the features with it. Values are float32 in [0, 1], background 0 and
features near 1. ``seed`` only changes smooth parameters (phases, small offsets
of paths and tilts), never adds voxel noise, and equal inputs give bit-identical
outputs, on any machine (every transcendental function is evaluated in float64 and rounded
once to float32: `chronocl.data.synthetic_shapes`, which holds the shared building blocks).
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.data.synthetic_shapes import (
    CUT,
    box_axis,
    f64,
    frame,
    gauss,
    index_range,
    union,
    unit,
)

DATASETS: dict[str, str] = {
    "vortex": "vortex rings and a twisting tube that move, tilt, spin, grow and merge",
    "jet": "a swirling jet from the x = -1 face whose front advances and spreads across the box",
}

_F = np.float32
# The jet's profile is 2 ** -(distance / half width) ** 2, cut to exactly 0 like `gauss`.
_JET_CUT = 4.0
_JET_FLOOR = float(2.0 ** -(_JET_CUT**2))


def _check_int(value: object, what: str, fix: str) -> int:
    if isinstance(value, bool):
        raise InvalidParameterError(f"{what} must be an integer, got {value!r}; {fix}")
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise InvalidParameterError(f"{what} must be an integer, got {value!r}; {fix}") from None


def _validate(
    name: str, n_steps: int, shape_zyx: tuple[int, int, int], seed: int
) -> tuple[int, tuple[int, int, int], int]:
    if not isinstance(name, str) or name not in DATASETS:
        known = ", ".join(sorted(DATASETS))
        raise UnknownNameError(f"unknown synthetic data set {name!r}; known names: {known}")
    n_steps = _check_int(n_steps, "n_steps", "give the number of time steps, e.g. 20")
    if n_steps < 1:
        raise InvalidParameterError(f"n_steps must be at least 1, got {n_steps}; e.g. use 20")
    try:
        dims = tuple(shape_zyx)
    except TypeError:
        dims = ()
    if len(dims) != 3:
        raise InvalidParameterError(
            f"shape_zyx must have 3 entries (Z, Y, X), got {shape_zyx!r}; e.g. (64, 64, 64)"
        )
    shape = tuple(_check_int(d, "each shape_zyx entry", "e.g. (64, 64, 64)") for d in dims)
    if min(shape) < 1:
        raise InvalidParameterError(
            f"every shape_zyx entry must be at least 1, got {shape}; e.g. (64, 64, 64)"
        )
    seed = _check_int(seed, "seed", "use a non-negative integer such as 0")
    if seed < 0:
        raise InvalidParameterError(f"seed must be non-negative, got {seed}; e.g. use 0")
    return n_steps, shape, seed  # type: ignore[return-value]


# ---------------------------------------------------------------------------- vortex


@dataclass(frozen=True)
class _Ring:
    """A vortex ring's motion; vectors are (x, y, z) in box coordinates, s in [0, 1]."""

    c0: tuple[float, float, float]  # centre at the start
    c1: tuple[float, float, float]  # centre at the end
    bend: tuple[float, float, float]  # the path bulges by this much half way
    n0: tuple[float, float, float]  # normal at the start
    n1: tuple[float, float, float]  # normal at the end
    r0: float  # ring radius at the start ...
    r1: float  # ... and at the end
    s0: float  # core width (Gaussian sigma) at the start ...
    s1: float  # ... and at the end
    spin: float  # turns of the ring about its normal (moves the wobble and the bright spots)


def _ring_field(
    out: np.ndarray,
    axes: tuple[np.ndarray, np.ndarray, np.ndarray],
    ring: _Ring,
    tau: float,
    phase: np.ndarray,
    jitter: np.ndarray,
) -> None:
    z, y, x = axes
    c = (
        (1 - tau) * np.array(ring.c0)
        + tau * np.array(ring.c1)
        + 4 * tau * (1 - tau) * np.array(ring.bend)
        + jitter * np.sin(np.pi * tau)
    )
    e1, e2, normal = frame(np.array(ring.n0), np.array(ring.n1), tau)
    radius = ring.r0 + (ring.r1 - ring.r0) * tau
    sigma = ring.s0 + (ring.s1 - ring.s0) * tau
    wobble = 0.1 * radius  # amplitude of the 3-lobed wobble of the ring's radius
    reach = radius + wobble + CUT * sigma
    sl = (
        index_range(c[2] - reach, c[2] + reach, z.size),
        index_range(c[1] - reach, c[1] + reach, y.size),
        index_range(c[0] - reach, c[0] + reach, x.size),
    )
    if any(s.start >= s.stop for s in sl):
        return
    dz = (z[sl[0]] - _F(c[2]))[:, None, None]
    dy = (y[sl[1]] - _F(c[1]))[None, :, None]
    dx = (x[sl[2]] - _F(c[0]))[None, None, :]
    u = dx * _F(e1[0]) + dy * _F(e1[1]) + dz * _F(e1[2])
    v = dx * _F(e2[0]) + dy * _F(e2[1]) + dz * _F(e2[2])
    w = dx * _F(normal[0]) + dy * _F(normal[1]) + dz * _F(normal[2])
    rho = f64(np.hypot, u, v)
    azim = f64(np.arctan2, v, u)
    turn = _F(2 * np.pi * ring.spin * tau)
    rr = radius + wobble * f64(np.sin, 3 * azim + (turn + _F(phase[0])))
    rho -= rr
    d2 = rho * rho
    d2 += w * w
    f = gauss(d2, sigma)
    # Brighter and dimmer stretches along the ring, turning with it, make the spin visible.
    f *= _F(0.85) + _F(0.15) * f64(np.cos, 2 * azim + (turn + _F(phase[1])))
    union(out, sl, f)


def _vortex_rings() -> tuple[_Ring, ...]:
    merge = (0.15, 0.05, 0.05)  # rings A and B end up here, coaxial along n_merge
    n_merge = tuple(unit(np.array([0.3, 1.0, 0.4])))
    gap = 0.05  # half their remaining separation along the common axis at the end
    return (
        _Ring(  # A: from the lower left, tilting to the shared axis, growing
            c0=(-0.6, -0.55, -0.45),
            c1=tuple(np.array(merge) - gap * np.array(n_merge)),
            bend=(-0.1, 0.15, 0.2),
            n0=(1.0, 0.2, 0.3),
            n1=n_merge,
            r0=0.17,
            r1=0.3,
            s0=0.045,
            s1=0.07,
            spin=0.5,
        ),
        _Ring(  # B: from the lower right front, meets A
            c0=(0.6, -0.5, 0.5),
            c1=tuple(np.array(merge) + gap * np.array(n_merge)),
            bend=(0.25, 0.05, -0.05),
            n0=(-0.6, 0.5, -0.6),
            n1=n_merge,
            r0=0.15,
            r1=0.28,
            s0=0.04,
            s1=0.07,
            spin=-0.5,
        ),
        _Ring(  # C: a lone ring rising along y on the far left, tumbling as it goes
            c0=(-0.55, -0.2, 0.5),
            c1=(-0.45, 0.6, -0.2),
            bend=(-0.15, 0.0, 0.1),
            n0=(0.0, 1.0, 0.2),
            n1=(1.0, 0.1, -0.6),
            r0=0.14,
            r1=0.22,
            s0=0.04,
            s1=0.055,
            spin=0.75,
        ),
    )


def _tube_field(
    out: np.ndarray,
    axes: tuple[np.ndarray, np.ndarray, np.ndarray],
    tau: float,
    phase: np.ndarray,
) -> None:
    """A helical vortex tube along z near the back corner that precesses and drifts."""
    z, y, x = axes
    cx0, cy0 = 0.6 - 0.2 * tau, 0.5 + 0.15 * tau
    amp = 0.18 + 0.04 * tau
    sigma = 0.05 + 0.015 * tau
    reach = amp + CUT * sigma
    sl = (
        index_range(-0.95, 0.95, z.size),
        index_range(cy0 - reach, cy0 + reach, y.size),
        index_range(cx0 - reach, cx0 + reach, x.size),
    )
    if any(s.start >= s.stop for s in sl):
        return
    zz = z[sl[0]].astype(np.float64)
    # The helix's phase along z advances by half a turn over the series: the tube
    # precesses about its axis, so the first and last steps lie apart.
    psi = 0.8 * np.pi * zz + np.pi * tau + phase[0]
    cx = (cx0 + amp * np.cos(psi)).astype(_F)[:, None, None]
    cy = (cy0 + amp * np.sin(psi)).astype(_F)[:, None, None]
    dx = x[sl[2]][None, None, :] - cx
    dy = y[sl[1]][None, :, None] - cy
    f = gauss(dx * dx + dy * dy, sigma)
    # Taper the ends smoothly instead of cutting the tube at the box faces.
    ends = np.clip((0.85 - np.abs(zz)) / 0.2, 0.0, 1.0)
    f *= (ends * ends * (3 - 2 * ends)).astype(_F)[:, None, None]
    union(out, sl, f)


def _vortex(shape: tuple[int, int, int], tau: float, rng: np.random.Generator) -> np.ndarray:
    axes = (box_axis(shape[0]), box_axis(shape[1]), box_axis(shape[2]))
    out = np.zeros(shape, dtype=_F)
    rings = _vortex_rings()
    phases = rng.uniform(0.0, 2 * np.pi, size=(len(rings) + 1, 2))
    jitters = rng.uniform(-0.06, 0.06, size=(len(rings), 3))
    for ring, phase, jitter in zip(rings, phases[:-1], jitters, strict=True):
        _ring_field(out, axes, ring, tau, phase, jitter)
    _tube_field(out, axes, tau, phases[-1])
    return out


# ------------------------------------------------------------------------------- jet


def _jet(shape: tuple[int, int, int], tau: float, rng: np.random.Generator) -> np.ndarray:
    z, y, x = box_axis(shape[0]), box_axis(shape[1]), box_axis(shape[2])
    p = rng.uniform(0.0, 2 * np.pi, size=6)
    yc0, zc0 = rng.uniform(-0.05, 0.05, size=2)

    # The head is a half ellipsoid of length `cap` whose tip (value 0.5 on the axis)
    # moves from near the inlet to near the far face.
    cap = 0.25
    front = -0.8 + 1.65 * tau
    base = front - cap  # where the head's rounded cap begins
    out = np.zeros(shape, dtype=_F)
    xs = index_range(-1.0, base + _JET_CUT * cap, x.size)
    if xs.start >= xs.stop:
        return out
    xx = x[xs].astype(np.float64)
    s = xx + 1.0  # distance from the inlet, 0..2
    # Everything that depends on x only is computed on the 1-D axis (cheap).
    flow = 6.0 * tau  # how far the pattern has been carried downstream (radians)
    amp = 0.02 * s + 0.04 * s * s  # meander of the centre line grows downstream
    yc = yc0 + amp * np.sin(3.0 * s - flow + p[0])
    zc = zc0 + amp * np.cos(2.6 * s - flow + p[1])
    # Half width at half maximum: narrow at the inlet, spreading with distance,
    # with a mushroom-like bulge at the head.
    bulge = 1.0 + 0.35 * np.exp(-(((xx - base) / 0.2) ** 2))
    grow = np.clip(s / 1.2, 0.0, 1.0)  # the instabilities grow downstream
    ripple = 1.0 + 0.2 * grow * np.sin(9.0 * s - 2.0 * flow + p[4])  # varicose ripples
    width = (0.08 + 0.1 * s) * bulge * ripple
    swirl = 0.4 * grow  # depth of the 3 swirling lobes
    twist = 4.0 * s - 2.0 * flow + p[2]
    # Brighter and dimmer puffs carried downstream, full strength at the inlet.
    puffs = 1.0 - 0.15 * grow * (1.0 + np.sin(7.0 * s - 2.0 * flow + p[3]))
    tip = (np.maximum(xx - base, 0.0) / cap) ** 2

    dy = y[None, :, None] - yc.astype(_F)[None, None, :]
    dz = z[:, None, None] - zc.astype(_F)[None, None, :]
    r2 = dy * dy + dz * dz
    # cos(3 theta - twist) from dy, dz without an arctan: 3 swirling lobes.
    inv_r = 1 / np.sqrt(r2 + _F(1e-12))
    c = dy * inv_r
    sn = dz * inv_r
    cos3 = c * (4 * c * c - 3)
    sin3 = sn * (3 - 4 * sn * sn)
    lobes = cos3 * np.cos(twist).astype(_F) + sin3 * np.sin(twist).astype(_F)
    lobes *= swirl.astype(_F)
    lobes += 1
    w = lobes * width.astype(_F)
    r2 /= w * w
    r2 += tip.astype(_F)
    f = f64(np.exp2, -r2)
    # Shift and rescale so the field reaches exactly 0 where the crop above cuts it.
    f -= _F(_JET_FLOOR)
    f *= (puffs / (1.0 - _JET_FLOOR)).astype(_F)
    out[:, :, xs] = f
    return np.clip(out, 0, 1, out=out)


_BUILDERS: dict[str, Callable[[tuple[int, int, int], float, np.random.Generator], np.ndarray]] = {
    "vortex": _vortex,
    "jet": _jet,
}


def step(
    name: str, t: int, n_steps: int, shape_zyx: tuple[int, int, int], seed: int = 0
) -> np.ndarray:
    """Time step `t` of `n_steps` of data set `name`: float32 (Z, Y, X) in [0, 1]."""
    n_steps, shape, seed = _validate(name, n_steps, shape_zyx, seed)
    t = _check_int(t, "t", f"use a step between 0 and {n_steps - 1}")
    if not 0 <= t < n_steps:
        raise InvalidParameterError(
            f"time step t={t} is outside [0, {n_steps}); use a step between 0 and {n_steps - 1}"
        )
    tau = t / max(n_steps - 1, 1)
    # The data set's index in the seed keeps the two data sets' randomness unrelated.
    rng = np.random.default_rng([seed, list(DATASETS).index(name)])
    return _BUILDERS[name](shape, tau, rng)


def steps(
    name: str, n_steps: int, shape_zyx: tuple[int, int, int], seed: int = 0
) -> Iterator[np.ndarray]:
    """Yield step(name, t, n_steps, shape_zyx, seed) for t in range(n_steps).

    The arguments are checked at the call, not at the first ``next``.
    """
    n_steps, shape, seed = _validate(name, n_steps, shape_zyx, seed)
    return (step(name, t, n_steps, shape, seed) for t in range(n_steps))
