"""Chunked, overlapped brick transfers and compact device formats, on PoCL.

The copy path (host_ptr=False, what GPUs take) cuts a brick into chunks that travel while the
chunk before is integrated: it must give the very bits of the serial copy and of the host-pointer
path, its commands must be ordered by events as `chronocl.engine.transfer` says, and a compact
device format must equal the reference applied to equally converted data.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl import modes
from chronocl.core import values
from chronocl.core.errors import ChronoclError, InvalidParameterError, UnknownNameError
from chronocl.core.tuning import TUNING
from chronocl.engine import opencl as opencl_module
from chronocl.engine import transfer
from chronocl.engine.device import get_context
from chronocl.engine.device_formats import quantize, resolve_format, stored_dtype
from chronocl.engine.opencl import OpenCLEngine
from chronocl.engine.transfer import chunks_of
from chronocl.modes.spec import IntegrationSpec

from .strategies import examples, specs, windows
from .test_opencl import series_of

# Drawn transfer functions and data are often transparent on purpose; the warnings saying so
# (chronocl.integration.visibility) are tested in test_visibility.py.
pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

DTYPES = [np.float32, np.float64, np.uint8, np.uint16, np.int16]


def assert_identical(a: chronocl.Chronovolume, b: chronocl.Chronovolume) -> None:
    np.testing.assert_array_equal(a.rgba, b.rgba)
    if a.t_index is None:
        assert b.t_index is None
    else:
        np.testing.assert_array_equal(a.t_index, b.t_index)


def assert_close(a: chronocl.Chronovolume, b: chronocl.Chronovolume) -> None:
    np.testing.assert_allclose(a.rgba, b.rgba, atol=1e-5, rtol=0)
    if a.t_index is not None:
        np.testing.assert_array_equal(a.t_index, b.t_index)


def row_bytes(series: chronocl.TimeSeries, width: int, dtype=None) -> int:
    _, ny, nx = series.volume_shape
    dt = stored_dtype(series.dtype) if dtype is None else np.dtype(dtype)
    return width * ny * nx * dt.itemsize


@settings(max_examples=examples(20))  # four integrations per example
@given(st.data())
def test_overlapped_chunks_equal_serial_and_host_paths(data):
    """Any mode, odd shapes, any slabs and chunks of 1-3 rows: the same bits on every path."""
    u, sel = data.draw(windows(max_w=12, wide=data.draw(st.booleans())))
    spec = data.draw(specs(selection=sel))
    series = series_of(u, sel, data.draw(st.sampled_from(DTYPES)))
    slab = data.draw(st.integers(1, u.shape[1] + 1))
    chunk = data.draw(st.integers(1, 3)) * row_bytes(series, sel.width)
    host = chronocl.integrate(series, sel, spec=spec, slab=slab, engine=OpenCLEngine(host_ptr=True))
    serial = OpenCLEngine(host_ptr=False, overlap=False, chunk_bytes=0)
    overlapped = OpenCLEngine(host_ptr=False, chunk_bytes=chunk)
    assert_identical(host, chronocl.integrate(series, sel, spec=spec, slab=slab, engine=serial))
    assert_identical(host, chronocl.integrate(series, sel, spec=spec, slab=slab, engine=overlapped))
    assert overlapped.last_transfer is not None and serial.last_transfer.chunks == 1
    ref = chronocl.integrate(series, sel, spec=spec, engine="numpy")
    assert_close(ref, host)


@pytest.mark.parametrize("enhance", ["none", "edge"])
def test_events_order_every_chunk(monkeypatch, enhance):
    """An upload into a buffer waits for the kernels that last read it, a kernel for its upload
    and for the read-back of the outputs it overwrites, a read-back for its kernels: both in the
    events given and in the device's timestamps; the three roles run on three queues."""
    log: list = []
    monkeypatch.setattr(
        opencl_module, "run_chunks", functools.partial(transfer.run_chunks, log=log)
    )
    rng = np.random.default_rng(2)
    series = chronocl.TimeSeries.from_array(rng.random((6, 11, 5, 37), dtype=np.float32))
    engine = OpenCLEngine(host_ptr=False, chunk_bytes=2 * row_bytes(series, 6))
    spec = IntegrationSpec(mode="max", enhance=chronocl.Enhance(enhance))
    got = chronocl.integrate(series, None, spec=spec, engine=engine)
    assert_close(chronocl.integrate(series, None, spec=spec, engine="numpy"), got)

    n = engine.last_transfer.chunks
    assert n >= 4
    by = {(kind, j): (slot, evs, after) for kind, j, slot, evs, after in log}
    queues = {
        kind: {ev.command_queue.int_ptr for j in range(n) for ev in by[kind, j][1]}
        for kind in ("upload", "kernel", "download")
    }
    assert all(len(q) == 1 for q in queues.values())
    assert len(set().union(*queues.values())) == 3

    def same(a, b):
        return {e.int_ptr for e in a} == {e.int_ptr for e in b}

    for j in range(n):
        slot, (upload,), after = by["upload", j]
        assert slot == j % 2
        kernels = by["kernel", j][1]
        reads = by["download", j][1]
        assert same(after, by["kernel", j - 2][1] if j >= 2 else [])
        assert same(by["kernel", j][2], [upload] + (by["download", j - 2][1] if j >= 2 else []))
        assert same(by["download", j][2], kernels)
        start = min(e.profile.start for e in kernels)
        assert upload.profile.end <= start
        assert max(e.profile.end for e in kernels) <= min(e.profile.start for e in reads)
        if j >= 2:
            assert max(e.profile.end for e in by["kernel", j - 2][1]) <= upload.profile.start
            assert max(e.profile.end for e in by["download", j - 2][1]) <= start
    stats = engine.last_transfer
    assert stats.upload_bytes >= series.nbytes if hasattr(series, "nbytes") else True
    assert stats.kernel_s > 0 and stats.upload_s > 0 and stats.overlap is not None


