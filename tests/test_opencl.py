"""The OpenCL engine on PoCL equals the numpy reference; every fast path equals the general path."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl import modes
from chronocl.core.errors import EngineUnavailableError, KernelBuildError
from chronocl.core.tuning import TUNING
from chronocl.engine.device import list_devices
from chronocl.engine.opencl import OpenCLEngine
from chronocl.modes.spec import IntegrationSpec

from .strategies import examples, specs, windows

# Drawn transfer functions and data are often transparent on purpose; the warnings saying so
# (chronocl.integration.visibility) are tested in test_visibility.py.
pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


def series_of(u: np.ndarray, sel, dtype=np.float32) -> chronocl.TimeSeries:
    raw = np.zeros((sel.n_steps, *u.shape[1:]), dtype=np.float32)
    raw[list(sel.steps)] = u
    raw[0].flat[0], raw[-1].flat[-1] = 0.0, 1.0
    if np.dtype(dtype) == np.uint8:
        raw = np.round(raw * 255).astype(np.uint8)
    return chronocl.TimeSeries.from_array(raw.astype(dtype))


def assert_same(a: chronocl.Chronovolume, b: chronocl.Chronovolume, atol: float = 1e-5) -> None:
    np.testing.assert_allclose(a.rgba, b.rgba, atol=atol, rtol=0)
    if a.t_index is None:
        assert b.t_index is None
    else:
        np.testing.assert_array_equal(a.t_index, b.t_index)


@settings(max_examples=examples(40))
@given(st.data())
def test_opencl_equals_reference(data):
    """Invariant 4 (and 3 on the device): any mode x order x enhancement, odd shapes, any bricks."""
    u, sel = data.draw(windows(max_w=40, wide=data.draw(st.booleans())))
    spec = data.draw(specs(selection=sel))
    dtype = data.draw(st.sampled_from([np.float32, np.float64, np.uint8, np.uint16, np.int16]))
    series = series_of(u, sel, dtype)
    slab = data.draw(st.integers(1, u.shape[1] + 1))
    ref = chronocl.integrate(series, sel, spec=spec, engine="numpy")
    ocl = chronocl.integrate(series, sel, spec=spec, engine="opencl", slab=slab)
    assert_same(ref, ocl)


@settings(max_examples=examples(20))  # six integrations per example
@given(st.data())
def test_fast_paths_equal_the_general_path(data):
    """Early exit, uint8 LUT indexing, empty skipping, host pointers against the general path."""
    u, sel = data.draw(windows(max_w=16, wide=True))
    spec = data.draw(specs(selection=sel))
    series = series_of(u, sel, np.uint8)
    flags = ("host_ptr", "early_exit", "quantized", "skip_empty")
    general = OpenCLEngine(**dict.fromkeys(flags, False))
    fast = OpenCLEngine(**dict.fromkeys(flags, True))
    base = chronocl.integrate(series, sel, spec=spec, engine=general)
    assert_same(base, chronocl.integrate(series, sel, spec=spec, engine=fast))
    for flag in flags:
        options = {**dict.fromkeys(flags, False), flag: True}
        one = chronocl.integrate(series, sel, spec=spec, engine=OpenCLEngine(**options))
        assert_same(base, one)


@pytest.mark.parametrize("dtype", [np.float32, np.uint8, np.uint16, np.int16])
@pytest.mark.parametrize("mode", modes.names())
def test_aligned_vector_path_equals_reference(mode, dtype):
    """x a multiple of 16 with 64-byte aligned buffers: the kernels use vector pointers."""
    rng = np.random.default_rng(7)
    u = rng.random((9, 3, 5, 48), dtype=np.float32)
    u[rng.random(u.shape) < 0.5] = 0.0  # empty lanes next to live ones
    series = series_of(u, chronocl.Selection(tuple(range(9)), 9), dtype)
    for order in ("forward", "backward"):
        spec = IntegrationSpec(mode=mode, order=order, threshold=0.1)
        ref = chronocl.integrate(series, None, spec=spec, engine="numpy")
        assert_same(ref, chronocl.integrate(series, None, spec=spec))
        assert_same(ref, chronocl.integrate(series, None, spec=spec, slab=2))


@pytest.mark.parametrize("mode", modes.names())
@pytest.mark.parametrize("local_size", [None, (1, 1, 2), (4, 2, 2)])
def test_padded_launches_stay_inside_their_slab(mode, local_size):
    """x = 150 (9 vectors + 6, padded to whole work-groups), z padded by the local size: every
    write lands in the slab's rows, and the result equals the reference."""
    rng = np.random.default_rng(11)
    data = rng.random((5, 3, 3, 150), dtype=np.float32)
    series = chronocl.TimeSeries.from_array(data)
    spec = IntegrationSpec(mode=mode)
    engine = OpenCLEngine(local_size=local_size)
    sel = chronocl.Selection(tuple(range(5)), 5)
    brick = series.read_brick(sel.steps)
    rgba = np.full((4, 3, 150, 4), 7.0, dtype=np.float32)  # row 3 is a sentinel
    t_index = np.full((4, 3, 150), 77, dtype=np.int32)
    positions = spec.time_tf.positions_of(sel.steps, 5)
    order = np.arange(5)
    engine.accumulate(
        brick,
        slice(0, 3),
        sel.steps,
        positions,
        order,
        spec,
        (series.vmin, series.vmax),
        (rgba[:3], t_index[:3]),
    )
    assert np.all(rgba[3] == 7.0) and np.all(t_index[3] == 77)
    ref = chronocl.integrate(series, sel, spec=spec, engine="numpy")
    assert_same(ref, chronocl.integrate(series, sel, spec=spec, engine=engine))


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
def test_first_hit_threshold_on_an_opacity_plateau(dtype):
    """Opacity exactly at the threshold is not a hit, in both engines alike."""
    rng = np.random.default_rng(5)
    series = series_of(
        rng.random((4, 2, 3, 37), dtype=np.float32), chronocl.Selection(tuple(range(4)), 4), dtype
    )
    for level in (0.1, 0.3, 0.7):
        spec = IntegrationSpec(
            mode="first_hit",
            threshold=level,
            data_tf=chronocl.DataTF(points=[(0, 1, 1, 1, level), (1, 1, 1, 1, level)]),
        )
        ref = chronocl.integrate(series, None, spec=spec, engine="numpy")
        assert_same(ref, chronocl.integrate(series, None, spec=spec))


