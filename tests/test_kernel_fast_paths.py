"""The kernels' comparison and colour fast paths equal the general path and the numpy reference.

- max / min compare the raw values: integer data in the data's lanes, the winning step in
  lanes as narrow where the steps fit (`extreme.raw_lanes`), else as float.
- A data TF made of a few straight pieces is evaluated piece by piece instead of looked up
  (`tables.tf_segments`): colour and opacity in alpha, additive and mean; in first_hit and
  count (thresholds) the pieces' opacity decides only lanes farther than SEG_MARGIN from the
  threshold and the exact opacity decides the rest, so their results equal the lookups' bits.

Each is checked against the numpy reference (1e-5, t_index exactly) and against the engine
with the fast path switched off, on every stored dtype, odd shapes and window lengths, value
ranges that clip, ties, every order and brick splits.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl import modes
from chronocl.core.enhance import Enhance
from chronocl.core.tf import DataTF, lut_lerp32
from chronocl.engine import opencl, tables
from chronocl.modes import extreme
from chronocl.modes.spec import IntegrationSpec

from .strategies import enhancements, examples, time_tfs

# Drawn transfer functions and data are often transparent on purpose; the warnings saying so
# (chronocl.integration.visibility) are tested in test_visibility.py.
pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

DTYPES = ["uint8", "uint16", "int16", "float32"]


def assert_same(a, b, atol: float = 1e-5) -> None:
    np.testing.assert_allclose(a.rgba, b.rgba, atol=atol, rtol=0)
    if a.t_index is None:
        assert b.t_index is None
    else:
        np.testing.assert_array_equal(a.t_index, b.t_index)


def raw_values(data, dtype: str, shape: tuple) -> np.ndarray:
    """Random values of `dtype`, often from a few levels (ties), sometimes beyond any range."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    if data.draw(st.booleans()):  # few levels: exact ties everywhere
        v = rng.integers(0, 5, shape) * 20 - 10
    else:
        v = rng.integers(-40, 300, shape)
    if dtype == "float32":
        return (v + rng.choice([0.0, 1e-5, 0.5], shape)).astype(np.float32)
    info = np.iinfo(dtype)
    return np.clip(v, info.min, info.max).astype(dtype)


@settings(max_examples=examples(14))
@given(st.data())
def test_max_min_keys_equal_reference_and_general_path(data):
    dtype = data.draw(st.sampled_from(DTYPES))
    w = data.draw(st.integers(1, 37))
    shape = (w, data.draw(st.integers(1, 4)), data.draw(st.integers(1, 3)))
    shape += (data.draw(st.sampled_from([1, 16, 21, 32, 47])),)
    raw = raw_values(data, dtype, shape)
    # None: the data's own range; the others clip values on one side or both (u ties there,
    # the raw values do not), or (for 16-bit data) merge neighbouring integers by rounding.
    value_range = data.draw(st.sampled_from([None, (0, 100), (20.5, 60), (-5, 400), (-1e9, 1e9)]))
    order = data.draw(
        st.one_of(st.sampled_from(["forward", "backward"]), st.permutations(range(w)))
    )
    order = order if isinstance(order, str) else tuple(order)
    tf = DataTF(points=[(0, 0, 0.2, 1, 0.1), (0.4, 1, 0.5, 0, 0.6), (1, 1, 1, 1, 1)])
    tf = DataTF(points=tf.points, value_range=value_range)
    spec = IntegrationSpec(
        mode=data.draw(st.sampled_from(["max", "min"])),
        order=order,
        data_tf=tf,
        time_tf=data.draw(time_tfs()),
    )
    series = chronocl.TimeSeries.from_array(raw)
    slab = data.draw(st.integers(1, shape[1] + 1))
    ref = chronocl.integrate(series, None, spec=spec, engine="numpy")
    fast = chronocl.integrate(series, None, spec=spec, engine="opencl", slab=slab)
    assert_same(ref, fast)
    with pytest.MonkeyPatch.context() as mp:  # every dtype compares its values as float
        mp.setattr(extreme, "raw_lanes", lambda *a: None)
        general = chronocl.integrate(series, None, spec=spec, engine="opencl", slab=slab)
    assert_same(general, fast, atol=0)


