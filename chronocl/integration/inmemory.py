"""The public integration call: a series and a window in, a Chronovolume out.

`integrate` validates everything at the edge (selection, mode, order, TFs,
enhancement), then integrates the window slab by slab in z (with a one-voxel
halo when enhancement needs gradients) and finalises once for the whole
volume. The engine computes each slab; ``numpy`` is the reference. Bricks come
from a `chronocl.data.bricks.BrickSource`: the series by default, or steps
already in memory (`integrate_bricks`). `prepare`, `engine_rows`, `integrate_brick`
and `integrate_slabs` are shared with the out-of-core run
(`chronocl.integration.runs.streaming`), which writes the slabs to a store instead.
`chronovolume_metadata` is what every chronovolume records, whichever path made it: a window
integrated here, slid (`chronocl.integration.interactive`) or streamed.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from chronocl import modes, reference
from chronocl.core.enhance import Enhance
from chronocl.core.errors import InvalidParameterError
from chronocl.core.interrupt import checkpoint
from chronocl.core.memory import recycled_empty
from chronocl.core.progress import track
from chronocl.core.selection import Selection, parse_selection
from chronocl.core.slab_sink import finished, listening
from chronocl.core.tf import FITTED, GLOBAL, DataTF, TFSetting, TimeTF
from chronocl.data.bricks import BrickSource, SeriesBricks, Slab, slabs
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.engine import get_engine
from chronocl.engine.base import Engine
from chronocl.engine.device_formats import with_device_format
from chronocl.integration.fit_range import window_range
from chronocl.integration.visibility import warn_invisible
from chronocl.integration.window_centres import window_centres
from chronocl.modes.base import Partial
from chronocl.modes.spec import IntegrationSpec, default_data_tf, resolve_order


def make_spec(
    mode: str = modes.DEFAULT,
    *,
    tf: TFSetting | str | os.PathLike | None = None,
    data_tf: DataTF | None = None,
    time_tf: TimeTF | str | None = None,
    order: str | Sequence[int] = "forward",
    enhance: Enhance | str | None = None,
    threshold: float | None = None,
    normalize: str = "time",
    value_range: tuple[float, float] | str | None = None,
) -> IntegrationSpec:
    """Build a validated IntegrationSpec; explicit data_tf / time_tf override those in `tf`.
    `value_range` replaces the data TF's (the mode's own TF where none is given): "window"
    (fitted to the window), "series" (the range recorded at ingest) or (lo, hi).
    With no time colours given (no time TF here or in `tf`, or only an opacity preset: hat,
    inverted-hat, constant) they follow the data TF: time as hue (rgb) for a grey or white
    one, as lightness for a coloured one such as a colour map (`TimeTF.for_data`)."""
    setting = tf if isinstance(tf, TFSetting) else TFSetting.load(tf) if tf else TFSetting()
    # No data TF given (here or in `tf`): None, the mode's own, and with it its threshold
    # (IntegrationSpec resolves both).
    data_tf = data_tf or (setting.data_tf if tf else None)
    if value_range is not None:
        if data_tf is None and threshold is None:  # the mode's own TF keeps its threshold
            threshold = modes.get(mode).default_threshold
        vr = GLOBAL if value_range == "series" else value_range
        data_tf = replace(data_tf or default_data_tf(mode), value_range=vr)
    if isinstance(time_tf, str):
        shape = time_tf in ("hat", "inverted-hat", "constant")  # an opacity: colours unchosen
        time_tf = TimeTF.preset(time_tf)
        if shape:
            points = (data_tf or default_data_tf(mode)).points
            time_tf = replace(time_tf, color=TimeTF.for_data(points).color)
    if isinstance(enhance, str):
        enhance = Enhance(enhance)
    return IntegrationSpec(
        mode=mode,
        order=order if isinstance(order, str) else tuple(order),
        data_tf=data_tf,
        time_tf=time_tf or setting.time_tf,  # None: IntegrationSpec takes TimeTF.for_data
        enhance=enhance or Enhance(),
        threshold=threshold,
        normalize=normalize,
    )


@dataclass(frozen=True)
class Job:
    """One validated integration: the series, its selection and spec, and what every slab shares."""

    series: TimeSeries
    selection: Selection
    spec: IntegrationSpec
    order: np.ndarray
    positions: np.ndarray
    value_range: tuple[float, float]

    @classmethod
    def of(
        cls,
        series: TimeSeries,
        selection: Selection,
        spec: IntegrationSpec,
        value_range: tuple[float, float],
    ) -> Job:
        """The job of `spec` over `selection`, with the order and time positions they imply."""
        return cls(
            series=series,
            selection=selection,
            spec=spec,
            order=resolve_order(spec.order, selection),
            positions=spec.time_tf.positions_of(selection.steps, series.n_steps),
            value_range=value_range,
        )

    @property
    def halo(self) -> int:
        """z rows read on each side of a slab: 1 when enhancement needs gradients."""
        return 1 if self.spec.enhance.needs_gradient else 0

    @property
    def row_bytes(self) -> int:
        """Bytes of one z-row of the window's brick (W, Y, X) as stored."""
        _, ny, nx = self.series.volume_shape
        return self.selection.width * ny * nx * self.series.dtype.itemsize

    def format_input(self) -> tuple:
        """What a device format is checked against (`device_formats.resolve_format`'s
        arguments after the name): the stored type, the value range, the mode and the data's
        range (max/min refuse a quantising that clips it)."""
        data = (self.series.vmin, self.series.vmax)
        return self.series.dtype, self.value_range, self.spec.mode, data

    def metadata(self, engine: str) -> dict:
        """The chronovolume metadata of this integration."""
        return chronovolume_metadata(
            self.series, self.selection, self.spec, self.value_range, engine
        )