def test_early_exit_on_opaque_front_and_window_of_40():
    rng = np.random.default_rng(3)
    data = rng.random((40, 5, 7, 13)).astype(np.float32)
    data[0] = 1.0  # the first step is opaque everywhere: the rest is skipped
    series = chronocl.TimeSeries.from_array(data)
    spec = IntegrationSpec(
        mode="alpha", data_tf=chronocl.DataTF(points=[(0, 1, 1, 1, 0), (1, 1, 1, 1, 1)])
    )
    ref = chronocl.integrate(series, "0:40", spec=spec, engine="numpy")
    ocl = chronocl.integrate(series, "0:40", spec=spec)
    assert_same(ref, ocl)
    np.testing.assert_allclose(ocl.rgba[..., 3], 1.0)


def test_device_tables_are_kept_and_an_edited_tf_gets_its_own():
    """An engine keeps the device tables of its last TUNING.lut_cache integrations (read-only, so no
    caller can change them), and an edited data TF, time TF, window or value range builds
    tables of its own: each integration equals the reference."""

    engine = OpenCLEngine()
    spec = IntegrationSpec(mode="max")
    pos = np.linspace(0.0, 1.0, 5)
    first = engine.luts(spec, pos, False, (0.0, 1.0))
    assert engine.luts(spec, pos.copy(), False, (0.0, 1.0)) is first
    assert not any(a.flags.writeable for a in first if isinstance(a, np.ndarray))
    with pytest.raises(ValueError):
        first[0][0, 0] = 1.0
    edited = IntegrationSpec(
        mode="max", data_tf=chronocl.DataTF(points=[(0, 1, 0, 0, 0), (1, 1, 0, 0, 1)])
    )
    assert not np.array_equal(engine.luts(edited, pos, False, (0.0, 1.0))[0], first[0])
    assert not np.array_equal(engine.luts(spec, pos[::-1], False, (0.0, 1.0))[1], first[1])
    assert engine.luts(spec, pos, False, (0.5, 1.0))[3] != first[3]  # the skip cut
    assert first[4] is not None  # the default TF as pieces, but not for an engine without them
    assert engine.with_options(pieces=False).luts(spec, pos, False, (0.0, 1.0))[4] is None
    for n in range(2 * TUNING.lut_cache):  # the one in use stays, the others come and go
        assert engine.luts(spec, pos, False, (0.0, 1.0)) is first
        engine.luts(spec, np.linspace(0.0, 1.0, n + 2), False, (0.0, 1.0))
    assert len(engine._luts) == TUNING.lut_cache
    assert engine.luts(spec, pos, False, (0.0, 1.0)) is first
    # points given to a preset that does not use them (a TF file may carry them) are dropped
    unused = chronocl.TimeTF(color=chronocl.TimeColor("rgb", points=[[0, 0, 0, 1], [1, 1, 0, 0]]))
    got = engine.luts(IntegrationSpec(mode="max", time_tf=unused), pos, False, (0.0, 1.0))
    rgb = chronocl.TimeTF(color=chronocl.TimeColor("rgb"))
    plain = engine.luts(IntegrationSpec(mode="max", time_tf=rgb), pos, False, (0.0, 1.0))
    assert len(got) == len(plain)
    for a, b in zip(got, plain, strict=True):
        np.testing.assert_array_equal(a, b)

    data = np.random.default_rng(8).random((6, 3, 4, 37)).astype(np.float32)
    series = chronocl.TimeSeries.from_array(data)
    for mode in ("max", "alpha", "first_hit"):
        for points in ([(0, 1, 1, 1, 0), (1, 1, 1, 1, 1)], [(0, 0, 1, 0, 0.2), (1, 1, 0, 0, 0.9)]):
            for window in ("0:6", "1:4"):
                spec = IntegrationSpec(
                    mode=mode, data_tf=chronocl.DataTF(points=points), threshold=0.3
                )
                ref = chronocl.integrate(series, window, spec=spec, engine="numpy")
                assert_same(ref, chronocl.integrate(series, window, spec=spec, engine=engine))