def test_chunks_cover_the_crop_with_their_halo():
    cs = chunks_of(10, slice(1, 9), 1, 100, 350)  # 3 rows per chunk, 1 output row
    assert [(c.a, c.b, c.r0, c.r1) for c in cs] == [(a, a + 1, a - 1, a + 2) for a in range(1, 9)]
    cs = chunks_of(10, slice(0, 10), 0, 100, 350)
    assert [(c.a, c.b) for c in cs] == [(0, 3), (3, 6), (6, 9), (9, 10)]
    assert len(chunks_of(10, slice(0, 10), 1, 100, 0)) == 1
    assert all(c.rows >= 1 for c in chunks_of(3, slice(0, 3), 1, 10**9, None))


def quantized_spec(spec: IntegrationSpec, value_range) -> IntegrationSpec:
    """`spec` normalising over `value_range` (a constant range: the data's own, as before)."""
    if not value_range[1] > value_range[0]:
        return spec
    return dataclasses.replace(
        spec, data_tf=dataclasses.replace(spec.data_tf, value_range=tuple(value_range))
    )


@settings(max_examples=examples(20))
@given(st.data())
def test_compact_formats_equal_the_reference_on_equally_converted_data(data):
    """uint8/uint16 quantised over the value range and float16: the engine's result is the
    reference's on the data converted the same way (kernels see q with range 0..q_max)."""
    u, sel = data.draw(windows(max_w=9, wide=data.draw(st.booleans())))
    spec = data.draw(specs(selection=sel))
    stored = data.draw(st.sampled_from([np.float32, np.float64, np.uint16, np.int16]))
    series = series_of(u, sel, stored)
    choices = ["uint8"] if stored in (np.uint16, np.int16) else ["uint8", "uint16", "float16"]
    name = data.draw(st.sampled_from(choices))
    value_range = (series.vmin, series.vmax)
    fmt = resolve_format(name, series.dtype, value_range)
    raw = series.read_brick(range(series.n_steps)).swapaxes(0, 1)  # (T, Z, Y, X)
    if fmt.quant_max:
        converted = quantize(raw, value_range, fmt.quant_max).astype(fmt.dtype)
    else:
        converted = raw.astype(np.float16).astype(np.float32)
    same = chronocl.TimeSeries.from_array(np.ascontiguousarray(converted))
    ref = chronocl.integrate(same, sel, spec=quantized_spec(spec, fmt.device_range), engine="numpy")
    engine = OpenCLEngine(
        host_ptr=data.draw(st.booleans()),
        chunk_bytes=data.draw(st.sampled_from([None, row_bytes(series, sel.width, fmt.dtype)])),
    )
    got = chronocl.integrate(series, sel, spec=spec, engine=engine, device_format=name)
    assert_close(ref, got)
    assert got.metadata.get("device_format", "auto") == name  # a lossy result says so