def prepare(
    series: TimeSeries,
    window: object = None,
    mode: str = modes.DEFAULT,
    spec: IntegrationSpec | None = None,
    spec_args: dict | None = None,
) -> Job:
    """Validate window, spec (or the arguments of `make_spec`) and order into a Job."""
    if spec is None:
        spec = make_spec(mode, **(spec_args or {}))  # type: ignore[arg-type]
    elif spec_args:
        raise InvalidParameterError("pass either spec= or the integration arguments, not both")
    return window_job(series, parse_selection(window, series.n_steps, series.times), spec)


def chronovolume_metadata(
    series: TimeSeries,
    selection: Selection,
    spec: IntegrationSpec,
    value_range: tuple[float, float],
    engine: str,
) -> dict:
    """The metadata of `selection` of `series` integrated under `spec` by the engine named."""
    return {
        "dataset": series.source or (str(series.path) if series.path else ""),
        # Where to read the series again (a silhouette re-integrated for another view).
        "store": str(series.path.resolve()) if series.path is not None else None,
        "selection": {"steps": list(selection.steps), "n_steps": selection.n_steps},
        "time_labels": [series.times[s] for s in selection.steps],
        "time_unit": series.time_unit,
        "spec": spec.to_dict(),
        "spacing": dict(zip("xyz", series.spacing, strict=True)),
        "value_range": [float(value_range[0]), float(value_range[1])],
        "engine": engine,
        "level": series.level_index,
    }


def engine_name(engine: object) -> str:
    """The name an engine goes by in metadata ('opencl', 'numpy', or its class name)."""
    return getattr(engine, "name", type(engine).__name__)


def window_job(series: TimeSeries, selection: Selection, spec: IntegrationSpec) -> Job:
    """The Job of `spec` over a parsed `selection`, with the value range the spec implies."""
    return Job.of(series, selection, spec, value_range(series, selection, spec))


def value_range(series: TimeSeries, selection: Selection, spec: IntegrationSpec):
    """The (min, max) that normalises values: the data TF's own, the series' recorded range,
    or one fitted to the selected window for the mode (`DataTF.range_kind`,
    `chronocl.integration.fit_range`)."""
    kind = spec.data_tf.range_kind
    if kind == "given":
        return spec.data_tf.value_range
    if kind == GLOBAL:
        return (series.vmin, series.vmax)
    return window_range(series, selection, spec.integration)


def check_level(series: TimeSeries, level: object) -> int:
    """A fixed level of `series`: an integer in 0..n_levels-1, else one clear line."""
    n = series.n_levels
    if isinstance(level, bool) or not isinstance(level, int):
        raise InvalidParameterError(
            f"level {level!r} must be an integer 0..{n - 1} (0: full resolution) or 'auto'"
        )
    if not 0 <= level < n:
        name = series.source or "the series"
        have = (
            "only level 0 (add coarse levels with 'chronocl pyramid')"
            if n == 1
            else f"levels 0..{n - 1}"
        )
        raise InvalidParameterError(f"level {level} is out of range: {name} has {have}")
    return level


def fix_range(series: TimeSeries, spec: IntegrationSpec, selection: Selection) -> IntegrationSpec:
    """`spec` with its value range fixed: one fitted to `selection` when the data TF asks for
    a fitted range, else `spec` itself (its range is the same for every window). A session
    fixes it once, when the spec is set, and keeps it while the window slides: sliding then
    equals integrating each window with that range (docs/semantics.md)."""
    if spec.data_tf.range_kind != FITTED:
        return spec
    return spec.with_value_range(value_range(series, selection, spec))