def test_window_larger_than_a_brick_is_split():
    """A device that holds only a few rows gets more bricks, not a failure."""
    data = np.random.default_rng(4).random((12, 9, 6, 5)).astype(np.float32)
    series = chronocl.TimeSeries.from_array(data)
    small = OpenCLEngine(max_brick_bytes=4 * 12 * 6 * 5 * 4)  # four z-rows of the window
    calls = []
    accumulate = small.accumulate
    small.accumulate = lambda brick, *a: calls.append(brick.shape) or accumulate(brick, *a)
    ref = chronocl.integrate(series, "0:12", "alpha", engine="numpy", enhance="edge")
    assert_same(ref, chronocl.integrate(series, "0:12", "alpha", engine=small, enhance="edge"))
    assert len(calls) == 5  # 2 output rows + 2 halo rows per brick over 9 rows
    assert all(shape[0] <= 4 for shape in calls)


def test_window_that_cannot_fit_one_row_names_the_limit():
    series = chronocl.TimeSeries.from_array(np.zeros((12, 3, 6, 5), dtype=np.float32))
    tiny = OpenCLEngine(max_brick_bytes=3 * 6 * 5 * 4)
    with pytest.raises(chronocl.ChronoclError, match="window of at most 1 steps"):
        chronocl.integrate(series, "0:12", "alpha", engine=tiny, enhance="edge")


def test_unknown_device_names_the_available_ones():
    with pytest.raises(EngineUnavailableError, match="no OpenCL device matches 'quantum'") as info:
        chronocl.integrate(chronocl.TimeSeries.from_array(np.zeros((1, 1, 1, 1))), device="quantum")
    assert list_devices()[0].name in str(info.value)
    assert isinstance(info.value, RuntimeError)


def test_build_error_shows_options_device_and_log():
    from chronocl.engine.device import get_context
    from chronocl.engine.program import build

    dc = get_context()
    with pytest.raises(KernelBuildError) as info:
        build(dc, "broken.cl", {"LUT_N": 256}, text="__kernel void f() { this is not C; }")
    message = str(info.value)
    assert "broken.cl" in message and "-DLUT_N=256" in message
    assert dc.info.name in message and "error" in message.lower()