@pytest.mark.parametrize("mode", modes.names())
def test_uint8_device_format_is_exact_for_byte_valued_data(mode):
    """Float data that are whole multiples of 1/255 of their range lose nothing in uint8."""
    rng = np.random.default_rng(9)
    data = (rng.integers(0, 256, (5, 3, 4, 21)) / 255.0).astype(np.float32)
    data[0, 0, 0, 0], data[-1, -1, -1, -1] = 0.0, 1.0
    series = chronocl.TimeSeries.from_array(data)
    # Normalised by each series' own full range, byte values land on the same u.
    spec = IntegrationSpec(mode=mode, threshold=0.2, data_tf=chronocl.DataTF(value_range="global"))
    as_bytes = chronocl.TimeSeries.from_array(np.round(data * 255).astype(np.uint8))
    ref = chronocl.integrate(as_bytes, None, spec=spec, engine="numpy")
    engine = OpenCLEngine(host_ptr=False)
    assert_close(
        ref, chronocl.integrate(series, None, spec=spec, engine=engine, device_format="uint8")
    )
    assert engine.device_format == "auto"  # integrate() configured a copy


@given(
    st.floats(-1e4, 1e4),
    st.floats(1e-3, 1e4),
    st.sampled_from(["uint8", "uint16", "float16"]),
    st.integers(0, 2**31),
)
def test_max_error_bounds_the_error_in_u(lo, span, name, seed):
    """Values inside the range come back within `max_error` of their u (plus float32 rounding)."""
    hi = lo + span
    try:
        fmt = resolve_format(name, np.float32, (lo, hi))
    except InvalidParameterError:
        assert name == "float16"
        return
    v = np.random.default_rng(seed).uniform(lo, hi, 200).astype(np.float32)
    enc = fmt.encode(v)
    lo_d, hi_d = fmt.device_range
    u_dev = values.normalize(enc.astype(np.float32), lo_d, hi_d).astype(np.float64)
    u = values.normalize(v, lo, hi).astype(np.float64)
    assert np.max(np.abs(u_dev - u)) <= fmt.max_error * (1 + 1e-3) + 1e-5


@pytest.mark.parametrize(
    ("name", "dtype", "value_range", "error", "match"),
    [
        ("int8", np.float32, (0, 1), UnknownNameError, "unknown device format 'int8'"),
        ("uint16", np.uint8, (0, 255), InvalidParameterError, "not fewer than the 1"),
        ("float16", np.uint8, (0, 255), InvalidParameterError, "use auto"),
        ("float16", np.uint16, (0, 9), InvalidParameterError, "not fewer than the 2"),
        ("uint16", np.int16, (-5, 9), InvalidParameterError, "not fewer"),
        ("float16", np.float32, (0, 1e6), InvalidParameterError, "cannot hold the value range"),
        ("float16", np.float32, (1000, 1001), InvalidParameterError, "coarser than uint8"),
    ],
)
def test_nonsense_formats_are_refused(name, dtype, value_range, error, match):
    with pytest.raises(error, match=match) as info:
        resolve_format(name, np.dtype(dtype), value_range)
    assert isinstance(info.value, ChronoclError) and isinstance(info.value, ValueError)
    assert "\n" not in str(info.value)


def test_formats_that_send_the_data_as_stored():
    assert resolve_format("auto", np.float64, (0, 1)).dtype == np.float32
    assert not resolve_format("uint8", np.uint8, (0, 255)).converts
    assert resolve_format("float32", np.uint8, (0, 255)).dtype == np.float32
    assert resolve_format("uint8", np.int16, (-3, 7)).quant_max == 255
    assert resolve_format("float16", np.float32, (0, 1)).max_error < 1e-3


