"""Every path obeys the device's largest allocation, and its split results equal the whole ones.

``CHRONOCL_MAX_ALLOC`` lowers the largest buffer (`chronocl.engine.buffers.max_alloc`) so
that one step here (36 x 44 x 96 float32, 608 KB) is over it: every mode's integration (at full
resolution and a coarse level, float32 and the display's RGBA8), a session's slides both ways
(incrementally: the sliding kernels) and TF edits (recoloured where the mode allows), the
gather of the winners and the probe then run in pieces (the brick-wise recolouring takes the
winners in one buffer, or the edit integrates). Each result equals the
uncapped one bit for bit (issue 45: the users' case at the default budget wrapped a 6.5 GB
block in one buffer, over PoCL's 4 GB).
"""

from __future__ import annotations

import numpy as np
import pytest

from chronocl import modes
from chronocl.core.tf import DataTF, TimeTF
from chronocl.data.probe import probe
from chronocl.data.series import TimeSeries, open_series
from chronocl.engine import buffers
from chronocl.integration.inmemory import integrate
from chronocl.integration.interactive.session import Session
from chronocl.integration.interactive.winners import RECOLOURED
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.recolour.bricks import BrickRecolourer
from chronocl.render.recolour.gather import gather
from chronocl.viewer.recolouring import on_host

CAP = "128KB"  # one step is 608 KB; a brick row of 6 steps 101 KB, of RGBA float32 66 KB
SHAPE = (36, 44, 96)  # coarse levels from 96 along x
STEPS = 12
VR = (-10.0, 30.0)


@pytest.fixture(scope="module")
def series(tmp_path_factory) -> TimeSeries:
    rng = np.random.default_rng(17)
    z, y, x = np.meshgrid(*[np.linspace(-1, 1, n) for n in SHAPE], indexing="ij")
    steps = [
        30 * np.exp(-((x - 0.1 * t + 0.5) ** 2 + y**2 + z**2) * 4) + rng.normal(0, 2, SHAPE) - 5
        for t in range(STEPS)
    ]
    path = tmp_path_factory.mktemp("capped") / "series.zarr"
    TimeSeries.from_array(np.stack(steps).astype(np.float32)).save(path)
    series = open_series(path)
    assert series.n_levels == 2
    return series


def _spec(mode: str, points=None) -> IntegrationSpec:
    tf = DataTF(value_range=VR) if points is None else DataTF(points=points, value_range=VR)
    return IntegrationSpec(mode=mode, data_tf=tf, time_tf=TimeTF(positions="absolute"))


EDIT = ((0, 0.2, 0.4, 1, 0.0), (0.4, 1, 0.5, 0, 0.3), (1, 1, 1, 0.2, 0.9))


def _run_all(series: TimeSeries, mode: str) -> dict[str, np.ndarray]:
    """Every result of one mode the capped paths must reproduce, by name."""
    out: dict[str, np.ndarray] = {}

    def keep(name: str, cv) -> None:
        out[f"{name}.rgba"] = np.array(cv.rgba, copy=True)
        if cv.t_index is not None:
            out[f"{name}.t_index"] = np.array(cv.t_index, copy=True)

    spec = _spec(mode)
    keep("integrate", integrate(series, "1:7", spec=spec, engine="opencl"))
    keep("level1", integrate(series, "1:7", spec=spec, engine="opencl", level=1))
    for display in (False, True):
        options = {"display": display}  # no slide costs: slides always incremental
        with Session(series, engine="opencl", spec=spec, memory="64MB", **options) as s:
            s.set_window(2, 8)
            for move in (+2, -3):
                keep(f"slide{move:+d}.display{display}", s.slide(move))
            keep(f"edit.display{display}", s.set_spec(_spec(mode, EDIT)))
            if mode in RECOLOURED and not display:
                _, reason = s.recolours(_spec(mode, EDIT))
                w = s.winners(gather)
                assert reason is None and w is not None, reason
                out["winners.u"], out["winners.k"] = w.u.copy(), w.k.copy()
    curve = probe(series, region=((3, 40), (2, 30), (5, 33)))
    out["probe"] = np.stack([curve.values, curve.min, curve.max])
    return out


