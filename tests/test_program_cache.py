"""Built programs' binaries kept between processes (`chronocl.engine.program`,
CHRONOCL_PROGRAM_CACHE): a second build loads the binary and computes the same, a damaged or
refused binary is built again from source and replaced, and a cache that cannot be written or
is turned off changes nothing but speed."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from chronocl.engine import program
from chronocl.engine.device import get_context

SOURCE = """
__kernel void f(__global float *a, const int n) {
    int i = get_global_id(0);
    if (i < n) a[i] = sqrt(a[i]) * SCALE + (float)n;
}
"""
OPTIONS = ("-DSCALE=3.0f",)


def run(prog) -> np.ndarray:
    dc = get_context()
    a = np.arange(37, dtype=np.float32)
    buf = cl.Buffer(dc.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=a)
    kern = cl.Kernel(prog, "f")
    kern.set_args(buf, np.int32(a.size))
    with dc.lock:
        cl.enqueue_nd_range_kernel(dc.queue, kern, (a.size,), None)
        cl.enqueue_copy(dc.queue, a, buf)
    return a


@pytest.fixture
def cache(monkeypatch, tmp_path):
    monkeypatch.setenv(program.CACHE_VAR, str(tmp_path / "programs"))
    return tmp_path / "programs"


def no_source_builds(monkeypatch) -> None:
    """Make any build from source fail: what still builds came from a binary."""
    real = cl.Program

    def binaries_only(context, *args):
        if len(args) == 1 and isinstance(args[0], str):
            raise AssertionError("built from source")
        return real(context, *args)

    monkeypatch.setattr(cl, "Program", binaries_only)


def test_a_second_build_loads_the_binary_and_computes_the_same(cache, monkeypatch):
    dc = get_context()
    built = program._compile(dc, "f.cl", SOURCE, OPTIONS)
    path = program.binary_path(dc, SOURCE, OPTIONS)
    assert path.parent == cache and path.is_file()
    assert not [p for p in cache.iterdir() if p.name.startswith(".")]  # nothing left aside
    no_source_builds(monkeypatch)
    loaded = program._compile(dc, "f.cl", SOURCE, OPTIONS)
    np.testing.assert_array_equal(run(loaded), run(built))
    with pytest.raises(AssertionError, match="from source"):  # the spy does catch source builds
        program._compile(dc, "f.cl", SOURCE, ("-DSCALE=2.0f",))


def test_the_key_holds_the_source_the_options_and_the_pocl_settings(cache, monkeypatch):
    dc = get_context()
    one = program.binary_path(dc, SOURCE, OPTIONS)
    assert program.binary_path(dc, SOURCE, OPTIONS) == one
    assert program.binary_path(dc, SOURCE + " ", OPTIONS) != one
    assert program.binary_path(dc, SOURCE, ("-DSCALE=2.0f",)) != one
    monkeypatch.setenv("POCL_CPU_TARGET", "x86-64")  # another target compiles other code
    assert program.binary_path(dc, SOURCE, OPTIONS) != one
    monkeypatch.delenv("POCL_CPU_TARGET")
    monkeypatch.setenv("POCL_CACHE_DIR", "/elsewhere")  # where PoCL caches changes no binary
    assert program.binary_path(dc, SOURCE, OPTIONS) == one
    # pyopencl's own folder (PYOPENCL_HOME, set on import) is another in every virtual
    # environment: CI's second interpreter must find the first's binaries
    monkeypatch.setenv("PYOPENCL_HOME", "/another/venv/site-packages/pyopencl")
    assert program.binary_path(dc, SOURCE, OPTIONS) == one
    monkeypatch.setenv("PYOPENCL_BUILD_OPTIONS", "-cl-fast-relaxed-math")  # pyopencl adds it
    assert program.binary_path(dc, SOURCE, OPTIONS) != one


def test_a_binary_loads_as_quietly_as_it_built(cache):
    """PoCL keeps a build's log with its binary and gives it again on loading it: pyopencl's
    CompilerWarning is held back then too (the module's promise: builds are quiet)."""
    import warnings

    dc = get_context()
    loud = '#warning "chronocl test: kept with the binary"\n' + SOURCE
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        program._compile(dc, "loud.cl", loud, OPTIONS)
        assert program.binary_path(dc, loud, OPTIONS).is_file()
        program._compile(dc, "loud.cl", loud, OPTIONS)
    assert [str(w.message) for w in caught] == []


@pytest.mark.parametrize("damage", ["flipped byte", "truncated", "refused by the driver"])
def test_a_damaged_binary_is_built_again_and_replaced(cache, damage):
    import hashlib

    dc = get_context()
    want = run(program._compile(dc, "f.cl", SOURCE, OPTIONS))
    path = program.binary_path(dc, SOURCE, OPTIONS)
    good = path.read_bytes()
    if damage == "flipped byte":
        bad = bytearray(good)
        bad[-100] ^= 0xFF
        bad = bytes(bad)
    elif damage == "truncated":
        bad = good[: len(good) // 2]
    else:  # its checksum holds: only the driver can tell
        junk = b"not a program" * 50
        bad = program._MAGIC + hashlib.sha256(junk).hexdigest().encode() + b"\n\n" + junk
    path.write_bytes(bad)
    np.testing.assert_array_equal(run(program._compile(dc, "f.cl", SOURCE, OPTIONS)), want)
    assert path.read_bytes() != bad
    assert program._load(dc, path, OPTIONS) is not None  # a whole binary again


def test_an_unwritable_or_disabled_cache_still_builds(monkeypatch, tmp_path):
    dc = get_context()
    blocked = tmp_path / "a file"
    blocked.write_text("")
    monkeypatch.setenv(program.CACHE_VAR, str(blocked / "programs"))  # under a file: no folder
    want = run(program._compile(dc, "f.cl", SOURCE, OPTIONS))
    assert blocked.read_text() == "" and list(tmp_path.iterdir()) == [blocked]
    monkeypatch.setenv(program.CACHE_VAR, "off")
    assert program.binary_path(dc, SOURCE, OPTIONS) is None
    np.testing.assert_array_equal(run(program._compile(dc, "f.cl", SOURCE, OPTIONS)), want)


def test_the_default_folder_is_the_users_cache(monkeypatch, tmp_path):
    monkeypatch.delenv(program.CACHE_VAR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert program.cache_dir() == tmp_path / "chronocl" / "programs"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative")  # ignored, as the XDG spec says
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert program.cache_dir() == tmp_path / "home" / ".cache" / "chronocl" / "programs"