def test_api_refusals_come_before_any_work():
    series = chronocl.TimeSeries.from_array(np.zeros((2, 2, 2, 2), dtype=np.uint8))
    with pytest.raises(UnknownNameError, match="choose one of auto, float32"):
        chronocl.integrate(series, device_format="half")
    with pytest.raises(InvalidParameterError, match="applies to the opencl engine"):
        chronocl.integrate(series, engine="numpy", device_format="float32")
    with pytest.raises(InvalidParameterError, match="not fewer than the 1"):
        chronocl.integrate(series, device_format="uint16")
    with pytest.raises(UnknownNameError):
        OpenCLEngine(device_format="int4")


def test_half_builds_are_silent_on_a_cold_cache(tmp_path):
    """Every integrate kernel built for float16 bricks (HALF_DATA), vectorised and scalar,
    aligned or not, with each enhancement: no compiler warning (as tests/test_kernel_build.py
    checks for the other brick types)."""
    import json
    import subprocess
    import sys

    from chronocl.engine import program

    from .test_kernel_build import BUILD_ALL, DRIVER_NOISE, cold_env, integration_combinations

    todo = []
    for file in sorted({f"{modes.get(m).kernel}.cl" for m in modes.names()}):
        name = next(m for m in modes.names() if f"{modes.get(m).kernel}.cl" == file)
        base = next(c for c in integration_combinations(name) if c["DATA_T"] == "float")
        for enh, vec, aligned in (
            (0, 16, True),
            (0, 16, False),
            (0, 1, False),
            (1, 1, False),
            (2, 1, False),
        ):
            defines = {**base, "ENHANCE": enh, "VEC": vec, "ALIGNED": aligned}
            defines.update(DATA_T="half", DATA_V="float16" if vec == 16 else "float")
            defines["HALF_DATA"] = True
            todo.append((file, list(program.build_options(defines)), True))
    result = subprocess.run(
        [sys.executable, "-c", BUILD_ALL, DRIVER_NOISE],
        input=json.dumps(todo),
        capture_output=True,
        text=True,
        env=cold_env(tmp_path),
        cwd=tmp_path,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    said = json.loads(result.stdout)["said"]
    assert not said, f"{len(said)} of {len(todo)} builds warned; the first: {said[0]}"


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """A float32 and a uint8 store, small."""
    folder = tmp_path_factory.mktemp("stores")
    rng = np.random.default_rng(4)
    f32 = rng.random((4, 3, 5, 21)).astype(np.float32)
    chronocl.TimeSeries.from_array(f32).save(folder / "f.zarr")
    chronocl.TimeSeries.from_array((f32 * 255).astype(np.uint8)).save(folder / "b.zarr")
    return folder


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["integrate", "f.zarr", "o.zarr", "--device-format", "int8"], "unknown device format"),
        (["integrate", "b.zarr", "o.zarr", "--device-format", "uint16"], "not fewer than the 1"),
        (
            ["integrate", "f.zarr", "o.zarr", "--engine", "numpy", "--device-format", "uint8"],
            "applies to the opencl engine",
        ),
        (["render", "b.zarr", "-o", "o.png", "--device-format", "float16"], "use auto"),
        (["render", "f.zarr", "-o", "o.png", "--device-format", "half"], "choose one of auto"),
    ],
)
def test_cli_refuses_nonsense_device_formats(stores, tmp_path, monkeypatch, args, needle):
    """In this process (the CLI's entry point turns the error into one line and exit 2, as the
    first case checks through `python -m chronocl`): the error, one line, nothing written."""
    import shutil

    from typer.testing import CliRunner

    from chronocl.cli.app import app

    from .test_cli import assert_one_line_error, cli

    for name in ("f.zarr", "b.zarr"):
        shutil.copytree(stores / name, tmp_path / name)
    before = sorted(p.name for p in tmp_path.iterdir())
    if "int8" in args:
        assert_one_line_error(cli(*args, cwd=tmp_path), needle)
    else:
        monkeypatch.chdir(tmp_path)
        result = CliRunner().invoke(app, args)
        assert isinstance(result.exception, ChronoclError), result.output
        assert result.exception.exit_code == 2
        assert needle in str(result.exception) and "\n" not in str(result.exception)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written


