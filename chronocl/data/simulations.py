"""Small simulations whose runs look like what users bring: data the defaults must show.

The analytic data sets (`chronocl.data.synthetic`) are bright from the first step. Real runs
are not: a smoke plume starts faint and brightens as its source keeps feeding it, and a
reaction–diffusion front starts as a seed in one corner and spreads. These solvers make such
runs on the fly (for the demo gallery, the tests and the benches):

* ``plume``: smoke advected upward (+y) and diffused, fed by a source near the bottom whose
  strength grows over the run, so the first steps are a faint fraction of the last;
* ``gray-scott``: the Gray–Scott reaction–diffusion model (the concentration v), seeded in
  the (x, y, z) = (0, 0, 0) corner, whose pattern front spreads through the box.

Both are explicit finite-difference schemes in float32 with zero-flux borders, deterministic
(elementwise arithmetic only). Arrays are (T, Z, Y, X), x fastest.
"""

from __future__ import annotations

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError

SIMULATIONS: dict[str, str] = {
    "plume": "smoke rising from a source that strengthens over the run (faint early steps)",
    "gray-scott": "a Gray–Scott reaction–diffusion front spreading from the (0, 0, 0) corner",
}
_F = np.float32


def simulate(name: str, shape_zyx: tuple[int, int, int] = (64, 64, 64), n_steps: int = 40):
    """The run `name` (one of SIMULATIONS) on a (Z, Y, X) grid: float32 (n_steps, Z, Y, X)."""
    if name not in SIMULATIONS:
        raise UnknownNameError(f"unknown simulation {name!r}; choose {', '.join(SIMULATIONS)}")
    shape = tuple(int(n) for n in shape_zyx)
    if len(shape) != 3 or min(shape) < 8 or not 1 <= int(n_steps) <= 10_000:
        raise InvalidParameterError(
            f"a simulation needs a (Z, Y, X) grid of at least 8 per axis and 1..10000 steps, "
            f"got {shape_zyx} and {n_steps}"
        )
    return (_plume if name == "plume" else _gray_scott)(shape, int(n_steps))


def _laplacian(a: np.ndarray) -> np.ndarray:
    """The 7-point Laplacian with zero-flux (mirrored) borders, grid spacing 1."""
    p = np.pad(a, 1, mode="edge")
    return (
        p[:-2, 1:-1, 1:-1]
        + p[2:, 1:-1, 1:-1]
        + p[1:-1, :-2, 1:-1]
        + p[1:-1, 2:, 1:-1]
        + p[1:-1, 1:-1, :-2]
        + p[1:-1, 1:-1, 2:]
        - _F(6) * a
    )


def _grid(shape: tuple[int, int, int]) -> tuple[np.ndarray, ...]:
    """(z, y, x) voxel-centre coordinates in [0, 1], broadcastable."""
    z, y, x = (((np.arange(n) + 0.5) / n).astype(_F) for n in shape)
    return z[:, None, None], y[None, :, None], x[None, None, :]


def _plume(shape: tuple[int, int, int], n_steps: int) -> np.ndarray:
    ny = shape[1]
    z, y, x = _grid(shape)
    source = np.exp(-(((x - 0.5) ** 2 + (z - 0.5) ** 2) / 0.006 + (y - 0.1) ** 2 / 0.003))
    source = source.astype(_F)
    c = np.zeros(shape, _F)
    out = np.empty((n_steps, *shape), _F)
    lift = _F(0.35)  # voxels per iteration upward, with a sideways sway
    per_step = max(1, round(0.9 * ny / n_steps / float(lift)))
    for t in range(n_steps):
        for i in range(per_step):
            tau = (t * per_step + i) / (n_steps * per_step)
            # Upwind advection along +y (the flow is upward), a slow sway in x, diffusion.
            up = c - np.concatenate([c[:, :1], c[:, :-1]], axis=1)
            sway = _F(0.08 * np.sin(6.0 * tau))
            side = c - np.roll(c, 1 if sway > 0 else -1, axis=2)
            c = c + _F(0.08) * _laplacian(c) - lift * up - abs(sway) * side
            c += _F(0.15 + 0.3 * tau) * source
        out[t] = c
    return out


def _gray_scott(shape: tuple[int, int, int], n_steps: int) -> np.ndarray:
    nz, ny, nx = shape
    u = np.ones(shape, _F)
    v = np.zeros(shape, _F)
    seed = tuple(slice(0, max(3, n // 8)) for n in shape)
    u[seed], v[seed] = _F(0.5), _F(0.25)
    du, dv, feed, kill = _F(0.16), _F(0.08), _F(0.035), _F(0.06)
    out = np.empty((n_steps, *shape), _F)
    # Enough iterations for the front (about 0.03 voxel per iteration) to cross the box.
    per_step = max(1, round((nz**2 + ny**2 + nx**2) ** 0.5 / 0.03 / n_steps))
    for t in range(n_steps):
        for _ in range(per_step):
            uvv = u * v * v
            u, v = (
                u + du * _laplacian(u) - uvv + feed * (_F(1) - u),
                v + dv * _laplacian(v) + uvv - (feed + kill) * v,
            )
        out[t] = v
    return out