ROW_MODES = [m for m in modes.names() if modes.get(m).rows_kernel]
# Transparent below u = 0.3 (steps skipped), opaque at the top (alpha stops early); or opacity
# everywhere (nothing skipped). The test also draws random pieced TFs (`pieced_tfs`).
ROW_TFS = [
    [(0, 0, 0.2, 1, 0), (0.3, 0, 0.2, 1, 0), (0.6, 1, 0.5, 0, 0.6), (1, 1, 1, 1, 1)],
    [(0, 0, 0.2, 1, 0.1), (0.4, 1, 0.5, 0, 0.6), (1, 1, 1, 1, 1)],
]


@settings(max_examples=examples(20))
@given(st.data())
def test_row_blocks_equal_the_per_vector_kernels_and_reference(data):
    """On CPU devices a work-item takes a block of rows, the steps in the outer loop a group at
    a time (kernels/opencl/common.h BLOCK_STEPS): bit for bit the per-vector kernel's result,
    in every mode that has one, with blocks cut small (several per slab, the last one short),
    through host pointers and copied chunks, the TF as pieces or looked up, every dtype, float
    data as float16 on the device too. Up to TIME_TABLE_MAX steps a block looks the winner's
    time colour and step up in register tables on AVX-512 and AVX2 CPUs (PERMUTE_TIME), more
    by loads."""
    dtype = data.draw(st.sampled_from(DTYPES))
    edge = opencl.TIME_TABLE_MAX
    w = data.draw(st.one_of(st.integers(1, 23), st.sampled_from([edge - 1, edge, edge + 1])))
    shape = (w, data.draw(st.integers(1, 4)), data.draw(st.integers(1, 13)))
    shape += (data.draw(st.sampled_from([16, 21, 47, 64])),)
    raw = raw_values(data, dtype, shape)
    value_range = data.draw(st.sampled_from([None, (0, 100), (20.5, 60), (-5, 400)]))
    order = data.draw(
        st.one_of(st.sampled_from(["forward", "backward"]), st.permutations(range(w)))
    )
    points = data.draw(st.one_of(st.sampled_from(ROW_TFS), pieced_tfs().map(lambda tf: tf.points)))
    spec = IntegrationSpec(
        mode=data.draw(st.sampled_from(ROW_MODES)),
        order=order if isinstance(order, str) else tuple(order),
        data_tf=DataTF(points=points, value_range=value_range),
        time_tf=data.draw(time_tfs()),
    )
    series = chronocl.TimeSeries.from_array(raw)
    slab = data.draw(st.integers(1, shape[1] + 1))
    fmt = data.draw(st.sampled_from(["auto", "auto", "float16"])) if dtype == "float32" else "auto"
    options = {"host_ptr": data.draw(st.booleans()), "device_format": fmt}
    options["pieces"] = data.draw(st.booleans())  # the TF as pieces, or looked up
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(opencl, "ROW_BLOCK_BYTES", data.draw(st.sampled_from([1024, 5000, 1 << 16])))
        mp.setattr(opencl, "ROW_BLOCKS_PER_UNIT", data.draw(st.sampled_from([1, 4])))
        engine = opencl.OpenCLEngine(**options)
        blocks = chronocl.integrate(series, None, spec=spec, engine=engine, slab=slab)
    vectors = opencl.OpenCLEngine(row_blocks=False, **options)
    assert_same(chronocl.integrate(series, None, spec=spec, engine=vectors, slab=slab), blocks, 0)
    if fmt == "auto":
        assert_same(chronocl.integrate(series, None, spec=spec, engine="numpy"), blocks)