def test_the_default_device_builds_kernels(monkeypatch):
    from chronocl.engine.device import build_problem, pick_device, usable_devices

    monkeypatch.delenv("CHRONOCL_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    info, _ = pick_device(None)
    assert build_problem(info.index) is None
    assert info in usable_devices()


def test_a_device_whose_compiler_fails_is_passed_over_or_named(monkeypatch):
    """PyPI's PoCL 3.0 (LLVM 14) lists its device on CPUs its LLVM does not know (AMD Zen 4)
    and fails every build: the default skips it; with no device left the error names each
    device's problem and the fix."""
    from chronocl.engine import device

    monkeypatch.delenv("CHRONOCL_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    found = list_devices()
    real = device.build_problem
    broken = {found[0].index}

    def problem(index):
        return "unknown target CPU 'generic'" if index in broken else real(index)

    monkeypatch.setattr(device, "build_problem", problem)
    others = [d for d in found[1:] if real(d.index) is None]
    if others:
        assert device.pick_device(None)[0].index != found[0].index
        assert found[0] not in device.usable_devices()
    broken.update(d.index for d in found)
    with pytest.raises(EngineUnavailableError) as info:
        device.pick_device(None)
    message = str(info.value)
    assert "unknown target CPU 'generic'" in message and found[0].label in message
    assert "apt-get install pocl-opencl-icd" in message and "--engine numpy" in message
    assert device.usable_devices() == []
    from chronocl.report.scaling import resolve_devices

    monkeypatch.setenv("CHRONOCL_DEVICE", found[0].index)  # a chosen device changes nothing
    with pytest.raises(EngineUnavailableError, match="unknown target CPU 'generic'"):
        resolve_devices("all")


def test_no_platform_gives_install_hint(tmp_path):
    env = {**os.environ, "OCL_ICD_VENDORS": str(tmp_path / "none"), "CHRONOCL_DEVICE": ""}
    store = tmp_path / "s.zarr"
    chronocl.TimeSeries.from_array(np.zeros((2, 2, 2, 2))).save(store)
    result = subprocess.run(
        [sys.executable, "-m", "chronocl", "integrate", str(store), str(tmp_path / "o.zarr")],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert result.returncode == 2
    assert "pyopencl[pocl]" in result.stderr and "pocl-opencl-icd" in result.stderr
    assert "--engine numpy" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "o.zarr").exists()


def test_kernels_load_from_an_installed_wheel(tmp_path):
    """A non-editable install must carry kernels/ (a missing force-include is silent)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(tmp_path / "dist"),
            root,
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    wheel = next((tmp_path / "dist").glob("chronocl-*.whl"))
    site = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--target",
            str(site),
            str(wheel),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    code = (
        "import numpy as np, chronocl; from chronocl.engine.program import kernel_dir; "
        "print(chronocl.__file__); print(kernel_dir()); "
        "s = chronocl.TimeSeries.from_array(np.random.default_rng(0).random((3, 2, 3, 4))); "
        "print(chronocl.integrate(s, mode='max').t_index.max())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(site)},
    )
    assert out.returncode == 0, out.stderr
    module_file, kernels, t_max = out.stdout.split()
    assert module_file.startswith(str(site)) and kernels.startswith(str(site))
    assert int(t_max) in (0, 1, 2)


@settings(max_examples=examples(25))
@given(st.data())
def test_change_in_byte_lanes_equals_reference(data):
    """change on bytes clipped to whole-number bounds is compared in byte lanes; other bounds
    take the float path. Few distinct values, so equal changes (ties) are everywhere."""
    w = data.draw(st.integers(1, 40))
    nx = data.draw(st.sampled_from([16, 33, 48]))
    seed = data.draw(st.integers(0, 2**16))
    raw = np.random.default_rng(seed).integers(0, 6, (w, 2, 3, nx)).astype(np.uint8) * 50
    series = chronocl.TimeSeries.from_array(raw)
    bounds = data.draw(st.sampled_from([(0, 255), (50, 200), (10.5, 200.25), (-3, 300)]))
    order = data.draw(st.sampled_from(["forward", "backward", tuple(range(w))[::-1]]))
    tf = chronocl.DataTF(points=[(0, 1, 1, 1, 0), (1, 1, 1, 1, 1)], value_range=bounds)
    spec = IntegrationSpec(mode="change", order=order, data_tf=tf)
    ref = chronocl.integrate(series, None, spec=spec, engine="numpy")
    assert_same(ref, chronocl.integrate(series, None, spec=spec, slab=2))