@pytest.mark.parametrize("mode", modes.names())
def test_every_path_under_the_allocation_cap_equals_the_whole(
    series, mode, monkeypatch, buffer_sizes
):
    monkeypatch.delenv(buffers.MAX_ALLOC_VAR, raising=False)
    whole = _run_all(series, mode)
    made = len(buffer_sizes)
    assert max(buffer_sizes) > 128_000  # the whole paths make buffers over the cap
    buffer_sizes.clear()
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, CAP)
    split = _run_all(series, mode)
    # the same work, in more pieces
    assert max(buffer_sizes) <= 128_000 and len(buffer_sizes) > made
    assert whole.keys() == split.keys()
    for name, want in whole.items():
        np.testing.assert_array_equal(split[name], want, err_msg=f"{mode} {name}")


def _device():
    from chronocl.engine.device import get_context

    return get_context()


def test_the_cap_is_below_one_step_and_splits_each_kind_of_buffer(series, monkeypatch):
    """The cap of the test above is under one step and over one brick row, and what asks for
    more than it is refused with a clear error instead of reaching the driver."""
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, CAP)
    dc = _device()
    limit = buffers.max_alloc(dc)
    assert limit == 128_000
    step = int(np.prod(SHAPE)) * 4
    assert step > limit > SHAPE[1] * SHAPE[2] * 16
    with pytest.raises(buffers.DeviceLimitError, match="largest buffer"):
        buffers.buffer(dc, nbytes=limit + 1)
    assert buffers.spans(20_000, 16, limit) == [(0, 8000), (8000, 16000), (16000, 20_000)]


def test_brick_recolouring_takes_a_volume_whose_rgba8_fits_one_buffer(series, monkeypatch):
    """A volume whose float32 RGBA is over the largest buffer but whose winners and RGBA8 are
    not is still recoloured brick by brick (a review found it sent to the whole-volume spans),
    and equals the uncapped recolouring; one whose RGBA8 is over it is not prepared there (the
    viewer integrates the edit, and says why)."""
    steps = tuple(range(1, 7))
    arrays = {s: np.ascontiguousarray(series.read([s])[0]) for s in steps}
    rng = np.random.default_rng(2)
    t_index = rng.choice(np.array([*steps, -1], np.int32), size=SHAPE)
    spec = _spec("max", EDIT)
    w = gather(t_index, arrays, steps, STEPS, VR, spec)
    bricks = BrickRecolourer()
    prepared = on_host(w, None)
    want = bricks.apply(prepared, spec).rgba.copy()
    prepared.release()
    voxels = int(np.prod(SHAPE))
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, str(voxels * 8))  # RGBA8 fits, float32 not
    prepared = on_host(w, None)
    np.testing.assert_array_equal(bricks.apply(prepared, spec).rgba, want)
    prepared.release()
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, str(voxels * 2))  # RGBA8 over it
    assert on_host(w, None) is None


def test_the_gather_wraps_only_what_its_rows_span_of_a_slot_block():
    """Issue 45's LogicError: the gather wrapped the window manager's slot block from the
    window's first step to the block's end in one buffer (6.5-7.5 GB at the users' default
    budget, by where that step's slot lay), and PoCL refused it ("create_buffer failed:
    INVALID_BUFFER_SIZE") after window_index was enqueued. Here three small steps lie at the
    start of a block larger than the device's memory (a memory map never touched): the
    gather wraps only the bytes they span, and equals numpy's."""
    from chronocl.core.memory import aligned_empty
    from chronocl.engine.device import get_context
    from chronocl.integration.interactive.winners import winners

    dc = get_context()
    try:
        owner = aligned_empty((dc.info.global_mem + 2**30,), np.uint8)
    except MemoryError:
        pytest.skip("no address space for a block larger than the device's memory")
    shape, steps = (2, 4, 64), (3, 4, 5)
    block = owner[: 2 * 3 * 4 * 64].reshape(2, 3, 4, 64)  # (Z, S, Y, X), as the slots
    rng = np.random.default_rng(8)
    block[...] = rng.integers(0, 256, block.shape, dtype=np.uint8)
    arrays = {s: block[:, i] for i, s in enumerate(steps)}
    t_index = rng.choice(np.array([*steps, -1], np.int32), size=shape)
    spec = _spec("max")
    want = winners(t_index, arrays, steps, 8, (0.0, 255.0), spec)
    got = gather(t_index, arrays, steps, 8, (0.0, 255.0), spec)
    np.testing.assert_array_equal(got.k, want.k)
    np.testing.assert_array_equal(got.u, want.u)