@pytest.mark.parametrize("mode", ["max", "min", "first_hit", "change"])
@pytest.mark.parametrize("w", [32, 33])
def test_time_tables_at_their_edge_equal_the_gathers(mode, w):
    """A window of 32 steps, the most the register tables hold (PERMUTE_TIME), and one of 33,
    which the gathers take: the rows kernels give the per-vector kernels' bits (and the
    reference's), every step winning somewhere, reversed and importance orders too."""
    rng = np.random.default_rng(w)
    # each voxel's steps hold 0..w-1 in a random order: every step is the maximum somewhere
    ranks = np.argsort(rng.random((2 * 3 * 48, w)), axis=1).astype(np.float32)
    series = chronocl.TimeSeries.from_array(np.ascontiguousarray(ranks.T.reshape(w, 2, 3, 48)))
    spec_args = {"threshold": 0.4} if mode == "first_hit" else {}
    for order in ("forward", "backward", tuple(rng.permutation(w).tolist())):
        spec = IntegrationSpec(
            mode=mode,
            order=order,
            time_tf=chronocl.TimeTF.preset("rgb"),
            data_tf=chronocl.DataTF(value_range="global"),  # every rank its own u
            **spec_args,
        )
        blocks = chronocl.integrate(series, None, spec=spec, engine=opencl.OpenCLEngine())
        vectors = opencl.OpenCLEngine(row_blocks=False)
        assert_same(chronocl.integrate(series, None, spec=spec, engine=vectors), blocks, 0)
        assert_same(chronocl.integrate(series, None, spec=spec, engine="numpy"), blocks)
        if mode in ("max", "min"):
            assert len(np.unique(blocks.t_index)) == w


