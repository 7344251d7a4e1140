"""Every path obeys the device's largest allocation, and its split results equal the whole ones.

``CHRONOCL_MAX_ALLOC`` lowers the largest buffer (`chronocl.engine.buffers.max_alloc`) so
that one step here (36 x 44 x 96 float32, 608 KB) is over it: every mode's integration (at full
resolution and a coarse level, float32 and the display's RGBA8), a session's slides both ways
(incrementally: the sliding kernels) and TF edits (recoloured where the mode allows), the
gather of the winners, the brick-wise recolouring (in z-spans of rows of bricks) and the probe
then run in pieces. Each result equals the uncapped one bit for bit (issue 45: the users' case
at the default budget wrapped a 6.5 GB block in one buffer, over PoCL's 4 GB; at 1024^3 the
winners' u alone is 4 GB).
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
                recolour = s.at(0).recolours(_spec(mode, EDIT))
                assert not isinstance(recolour, str), recolour
                w = s.at(0).winners()  # the OpenCL engine's gather
                assert w is not None
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


ODD = (37, 21, 29)  # no side a multiple of the 8^3 bricks: 5 rows of bricks, the last short
ROW = 8 * ODD[1] * ODD[2] * 4  # bytes of u of one row of bricks (19 488)
# opaque on a band of u (0.8 to 0.9) alone: few bricks coloured
BAND = ((0, 1, 1, 1, 0), (0.8, 1, 1, 1, 0), (0.81, 1, 0.2, 0, 1), (0.9, 0, 0.5, 1, 1),
        (0.91, 1, 1, 1, 0), (1, 1, 1, 1, 0))  # fmt: skip
SPANS = {  # cap -> rows of bricks of each span: boundaries at z = 8, 16, 24, 32; 16, 32; 32
    ROW: [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)],
    2 * ROW + 100: [(0, 2), (2, 4), (4, 5)],
    int(np.prod(ODD)) * 4 - 1: [(0, 4), (4, 5)],
    int(np.prod(ODD)) * 4: [(0, 5)],  # u fits (its float32 RGBA would not): one span
}


def _odd_winners(mode: str):
    """Winners of `ODD` that are empty (u 0) but for a blob across z = 16 and single voxels
    on the faces of rows of bricks either side of z = 8, 16, 24 and 32 (where the spans of
    one and two rows of bricks start), whose values differ from step to step (change)."""
    from chronocl.integration.interactive.winners import winners

    steps = tuple(range(1, 7))
    rng = np.random.default_rng(11)
    z, y, x = np.meshgrid(*[np.arange(n) for n in ODD], indexing="ij")
    blob = (z - 16) ** 2 + (y - 10) ** 2 + (x - 14) ** 2 <= 9
    arrays = {}
    for s in steps:
        a = np.full(ODD, VR[0], np.float32)
        a[blob] = rng.uniform(*VR, int(blob.sum()))
        for zi in (7, 8, 15, 23, 24, 31, 32, 36):
            a[zi, (3 * zi) % ODD[1], (5 * zi) % ODD[2]] = rng.uniform(*VR)
        arrays[s] = a
    t_index = rng.choice(np.array([*steps, -1], np.int32), size=ODD)
    return winners(t_index, arrays, steps, STEPS, VR, _spec(mode))


def _recoloured(w, mode: str) -> list[tuple]:
    """Each edit's output, box, grid, bricks coloured and rewritten, and the spans it ran in:
    EDIT (opaque wherever u > 0: the blob and the single voxels), BAND (a few bricks), EDIT and
    BAND again (the bricks either coloured rewritten, the others cleared)."""
    bricks = BrickRecolourer()
    prepared = on_host(w, None)
    got = []
    try:
        for points in (EDIT, BAND, EDIT, BAND):
            c = bricks.apply(prepared, _spec(mode, points))
            arrays = (c.rgba.copy(), c.bounds.copy(), c.bricks.copy(), c.coloured.copy())
            got.append((*arrays, c.rewritten, len(prepared.spans)))
    finally:
        prepared.release()
    return got


@pytest.mark.parametrize("mode", ["max", "min", "change"])
def test_brick_recolouring_of_winners_over_one_buffer_runs_in_spans(mode, monkeypatch):
    """Winners over the device's largest buffer (at 1024^3 u alone is 4 GB, over PoCL's 2-4
    GB on a CPU) are held in z-spans of whole rows of bricks, each span's buffers under it,
    and recoloured span by span: every edit's RGBA8, occupied box, brick grid (a brick grown
    by its neighbours across a span boundary) and bricks coloured equal the uncapped ones
    bit for bit, on a shape whose spans end mid-volume. Only a row of bricks over the
    largest buffer is not prepared there (the viewer integrates the edit, and says why)."""
    from chronocl.render import brick_grid
    from chronocl.render.recolour.bricks import span_rows

    w = _odd_winners(mode)
    monkeypatch.delenv(buffers.MAX_ALLOC_VAR, raising=False)
    whole = _recoloured(w, mode)
    assert [g[5] for g in whole] == [1] * 4
    band = whole[1]
    assert 0 < band[3].sum() < band[3].size / 2 and band[1][2] > 0  # few bricks, a box inside
    for cap, rows in SPANS.items():
        assert span_rows(ODD, cap) == rows
        monkeypatch.setenv(buffers.MAX_ALLOC_VAR, str(cap))
        split = _recoloured(w, mode)
        for i, (got, want) in enumerate(zip(split, whole, strict=True)):
            assert got[5] == len(rows), (cap, got[5])
            names = ("rgba", "box", "grid", "coloured", "rewritten")
            for name, a, b in zip(names, got, want, strict=False):
                np.testing.assert_array_equal(a, b, err_msg=f"{mode} cap {cap} edit {i} {name}")
            np.testing.assert_array_equal(got[2], brick_grid.from_rgba(got[0]))
    # spans start 64-byte aligned (PoCL's in place) where that leaves a row of bricks a span:
    # a row of (80, 3, 5) is 120 voxels (k: 120 bytes), so 8 rows, or any where fewer fit
    assert span_rows((80, 3, 5), 9 * 480) == [(0, 8), (8, 10)]
    assert span_rows((80, 3, 5), 3 * 480) == [(0, 3), (3, 6), (6, 9), (9, 10)]
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, str(ROW - 1))  # a row of bricks over it
    assert on_host(w, None) is None
    with pytest.raises(buffers.DeviceLimitError, match="a row of 8 z planes"):
        BrickRecolourer().prepare(w)


def test_the_gather_wraps_only_what_its_rows_span_of_a_slot_block():
    """Issue 45's LogicError: the gather wrapped the window manager's slot block from the
    window's first step to the block's end in one buffer (6.5-7.5 GB at the users' default
    budget, by where that step's slot lay), and PoCL refused it ("create_buffer failed:
    INVALID_BUFFER_SIZE") after window_index was enqueued. Here three small steps lie at the
    start of a block larger than the device's memory (a memory map never touched): the
    gather wraps only the bytes they span, and equals numpy's."""
    from chronocl.core.memory import aligned_empty
    from chronocl.engine.device import get_context
    from chronocl.engine.opencl import OpenCLEngine
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
    got = winners(t_index, arrays, steps, 8, (0.0, 255.0), spec, OpenCLEngine())
    np.testing.assert_array_equal(got.k, want.k)
    np.testing.assert_array_equal(got.u, want.u)
