"""The public integration call: a series and a window in, a Chronovolume out.

`integrate` validates everything at the edge (selection, mode, order, TFs,
enhancement), then integrates the window slab by slab in z (with a one-voxel
halo when enhancement needs gradients) and finalises once for the whole
volume. The engine computes each slab; ``numpy`` is the reference.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from . import reference
from .chronovolume import Chronovolume
from .data.bricks import slabs
from .data.series import TimeSeries
from .enhance import Enhance
from .errors import InvalidParameterError, UnknownNameError
from .progress import track
from .selection import Selection, parse_selection
from .spec import IntegrationSpec, resolve_order
from .tf import DataTF, TFSetting, TimeTF

ENGINES = ("numpy",)
SLAB_BYTES = 64 * 2**20


def make_spec(
    mode: str = "alpha",
    *,
    tf: TFSetting | str | os.PathLike | None = None,
    data_tf: DataTF | None = None,
    time_tf: TimeTF | str | None = None,
    order: str | Sequence[int] = "forward",
    enhance: Enhance | str | None = None,
    threshold: float = 0.0,
    normalize: str = "time",
) -> IntegrationSpec:
    """Build a validated IntegrationSpec; explicit data_tf / time_tf override those in `tf`."""
    setting = tf if isinstance(tf, TFSetting) else TFSetting.load(tf) if tf else TFSetting()
    if isinstance(time_tf, str):
        time_tf = TimeTF.preset(time_tf)
    if isinstance(enhance, str):
        enhance = Enhance(enhance)
    return IntegrationSpec(
        mode=mode,
        order=order if isinstance(order, str) else tuple(order),
        data_tf=data_tf or setting.data_tf,
        time_tf=time_tf or setting.time_tf,
        enhance=enhance or Enhance(),
        threshold=threshold,
        normalize=normalize,
    )


def integrate(
    series: TimeSeries,
    window: object = None,
    mode: str = "alpha",
    *,
    spec: IntegrationSpec | None = None,
    engine: str = "numpy",
    slab: int | None = None,
    progress: bool = False,
    **spec_args: object,
) -> Chronovolume:
    """Integrate the selected steps of `series` into a Chronovolume.

    `window` is 't0:t1[:stride]', a list of steps, a slice or a Selection (default:
    every step). Either pass a ready `spec`, or the arguments of `make_spec`
    (tf=, data_tf=, time_tf=, order=, enhance=, threshold=, normalize=).
    `slab` sets the z rows integrated at once (default: as many as fit 64 MB).
    """
    if engine not in ENGINES:
        raise UnknownNameError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")
    if spec is None:
        spec = make_spec(mode, **spec_args)  # type: ignore[arg-type]
    elif spec_args:
        raise InvalidParameterError("pass either spec= or the integration arguments, not both")
    selection = parse_selection(window, series.n_steps)
    order = resolve_order(spec.order, selection)
    positions = spec.time_tf.positions_of(selection.steps, series.n_steps)
    value_range = spec.data_tf.value_range or (series.vmin, series.vmax)

    nz, ny, nx = series.volume_shape
    if slab is None:
        slab = max(1, SLAB_BYTES // max(1, selection.width * ny * nx * 4))
    halo = 1 if spec.enhance.needs_gradient else 0
    parts = slabs(nz, slab, halo)

    rgba = np.zeros((nz, ny, nx, 4), dtype=np.float64)
    t_index = np.full((nz, ny, nx), -1, dtype=np.int32) if spec.has_t_index else None
    for s in track(parts, len(parts), "integrating slabs", progress and len(parts) > 1):
        u = series.normalized(selection.steps, s.r0, s.r1, value_range)
        partial = reference.accumulate(u, selection.steps, positions, order, spec)
        rgba[s.z0 : s.z1] = partial.rgba[s.crop]
        if t_index is not None:
            t_index[s.z0 : s.z1] = partial.t_index[s.crop]
    out = reference.finalize(reference.Partial(rgba, t_index), positions, spec)
    return Chronovolume(out, t_index, _metadata(series, selection, spec, value_range, engine))


def _metadata(
    series: TimeSeries,
    selection: Selection,
    spec: IntegrationSpec,
    value_range: tuple[float, float],
    engine: str,
) -> dict:
    dz, dy, dx = series.spacing
    return {
        "dataset": series.source or (str(series.path) if series.path else ""),
        "selection": {"steps": list(selection.steps), "n_steps": selection.n_steps},
        "time_labels": [series.times[s] for s in selection.steps],
        "spec": spec.to_dict(),
        "spacing": {"x": dx, "y": dy, "z": dz},
        "value_range": [float(value_range[0]), float(value_range[1])],
        "engine": engine,
    }