def _compiler_reports(engine, body: str, defines: dict) -> int:
    """What a one-item kernel of common.h plus `body` (which sets o[0]) writes, built with
    `defines` on the engine's device: what its compiler defines, not what the device is named."""
    import pyopencl as cl

    from chronocl.engine import program

    common = (program.kernel_dir() / "common.h").read_text()
    text = common + "__kernel void report(__global int *o) {\n" + body + "\n}\n"
    prg = program.build(engine.dc, "report", defines, text=text)
    out = np.full(1, -1, np.int32)
    buf = cl.Buffer(engine.dc.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    with engine.dc.lock:
        cl.Kernel(prg, "report")(engine.dc.queue, (1,), None, buf)
        cl.enqueue_copy(engine.dc.queue, out, buf)
    return int(out[0])


def test_time_tables_are_built_where_the_compiler_has_the_permutes():
    """The rows kernels of a window of at most 32 steps get the register tables (common.h
    PERMUTE_TIME): with AVX-512's two-table permute where the device's compiler defines
    __AVX512F__ and has its builtin, else with AVX2's one-table permute where it defines
    __AVX2__ and has that builtin, and never without TIME_TABLE: asked of the compiler (PoCL
    names its CPU target in the device name only sometimes, e.g. not for a generic or a newer
    target)."""
    engine = opencl.OpenCLEngine()
    defines = {"DATA_T": "float", "DATA_V": "float16", "VEC": 16, "LUT_N": 256}
    has = _compiler_reports(
        engine,
        "o[0] = 0;\n#if defined(__has_builtin)\n"
        "#if defined(__AVX2__) && __has_builtin(__builtin_ia32_permvarsf256) && "
        "__has_builtin(__builtin_shufflevector)\n o[0] = 256;\n#endif\n"
        "#if defined(__AVX512F__) && __has_builtin(__builtin_ia32_vpermi2varps512)\n"
        " o[0] = 512;\n#endif\n#endif",
        defines,
    )
    permutes = "#ifdef PERMUTE_TIME\n o[0] = PERMUTE_TIME;\n#else\n o[0] = 0;\n#endif"
    assert _compiler_reports(engine, permutes, {**defines, "TIME_TABLE": True}) == has
    assert _compiler_reports(engine, permutes, {**defines, "TIME_TABLE": False}) == 0
    if engine.dc.is_cpu and "avx512" in engine.dc.device.name.lower():
        assert has == 512  # PoCL named an AVX-512 target: its compiler must say so too


def test_order_defines_name_steps_in_turn_or_reversed():
    assert opencl.order_defines(np.arange(5), 5) == {"ORDER_FORWARD": True, "ORDER_BACKWARD": False}
    assert opencl.order_defines([4, 3, 2, 1, 0], 5) == {
        "ORDER_FORWARD": False,
        "ORDER_BACKWARD": True,
    }
    assert opencl.order_defines([0], 1) == {"ORDER_FORWARD": True, "ORDER_BACKWARD": False}
    assert not any(opencl.order_defines([0, 2, 1], 3).values())  # importance: the table


@settings(max_examples=examples(20))
@given(st.data())
def test_steps_in_turn_or_reversed_equal_the_order_table(data):
    """ORDER_FORWARD / ORDER_BACKWARD (the kernels step through the brick without order[]) give
    the bits of the order table, in every mode, dtype and order, over all steps or a window,
    blocks of rows or not."""
    dtype = data.draw(st.sampled_from(DTYPES))
    total = data.draw(st.integers(1, 17))
    shape = (total, data.draw(st.integers(1, 3)), data.draw(st.integers(1, 9)))
    shape += (data.draw(st.sampled_from([16, 19, 33])),)
    raw = raw_values(data, dtype, shape)
    chosen = data.draw(st.lists(st.integers(0, total - 1), min_size=min(3, total), unique=True))
    window = data.draw(st.sampled_from([None, ",".join(map(str, sorted(chosen)))]))
    spec = IntegrationSpec(
        mode=data.draw(st.sampled_from(modes.names())),
        order=data.draw(st.sampled_from(["forward", "backward"])),
        time_tf=data.draw(time_tfs()),
        enhance=data.draw(st.sampled_from([Enhance(), Enhance(), Enhance("edge")])),
    )
    series = chronocl.TimeSeries.from_array(raw)
    options = {"row_blocks": data.draw(st.booleans()), "host_ptr": data.draw(st.booleans())}
    engine = opencl.OpenCLEngine(**options)
    stepped = chronocl.integrate(series, window, spec=spec, engine=engine)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(opencl, "order_defines", lambda order, w: {})
        table = chronocl.integrate(series, window, spec=spec, engine=engine)
    assert_same(stepped, table, 0)


def test_row_blocks_where_they_apply():
    """Blocks of rows: on CPU devices, in every mode with a rows kernel, with whole vectors along
    x; each block's state within ROW_BLOCK_BYTES; blocks enough for every compute unit."""
    engine = opencl.OpenCLEngine()
    units = engine.dc.info.compute_units
    blocks = engine._row_blocks
    alpha = modes.get("alpha")
    if not engine.dc.is_cpu:  # a GPU keeps one voxel's state in registers: no blocks
        assert all(blocks(modes.get(m), 16, 8, 128, 128) == 0 for m in modes.names())
        return
    assert blocks(extreme.MAX, 16, 8, 128, 128) == opencl.ROW_BLOCK_BYTES // (128 * 8)
    assert blocks(alpha, 16, 8, 128, 128) == opencl.ROW_BLOCK_BYTES // (128 * 16)
    assert blocks(modes.get("change"), 16, 8, 128, 128) == opencl.ROW_BLOCK_BYTES // (128 * 12)
    assert all(modes.get(m).rows_kernel for m in modes.names())  # every mode has one
    assert blocks(extreme.MIN, 1, 8, 128, 128) == 0  # gradient enhancement
    assert blocks(extreme.MIN, 16, 0, 128, 128) == 0  # narrower than a vector
    assert blocks(extreme.MAX, 16, 4096, 128, 128) == 0  # a row over the budget
    assert blocks(extreme.MAX, 16, 8, 4 * units, 1) == 1  # thin: a block per row
    assert opencl.OpenCLEngine(row_blocks=False)._row_blocks(extreme.MAX, 16, 8, 9, 9) == 0


def test_integer_data_is_compared_in_its_own_lanes_where_the_steps_fit():
    lanes = extreme.raw_lanes
    assert lanes(np.uint8, 256) == "uchar"
    assert lanes(np.uint8, 257) is None  # steps beyond byte lanes: compared as float
    assert lanes(np.uint16, 300) == "ushort"
    assert lanes(np.int16, 5) == "ushort"
    assert lanes(np.float32, 5) is None


def pieced_tfs():
    """Data TFs of 2-5 control points (at most 8 straight pieces, often fewer): coloured or of
    one colour, opacity sometimes exactly 0.1 or 0.5 (the thresholds drawn: plateaus where
    the pieces cannot decide and the exact opacity must)."""

    @st.composite
    def build(draw):
        n = draw(st.integers(2, 5))
        us = sorted({*draw(st.lists(st.floats(0, 1), min_size=n, max_size=n)), 0.0, 1.0})
        unit = st.floats(0, 1)
        opacity = st.one_of(st.just(0.0), st.floats(1e-3, 1), st.sampled_from([0.1, 0.5]))
        if draw(st.booleans()):
            points = [(u, draw(unit), draw(unit), draw(unit), draw(opacity)) for u in us]
        else:
            rgb = (draw(unit), draw(unit), draw(unit))
            points = [(u, *rgb, draw(opacity)) for u in us]
        return DataTF(points=points, size=draw(st.sampled_from([256, 300, 1024])))

    return build()


@settings(max_examples=examples(14))
@given(st.data())
def test_tf_pieces_equal_reference_and_lookups(data):
    dtype = data.draw(st.sampled_from(DTYPES))
    w = data.draw(st.integers(1, 23))
    shape = (
        w,
        data.draw(st.integers(1, 3)),
        data.draw(st.integers(1, 3)),
        data.draw(st.sampled_from([3, 16, 37])),
    )
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    raw = rng.random(shape) * 250
    if dtype != "float32":
        raw = np.round(raw)
    series = chronocl.TimeSeries.from_array(raw.astype(dtype))
    mode = data.draw(st.sampled_from(modes.names()))
    spec = IntegrationSpec(
        mode=mode,
        order=data.draw(st.sampled_from(["forward", "backward"])),
        data_tf=data.draw(pieced_tfs()),
        time_tf=data.draw(time_tfs()),
        enhance=data.draw(enhancements),
        threshold=data.draw(st.sampled_from([0.0, 0.1, 0.5])),
        normalize=data.draw(st.sampled_from(["time", "max"])),
    )
    slab = data.draw(st.integers(1, shape[1] + 1))
    ref = chronocl.integrate(series, None, spec=spec, engine="numpy")
    fast = chronocl.integrate(series, None, spec=spec, engine="opencl", slab=slab)
    assert_same(ref, fast)
    looked_up = chronocl.integrate(
        series, None, spec=spec, engine=opencl.OpenCLEngine(pieces=False), slab=slab
    )
    # thresholds decide on the exact opacity: the same bits as the lookups
    assert_same(looked_up, fast, atol=0 if modes.get(mode).opacity_threshold else 2e-6)


@settings(max_examples=examples(16))
@given(st.data())
def test_threshold_modes_skip_steps_that_cannot_pass(data):
    """first_hit and count skip a step whose voxels all lie below the raw value where the data
    TF's opacity times the largest time opacity could first exceed the threshold (`skip_bar`):
    the same bits as without skipping (t_index included), and the reference; opacity plateaus
    exactly at the threshold, hat-shaped time opacities, the TF as pieces or looked up."""
    dtype = data.draw(st.sampled_from(DTYPES))
    w = data.draw(st.integers(1, 23))
    shape = (w, data.draw(st.integers(1, 3)), data.draw(st.integers(1, 5)))
    shape += (data.draw(st.sampled_from([16, 21, 37])),)
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    raw = rng.random(shape) * 250
    if dtype != "float32":
        raw = np.round(raw)
    series = chronocl.TimeSeries.from_array(raw.astype(dtype))
    order = data.draw(
        st.one_of(st.sampled_from(["forward", "backward"]), st.permutations(range(w)))
    )
    spec = IntegrationSpec(
        mode=data.draw(st.sampled_from(["first_hit", "count"])),
        order=order if isinstance(order, str) else tuple(order),
        data_tf=data.draw(pieced_tfs()),
        time_tf=data.draw(time_tfs()),
        threshold=data.draw(st.sampled_from([0.05, 0.1, 0.5])),
    )
    pieces = data.draw(st.booleans())
    slab = data.draw(st.integers(1, shape[1] + 1))
    fast = chronocl.integrate(
        series, None, spec=spec, engine=opencl.OpenCLEngine(pieces=pieces), slab=slab
    )
    every_step = opencl.OpenCLEngine(pieces=pieces, skip_empty=False, row_blocks=False)
    assert_same(chronocl.integrate(series, None, spec=spec, engine=every_step), fast, atol=0)
    assert_same(chronocl.integrate(series, None, spec=spec, engine="numpy"), fast)


def test_skip_bar_of_each_mode():
    a_t = np.array([0.25, 0.5, 0.125])
    bar = tables.skip_bar(IntegrationSpec(mode="first_hit", threshold=0.1), a_t)
    assert bar == pytest.approx(0.2 / tables.PASS_SLACK) and bar < 0.2
    assert tables.skip_bar(IntegrationSpec(mode="count", threshold=0.1), np.zeros(3)) == np.inf
    assert tables.skip_bar(IntegrationSpec(mode="alpha", threshold=0.1), a_t) == 0.0
    edge = IntegrationSpec(mode="first_hit", threshold=0.1, enhance=Enhance("edge"))
    assert tables.skip_bar(edge, a_t) == 0.0  # enhancement may raise opacity


def runs_of(table: np.ndarray, x: np.ndarray, n: int) -> np.ndarray:
    """The kernels' evaluation of pieces `table` at LUT positions x, in float32: the value at 0
    plus each piece's slope times x's run through it (clamped to the piece)."""
    x0 = table[0]
    length = np.diff(np.append(x0, np.float32(n - 1))).astype(np.float32)
    out = np.repeat(table[1:5, :1], len(x), axis=1)
    for j in range(table.shape[1]):
        run = np.clip(x - x0[j], np.float32(0), length[j] if j + 1 < table.shape[1] else None)
        out = out + table[5:9, j : j + 1] * run.astype(np.float32)
    return out


def test_tf_pieces_follow_the_lut():
    tf = DataTF(points=[(0, 0, 0, 1, 0.02), (0.5, 0, 1, 0, 0.1), (1, 1, 0, 0, 0.5)])
    table = tables.tf_segments(tf.lut, [0, 1, 2, 3])
    assert table is not None and table.shape == (9, 3)  # 0.5 falls between entries 127, 128
    x = np.linspace(0, 255, 100_003, dtype=np.float32)
    got = runs_of(table, x, 256)
    want = lut_lerp32(tf.lut, x / np.float32(255)).T
    error = np.abs(got - want).max(axis=1)
    assert error.max() < 1e-6
    assert error[3] <= tables.opacity_error(table, 256) < tables.OPACITY_ERROR_MAX
    only_opacity = tables.tf_segments(tf.lut, [3])
    assert np.all(only_opacity[1:4] == 0) and np.all(only_opacity[5:8] == 0)
    many = DataTF(points=[(i / 11, i % 2, 0, 1 - i % 2, 1) for i in range(12)])
    assert tables.tf_segments(many.lut, [0, 1, 2]) is None  # more pieces than the kernels take


def test_tf_pieces_scale_by_each_steps_time_factors():
    table = tables.tf_segments(
        DataTF(points=[(0, 0, 0, 1, 0.0), (1, 1, 0, 0, 1.0)]).lut, [0, 1, 2, 3]
    )
    tc = np.array([[1, 1, 1, 1], [0.5, 0, 1, 0.25]], dtype=np.float32)
    flat = tables.timed(table, tc)
    s = table.shape[1]
    rows = flat[s:].reshape(2, 4, s + 1)
    assert np.array_equal(flat[:s], table[0])
    np.testing.assert_allclose(rows[1, 3], 0.25 * np.concatenate([table[4, :1], table[8]]))
    np.testing.assert_allclose(rows[1, 1], 0.0)


ISA_REPORT = (
    "o[0] = 0;\n#ifdef ISA_AVX2\n o[0] += 1;\n#endif\n#ifdef ISA_AVX512\n o[0] += 2;\n#endif"
)


def _isa(engine, cpu_paths: str) -> int:
    """The x86 paths common.h takes under `cpu_paths` (bit 0: AVX2, bit 1: AVX-512)."""
    from chronocl.engine.defines import CPU_PATHS

    defines = {"DATA_T": "float", "DATA_V": "float16", "VEC": 16, "LUT_N": 256}
    return _compiler_reports(engine, ISA_REPORT, {**defines, "CPU_PATHS": CPU_PATHS[cpu_paths]})


def test_cpu_paths_lower_the_x86_paths_a_build_takes():
    """CPU_PATHS takes away AVX-512 ("avx2") or both ("generic") and never adds a path the
    compiler's target lacks: asked of the compiler."""
    engine = opencl.OpenCLEngine()
    native = _isa(engine, "native")
    assert _isa(engine, "avx2") == native & 1
    assert _isa(engine, "generic") == 0
    with pytest.raises(ValueError, match="cpu_paths"):
        opencl.OpenCLEngine(cpu_paths="sse")


@pytest.mark.parametrize("mode", ["alpha", "max", "first_hit", "change"])
def test_every_x86_variant_the_cpu_runs_gives_the_same_bits(mode):
    """The AVX-512, AVX2 and portable variants of common.h's x86 paths (register time tables,
    LUT pairs, shuffled time colours: AVX2 without AVX-512 only) give the same bits: every
    variant this CPU can run is built and compared with the native one, float32 data through
    the rows kernels, with up to 32 steps (register tables) and more (loads), both orders."""
    engine = opencl.OpenCLEngine(pieces=False)  # the TF looked up: the LUT pairs
    native = _isa(engine, "native")
    variants = [v for v in ("avx2", "generic") if _isa(engine, v) != native]
    if engine.dc.is_cpu and native:  # an x86 CPU: there is a lower variant to compare
        assert variants
    rng = np.random.default_rng(7)
    for w in (9, 40):
        raw = (rng.random((w, 3, 5, 48)) * 120 - 10).astype(np.float32)
        series = chronocl.TimeSeries.from_array(raw)
        for order in ("forward", "backward"):
            spec = IntegrationSpec(
                mode=mode,
                order=order,
                data_tf=DataTF(points=ROW_TFS[1], value_range=(0, 100)),
                time_tf=chronocl.TimeTF.preset("rgb"),
            )
            want = chronocl.integrate(series, None, spec=spec, engine=engine)
            for cpu_paths in variants:
                other = opencl.OpenCLEngine(pieces=False, cpu_paths=cpu_paths)
                assert_same(chronocl.integrate(series, None, spec=spec, engine=other), want, 0)