def at_level(job: Job, level: int) -> Job:
    """The job on a coarse level of its series (0: the job itself), pooled as its mode asks."""
    if level == 0:
        return job
    coarse = job.series.level(check_level(job.series, level), job.spec.integration.pool)
    return Job.of(coarse, job.selection, job.spec, job.value_range)  # one range at every level


def engine_rows(eng: Engine, job: Job) -> int:
    """Output z-rows per brick that fit the engine (at least 1, else a clear error)."""
    _, ny, nx = job.series.volume_shape
    halo = job.halo
    fit = eng.max_brick_bytes // max(1, job.row_bytes) - 2 * halo
    if fit < 1:
        itemsize = job.series.dtype.itemsize
        most = max(1, eng.max_brick_bytes // ((1 + 2 * halo) * ny * nx * itemsize))
        raise InvalidParameterError(
            f"one z-row of a {job.selection.width}-step window needs "
            f"{(1 + 2 * halo) * job.row_bytes / 2**20:.0f} MB but the engine holds at most "
            f"{eng.max_brick_bytes / 2**20:.0f} MB per brick; use a window of at most {most} steps"
        )
    return fit


Out = tuple[np.ndarray | None, ...]  # rgba, t_index (None: the mode has none), and u, k


@dataclass
class WinnersOut:
    """Where `integrate_bricks` puts each voxel's winner when asked, for a mode that writes
    them (`Mode.writes_winners`) on an engine that can: its u and its index into the window's
    steps (as `chronocl.integration.interactive.winners.Winners` holds them); None where they
    were not written."""

    u: np.ndarray | None = None
    k: np.ndarray | None = None


# Above this many voxels (32^3) display frames are RGBA8, below float32, and the viewer's
# textures follow (chronocl.render.upload.display_format; measured there, docs/display.md).
DISPLAY_VOXELS = 2**15
OutFor = Callable[[Slab], Out]
Integrate = Callable[[Slab, np.ndarray, Out | None], tuple[Partial, bool]]


def integrate_brick(
    job: Job, eng: Engine, slab: Slab, brick: np.ndarray, out: Out | None = None
) -> tuple[Partial, bool]:
    """Integrate the brick of `slab` (rows r0..r1 of the window); returns the slab's partial
    (into `out` if given) and whether the engine finished it."""
    steps = job.selection.steps
    return eng.accumulate(
        brick, slab.crop, steps, job.positions, job.order, job.spec, job.value_range, out
    )


def integrate_slabs(
    parts: Sequence[Slab],
    steps: Sequence[int],
    bricks: BrickSource,
    integrate_one: Integrate,
    out: OutFor,
    read_ahead: bool = True,
) -> Iterator[tuple[Slab, Partial, bool]]:
    """Integrate `parts` one after the other; yields (slab, partial, final) per slab.

    `integrate_one(slab, brick, out)` integrates one brick (`integrate_brick` with a job and an
    engine), `out(slab)` gives the C-contiguous buffers the slab's result is written to.
    With `read_ahead` the next brick is read from `bricks` on a background thread while this
    one is integrated (double buffering), so at most two bricks are held; without, one.
    """
    if not parts:
        return
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="chronocl-read") as reader:
        pending = reader.submit(bricks.read, steps, parts[0].r0, parts[0].r1)
        for i, s in enumerate(parts):
            checkpoint("integrating", i, len(parts))  # given up here when newer input came
            brick = pending.result()
            nxt = parts[i + 1] if i + 1 < len(parts) else None
            if nxt is not None and read_ahead:
                pending = reader.submit(bricks.read, steps, nxt.r0, nxt.r1)
            partial, final = integrate_one(s, brick, out(s))
            del brick
            if nxt is not None and not read_ahead:
                pending = reader.submit(bricks.read, steps, nxt.r0, nxt.r1)
            yield s, partial, final