def test_cli_device_format_gives_the_api_result(stores, tmp_path):
    from .test_cli import assert_one_line_error, cli

    out = tmp_path / "o.zarr"
    args = ["integrate", stores / "f.zarr", out, "--mode", "max", "--device-format", "uint8"]
    # max compares raw values: quantising over the fitted range would tie those beyond it
    assert_one_line_error(cli(*args), "give --value-range series, or use float16 or auto")
    assert not out.exists()
    result = cli(*args, "--value-range", "series")
    assert result.returncode == 0, result.stderr
    series = chronocl.open_series(stores / "f.zarr")
    api = chronocl.integrate(series, mode="max", device_format="uint8", value_range="series")
    got = chronocl.Chronovolume.load(out)
    np.testing.assert_array_equal(got.rgba, api.rgba)
    np.testing.assert_array_equal(got.t_index, api.t_index)


def test_bench_transfer_reports_null_on_cpu_and_figures_when_forced():
    import importlib.util
    import json
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "bench" / "transfer.py"
    kept = list(sys.path)  # the script puts bench/ first: taken out again after
    sys.path.insert(0, str(path.parent))
    try:
        spec = importlib.util.spec_from_file_location("chronocl_bench_transfer", path)
        bench = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(bench)
    finally:
        sys.path[:] = kept
    is_cpu = get_context(None).is_cpu  # PoCL (CI): a CPU device; a GPU copies and measures
    overlap = bench.transfer_overlap()
    if is_cpu:
        assert overlap is None
    else:
        assert isinstance(overlap, float) and np.isfinite(overlap) and overlap > 0
    figures = bench.run(None, 16, 4, "max", 1, force=True)
    json.dumps(figures)
    assert figures["is_cpu"] is is_cpu
    if is_cpu:  # forced through the copy path, but no transfer to overlap on a CPU device
        assert figures["transfer_overlap"] is None
    else:
        assert figures["transfer_overlap"] == figures["formats"]["auto"]["overlapped"]["overlap"]
        assert figures["transfer_overlap"] > 0
    up = {name: f["bytes_up"] for name, f in figures["formats"].items()}
    assert up["auto"] == 16**3 * 4 * 4 and up["float16"] == up["uint16"] == 2 * up["uint8"]
    auto = figures["formats"]["auto"]["overlapped"]
    assert auto["kernel_s"] > 0 and auto["upload_s"] > 0 and auto["wall_s"] > 0


@pytest.mark.parametrize("name", ["float16", "uint8", "uint16", "float32", "auto"])
def test_conversions_split_over_threads_equal_one_pass(name):
    n = TUNING.format_parallel_min * 2 + 7  # above the threshold: split
    v = np.random.default_rng(3).normal(0, 3e4, n).astype(np.float32)
    fmt = resolve_format(name, np.float32, (-1e4, 2e4))
    split = fmt.encode(v)
    np.testing.assert_array_equal(split, fmt._encode(v, np.empty(v.shape, fmt.dtype)))
    if name == "float16":
        assert np.isfinite(split).all()  # saturated, not inf


@pytest.mark.parametrize("mode", ["max", "additive"])
def test_streamed_runs_send_the_same_device_format(stores, tmp_path, mode):
    """Slab by slab into a store (and a resume key of its own): the in-memory result."""
    from chronocl.integration.runs.streaming import integrate_to_store

    series = chronocl.open_series(stores / "f.zarr")
    out = tmp_path / "s.zarr"
    whole = {"value_range": "series"}  # max: quantising over a range that clips is refused
    integrate_to_store(series, None, out, mode=mode, slab=1, device_format="uint16", **whole)
    got = chronocl.Chronovolume.load(out)
    api = chronocl.integrate(series, mode=mode, device_format="uint16", **whole)
    np.testing.assert_allclose(got.rgba, api.rgba, atol=1e-6, rtol=0)
    if api.t_index is not None:
        np.testing.assert_array_equal(got.t_index, api.t_index)
    with pytest.raises(InvalidParameterError, match="applies to the opencl engine"):
        integrate_to_store(series, None, tmp_path / "n.zarr", engine="numpy", device_format="uint8")
