"""The public integration call: a series and a window in, a Chronovolume out.

`integrate` validates everything at the edge (selection, mode, order, TFs,
enhancement), then integrates the window slab by slab in z (with a one-voxel
halo when enhancement needs gradients) and finalises once for the whole
volume. The engine computes each slab; ``numpy`` is the reference.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import reference
from .chronovolume import Chronovolume
from .data.bricks import slabs
from .data.series import TimeSeries
from .engine import get_engine
from .engine.memory import aligned_empty
from .enhance import Enhance
from .errors import InvalidParameterError
from .progress import track
from .selection import Selection, parse_selection
from .spec import IntegrationSpec, resolve_order
from .tf import DataTF, TFSetting, TimeTF


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
    engine: str | object = "opencl",
    device: str | None = None,
    slab: int | None = None,
    progress: bool = False,
    **spec_args: object,
) -> Chronovolume:
    """Integrate the selected steps of `series` into a Chronovolume.

    `window` is 't0:t1[:stride]', a list of steps, a slice or a Selection (default:
    every step). Either pass a ready `spec`, or the arguments of `make_spec`
    (tf=, data_tf=, time_tf=, order=, enhance=, threshold=, normalize=).
    `engine` is ``opencl`` (default; `device` picks one, see `chronocl devices`),
    ``numpy`` (the reference) or an engine object. `slab` sets the z rows per brick
    (default: as many as fit the engine's brick size).
    """
    if spec is None:
        spec = make_spec(mode, **spec_args)  # type: ignore[arg-type]
    elif spec_args:
        raise InvalidParameterError("pass either spec= or the integration arguments, not both")
    selection = parse_selection(window, series.n_steps)
    order = resolve_order(spec.order, selection)
    eng = get_engine(engine, device) if isinstance(engine, str) else engine
    positions = spec.time_tf.positions_of(selection.steps, series.n_steps)
    value_range = spec.data_tf.value_range or (series.vmin, series.vmax)

    nz, ny, nx = series.volume_shape
    halo = 1 if spec.enhance.needs_gradient else 0
    row_bytes = selection.width * ny * nx * series.dtype.itemsize
    fit = eng.max_brick_bytes // max(1, row_bytes) - 2 * halo
    if fit < 1:
        most = max(1, eng.max_brick_bytes // ((1 + 2 * halo) * ny * nx * series.dtype.itemsize))
        raise InvalidParameterError(
            f"one z-row of a {selection.width}-step window needs "
            f"{(1 + 2 * halo) * row_bytes / 2**20:.0f} MB but the engine holds at most "
            f"{eng.max_brick_bytes / 2**20:.0f} MB per brick; use a window of at most {most} steps"
        )
    slab = fit if slab is None else min(slab, fit)
    parts = slabs(nz, slab, halo)

    rgba = aligned_empty((nz, ny, nx, 4), np.float32)
    t_index = aligned_empty((nz, ny, nx), np.int32) if spec.has_t_index else None
    final = True
    # Double buffering: the next brick is read while the engine integrates this one.
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="chronocl-read") as reader:
        pending = reader.submit(series.read_brick, selection.steps, parts[0].r0, parts[0].r1)
        for i, s in enumerate(track(parts, len(parts), "integrating bricks", progress)):
            brick = pending.result()
            if i + 1 < len(parts):
                nxt = parts[i + 1]
                pending = reader.submit(series.read_brick, selection.steps, nxt.r0, nxt.r1)
            # z is the outermost axis, so a slab of the output is a contiguous view.
            out = (rgba[s.z0 : s.z1], None if t_index is None else t_index[s.z0 : s.z1])
            _, final = eng.accumulate(
                brick, s.crop, selection.steps, positions, order, spec, value_range, out
            )
    if not final:
        rgba = reference.finalize(reference.Partial(rgba, t_index), positions, spec)
    name = getattr(eng, "name", type(eng).__name__)
    return Chronovolume(rgba, t_index, _metadata(series, selection, spec, value_range, name))


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