def integrate(
    series: TimeSeries,
    window: object = None,
    mode: str = modes.DEFAULT,
    *,
    spec: IntegrationSpec | None = None,
    engine: str | Engine = "opencl",
    device: str | None = None,
    slab: int | None = None,
    progress: bool = False,
    level: int = 0,
    device_format: str = "auto",
    **spec_args: object,
) -> Chronovolume:
    """Integrate the selected steps of `series` into a Chronovolume.

    `window` is 't0:t1[:stride]', a list of steps, a slice or a Selection (default:
    every step). Either pass a ready `spec`, or the arguments of `make_spec`
    (tf=, data_tf=, time_tf=, order=, enhance=, threshold=, normalize=).
    `engine` is ``opencl`` (default; `device` picks one, see `chronocl devices`),
    ``numpy`` (the reference) or an engine object. `slab` sets the z rows per brick
    (default: as many as fit the engine's brick size). For outputs larger than memory
    see `chronocl.integration.runs.streaming.integrate_to_store`. `level` integrates a coarse
    level of the series (0: full resolution; docs/levels.md), pooled as the mode asks; the
    chronovolume keeps the physical extent, so it renders in the same place. Its metadata
    keeps where the window's first and last steps lie (``centres``), which `chronocl.render`
    looks from by default, as the command line does.
    `device_format` is what bricks travel to the device in: auto (as stored), float32,
    float16, or uint8 / uint16 quantised over the value range (docs/engine.md).
    """
    whole = prepare(series, window, mode, spec, spec_args)
    job = at_level(whole, level)
    eng = get_engine(engine, device) if isinstance(engine, str) else engine
    eng = with_device_format(eng, device_format, *job.format_input())
    cv = integrate_bricks(job, eng, SeriesBricks(job.series), slab, progress)
    warn_invisible(job, cv)  # steps, or a whole picture, the transfer functions hide
    # where the window's first and last steps lie: `chronocl.render` looks from the first
    centres = window_centres(whole.series, whole.selection, whole.value_range)
    if centres is not None:
        cv.metadata["centres"] = centres
    return cv


def integrate_bricks(
    job: Job,
    eng: Engine,
    bricks: BrickSource,
    slab: int | None = None,
    progress: bool = False,
    display: bool = False,
    winners: WinnersOut | None = None,
) -> Chronovolume:
    """Integrate a prepared `job` with bricks from `bricks` (e.g. steps already resident:
    `chronocl.data.bricks.ResidentBricks`) into a Chronovolume, as `integrate` does.

    With `display`, where the engine can (`writes_display`), the mode finishes each voxel on
    its own and the volume is larger than `DISPLAY_VOXELS`, its kernels write the display
    format, premultiplied RGBA8 (a viewer's frame: a quarter of the bytes, nothing to convert),
    and each slab is handed on as soon as it is written (`chronocl.core.slab_sink`: the viewer
    writes it to its texture while the next slab integrates); else the chronovolume is float32
    as always. With `winners`, a mode that writes them on an engine that can (a final result
    of fewer than 255 steps) fills it with each voxel's winner as it integrates."""
    fit = engine_rows(eng, job)
    slab = fit if slab is None else min(slab, fit)
    nz, ny, nx = job.series.volume_shape
    parts = slabs(nz, slab, job.halo)

    spec = job.spec
    rgba8 = display and eng.writes_display and nz * ny * nx > DISPLAY_VOXELS
    rgba8 = rgba8 and not spec.integration.finalize_is_global(spec)
    rgba = recycled_empty((nz, ny, nx, 4), np.uint8 if rgba8 else np.float32)
    t_index = recycled_empty((nz, ny, nx), np.int32) if job.spec.has_t_index else None
    outputs = [rgba, t_index]
    won = (
        winners is not None
        and eng.writes_winners
        and spec.integration.writes_winners
        and not spec.integration.finalize_is_global(spec)
        and job.selection.width < 255
    )
    if won:
        outputs += [recycled_empty((nz, ny, nx), dt) for dt in (np.float32, np.uint8)]

    def out(s: Slab) -> Out:
        # z is the outermost axis, so a slab of the output is a contiguous view.
        return tuple(None if a is None else a[s.z0 : s.z1] for a in outputs)

    final = True
    integrate_one = functools.partial(integrate_brick, job, eng)
    results = integrate_slabs(parts, job.selection.steps, bricks, integrate_one, out)
    handed_on = rgba8 and listening()  # RGBA8 final per voxel: each slab is done when written
    for s, _, last in track(results, len(parts), "integrating bricks", progress):
        final = last
        if handed_on and last:
            finished(rgba, s.z0, s.z1)
    if not final:
        rgba = reference.finalize(Partial(rgba, t_index), job.positions, job.spec)
    if won and final:
        winners.u, winners.k = outputs[2], outputs[3]
    meta = job.metadata(engine_name(eng))
    fmt = eng.device_format
    if fmt != "auto":  # a lossy format changes the result: say so where the result is kept
        meta["device_format"] = fmt
    return Chronovolume(rgba, t_index, meta)
