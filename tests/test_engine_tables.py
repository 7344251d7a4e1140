"""The engine's host tables (chronocl/engine/tables.py), without a device.

The data LUT and per-step factors against the transfer functions' own evaluation, the data
TF's straight pieces and what they are trusted for, the skip cut against the arithmetic the
kernels do, and the cache of recent tables. The kernels that read these tables are checked
against the reference in tests/test_kernel_fast_paths.py and tests/test_opencl.py.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from chronocl.core import values
from chronocl.core.enhance import Enhance
from chronocl.core.tf import DataTF, TimeColor, TimeTF, lut_lookup
from chronocl.core.tf_input import interp_points
from chronocl.engine import tables
from chronocl.modes.spec import IntegrationSpec

WHITE_RAMP = DataTF(points=[(0, 1, 1, 1, 0), (1, 1, 1, 1, 1)])  # constant colour, one piece
COLOURED = DataTF(points=[(0, 0, 0, 1, 0.02), (0.5, 0, 1, 0, 0.1), (1, 1, 0, 0, 0.5)])
DARK_START = DataTF(points=[(0, 1, 0, 0, 0), (0.25, 1, 0, 0, 0), (1, 1, 0, 0, 1)])
ZIGZAG = DataTF(points=[(i / 11, i % 2, 0, 1 - i % 2, 1) for i in range(12)])  # 11 pieces
POSITIONS = np.linspace(0.0, 1.0, 5)


def spec_of(data_tf: DataTF, mode: str = "alpha", **kw) -> IntegrationSpec:
    return IntegrationSpec(mode=mode, data_tf=data_tf, **kw)


def test_the_module_needs_no_device():
    """Importing the tables loads no OpenCL: they are built and tested on any machine."""
    code = "import sys, chronocl.engine.tables; print('pyopencl' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("tf", [WHITE_RAMP, COLOURED, DataTF(points=COLOURED.points, size=1024)])
def test_the_lut_is_the_data_tf_planar(tf):
    t = tables.host_tables(spec_of(tf), POSITIONS, False, (0.0, 1.0))
    assert t.lut.shape == (4, tf.size) and t.lut.dtype == np.float32
    assert t.lut.flags.c_contiguous
    np.testing.assert_array_equal(t.lut, tf.lut.T)
    u = np.linspace(0.0, 1.0, tf.size)
    np.testing.assert_allclose(t.lut.T, interp_points(tf.points, u), atol=1e-6)


def test_a_quantised_lut_holds_the_tf_of_every_byte_value():
    """uint8 data index their LUT directly: entry v is the TF at u(v), for the value range."""
    value_range = (10.0, 200.0)
    t = tables.host_tables(spec_of(COLOURED), POSITIONS, True, value_range)
    assert t.lut.shape == (4, 256)
    u = values.normalize(np.arange(256), *value_range)
    np.testing.assert_allclose(t.lut.T, lut_lookup(COLOURED.lut, u), atol=1e-6)
    np.testing.assert_array_equal(t.lut[:, :11], np.repeat(t.lut[:, :1], 11, axis=1))  # u = 0
    np.testing.assert_allclose(t.lut[:, 200:], np.repeat(t.lut[:, 255:], 56, axis=1))  # u = 1


def test_per_step_factors_are_the_time_tf():
    """tc is (rgb_t, a_t) per step; a constant data colour is folded into it."""
    time_tf = TimeTF(color=TimeColor("rgb"))
    rgb_t, a_t = time_tf.evaluate(POSITIONS)
    coloured = tables.host_tables(spec_of(COLOURED, time_tf=time_tf), POSITIONS, False, (0, 1))
    assert not coloured.const_color and coloured.tc.shape == (5, 4)
    assert coloured.tc.dtype == np.float32
    np.testing.assert_array_equal(coloured.tc, np.c_[rgb_t, a_t].astype(np.float32))
    red = DataTF(points=[(0, 0.5, 0, 0, 0), (1, 0.5, 0, 0, 1)])
    folded = tables.host_tables(spec_of(red, time_tf=time_tf), POSITIONS, False, (0, 1))
    assert folded.const_color
    want = np.c_[rgb_t * [0.5, 0.0, 0.0], a_t].astype(np.float32)
    np.testing.assert_array_equal(folded.tc, want)


def test_a_straight_tf_is_one_piece_for_opacity():
    """A ramp: one piece from 0 with its slope; alpha evaluates opacity from it (SEG_ALPHA 1),
    a threshold mode lets it decide only far from the threshold (2), no pieces when off (0)."""
    t = tables.host_tables(spec_of(WHITE_RAMP), POSITIONS, False, (0.0, 1.0))
    assert t.seg_alpha == 1 and t.segments.shape == (9, 1)
    assert t.segments[0, 0] == 0 and t.segments[4, 0] == 0  # x0, opacity at 0
    assert t.segments[8, 0] == pytest.approx(1 / 255)  # opacity slope per LUT position
    hit = tables.host_tables(
        spec_of(WHITE_RAMP, "first_hit", threshold=0.5), POSITIONS, False, (0, 1)
    )
    assert hit.seg_alpha == 2
    off = tables.host_tables(spec_of(WHITE_RAMP), POSITIONS, False, (0.0, 1.0), pieces=False)
    assert off.segments is None and off.seg_alpha == 0


def test_threshold_modes_keep_exact_opacity_where_pieces_cannot_bound_it():
    """Gradient enhancement (or a time opacity above 1) may raise opacity past what the pieces
    bound: a threshold mode then keeps the lookups (colour may still come from pieces)."""
    edge = spec_of(COLOURED, "first_hit", threshold=0.3, enhance=Enhance("edge"))
    t = tables.host_tables(edge, POSITIONS, False, (0.0, 1.0))
    assert t.seg_alpha == 0 and t.segments is not None  # colour pieces only
    assert np.all(t.segments[4] == 0) and np.all(t.segments[8] == 0)
    plain = tables.host_tables(
        spec_of(COLOURED, "first_hit", threshold=0.3), POSITIONS, False, (0, 1)
    )
    assert plain.seg_alpha == 2


def test_pieces_break_where_the_tf_bends_and_give_up_past_the_limit():
    table = tables.tf_segments(COLOURED.lut, [0, 1, 2, 3])
    assert table.shape == (9, 3)  # u = 0.5 falls between entries 127 and 128: a short middle piece
    np.testing.assert_array_equal(table[0], [0, 127, 128])
    lut = COLOURED.lut.astype(np.float64)
    np.testing.assert_allclose(table[1:5].T, lut[[0, 127, 128]], atol=1e-7)
    assert tables.tf_segments(ZIGZAG.lut, [0, 1, 2]) is None  # more than MAX_SEGMENTS
    t = tables.host_tables(spec_of(ZIGZAG), POSITIONS, False, (0.0, 1.0))
    assert t.segments is None and t.seg_alpha == 0


def test_the_timed_table_scales_pieces_by_each_step():
    """The lut buffer is the LUT, then x0 and per step and channel (value at 0, slopes) * tc."""
    t = tables.host_tables(spec_of(COLOURED), POSITIONS, False, (0.0, 1.0))
    s, w = t.segments.shape[1], len(POSITIONS)
    flat = t.lut_buffer()
    assert flat.dtype == np.float32 and flat.shape == (4 * 256 + s + w * 4 * (s + 1),)
    np.testing.assert_array_equal(flat[: 4 * 256], t.lut.ravel())
    rows = flat[4 * 256 + s :].reshape(w, 4, s + 1)
    np.testing.assert_array_equal(flat[4 * 256 : 4 * 256 + s], t.segments[0])
    want = t.tc[:, :, None].astype(np.float64) * np.c_[t.segments[1:5, :1], t.segments[5:9]]
    np.testing.assert_array_equal(rows, want.astype(np.float32))
    no_pieces = tables.host_tables(spec_of(ZIGZAG), POSITIONS, False, (0.0, 1.0))
    assert no_pieces.lut_buffer() is no_pieces.lut


def test_the_quantised_skip_cut_is_the_first_byte_with_opacity():
    t = tables.host_tables(spec_of(DARK_START), POSITIONS, True, (0.0, 255.0))
    live = np.flatnonzero(t.lut[3] > 0)
    assert t.cut == live[0] and t.lut[3, int(t.cut) - 1] == 0
    clear = DataTF(points=[(0, 1, 1, 1, 0), (1, 1, 1, 1, 0)])
    assert tables.host_tables(spec_of(clear), POSITIONS, True, (0.0, 255.0)).cut == 255.0


@pytest.mark.parametrize("value_range", [(0.0, 1.0), (-3.0, 7.5), (100.0, 65535.0)])
def test_the_raw_skip_cut_is_exact_in_the_kernels_arithmetic(value_range):
    """Raw values below the cut reach only LUT intervals of zero opacity, the cut itself does
    not: u(v) * (N - 1) in float32 as the kernels compute it crosses the first live interval's
    left entry exactly there."""
    t = tables.host_tables(spec_of(DARK_START), POSITIONS, False, value_range)
    lut_a = DARK_START.lut[:, 3].astype(np.float64)
    first = int(np.flatnonzero(np.maximum(lut_a[:-1], lut_a[1:]) > 0)[0])
    cut = np.float32(t.cut)
    below = np.nextafter(cut, np.float32(-np.inf))
    u = values.normalize(np.array([below, cut], dtype=np.float32), *value_range)
    x = u * np.float32(len(lut_a) - 1)
    assert x[0] < first <= x[1]


def test_a_constant_field_cuts_everything_or_nothing():
    assert tables.raw_cut(0.0, (3.0, 3.0), 256) == -np.inf  # u = 0 reaches position 0
    assert tables.raw_cut(5.0, (3.0, 3.0), 256) == np.inf


def test_threshold_modes_skip_what_cannot_pass():
    """first_hit with threshold 0.3 and time opacity at most 1: entries of opacity up to about
    0.3 are skipped, so the cut lies at the first byte whose opacity may pass."""
    spec = spec_of(WHITE_RAMP, "first_hit", threshold=0.3)
    t = tables.host_tables(spec, POSITIONS, True, (0.0, 255.0))
    a_t = spec.time_tf.evaluate(POSITIONS)[1]
    bar = tables.skip_bar(spec, a_t)
    assert bar == spec.threshold / (a_t.max() * tables.PASS_SLACK) and bar < 0.3 / a_t.max()
    assert t.lut[3, int(t.cut)] > bar >= t.lut[3, int(t.cut) - 1]
    alpha = tables.host_tables(spec_of(WHITE_RAMP), POSITIONS, True, (0.0, 255.0))
    assert alpha.cut == 1.0  # over adds every entry above 0


def test_opacity_error_bounds_the_pieces_for_threshold_modes():
    table = tables.tf_segments(COLOURED.lut, [0, 1, 2, 3])
    err = tables.opacity_error(table, 256)
    assert 2 * tables.SEGMENT_TOLERANCE < err < tables.OPACITY_ERROR_MAX


def test_the_cache_keeps_recent_tables_read_only():
    cache = tables.TableCache(size=3)
    spec = spec_of(DARK_START)
    first = cache.get(spec, POSITIONS, False, (0.0, 1.0))
    assert cache.get(spec, POSITIONS.copy(), False, (0.0, 1.0)) is first
    assert not any(a.flags.writeable for a in first if isinstance(a, np.ndarray))
    assert cache.get(spec, POSITIONS, False, (0.0, 1.0), pieces=False) is not first
    for n in range(5):  # the one in use stays, the others come and go
        assert cache.get(spec, POSITIONS, False, (0.0, 1.0)) is first
        cache.get(spec, np.linspace(0.0, 1.0, n + 2), False, (0.0, 1.0))
    assert len(cache) == 3
    again = cache.get(spec, POSITIONS, False, (0.5, 1.0))
    assert again is not first and again.cut != first.cut
