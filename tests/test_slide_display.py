"""A viewer's slides in the display format (issue 47): a display session's window that slides
through partials gets its value from the last combine as RGBA8, the bytes the viewer's host
conversion makes of the float32 value a library session slides to (render/upload.py
`convert`, kernels/opencl/rgba8.h: one rule), with the same winners; its partials stay
float32. On the host (PoCL reading host memory) and with the state on the device."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.tf import TimeTF
from chronocl.engine.opencl import OpenCLEngine
from chronocl.render.upload import convert

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

# 40 x 40 x 24 voxels: over the 32^3 under which display frames stay float32 (DISPLAY_VOXELS)
SHAPE = (24, 40, 40)


@pytest.fixture(scope="module")
def series():
    data = np.random.default_rng(47).random((14, *SHAPE), dtype=np.float32)
    data[3] = data[4]  # ties: the step integrated first wins, as in one pass
    return chronocl.TimeSeries.from_array(data)


@pytest.mark.parametrize("mode", ["alpha", "max", "min", "first_hit", "change"])
@pytest.mark.parametrize("copies", [False, True])
def test_a_display_slide_is_the_host_conversion_of_the_float_slide(series, mode, copies):
    absolute = TimeTF.preset("rgb", positions="absolute")
    engine = OpenCLEngine(host_ptr=False) if copies else "opencl"
    options = {"mode": mode, "time_tf": absolute, "engine": engine}
    if mode == "first_hit":
        options["threshold"] = 0.6
    with (
        chronocl.Session(series, display=True, **options) as shown,
        chronocl.Session(series, **options) as plain,
    ):
        shown.set_window(2, 9)
        plain.set_window(2, 9)
        rgba8 = 0
        for k in (1, 1, -1, 2, 1, -3, 1, 1):
            got, ref = shown.slide(k), plain.slide(k)
            assert shown.stats["path"] == plain.stats["path"] == "incremental"
            assert ref.rgba.dtype == np.float32
            # a window all on one side of its stacks (the other just emptied) has no last
            # combine: its value is a partial kept, float32, which the viewer converts
            rgba8 += got.rgba.dtype == np.uint8
            want = convert(ref.rgba, "f1")[0] if got.rgba.dtype == np.uint8 else ref.rgba
            np.testing.assert_array_equal(got.rgba, want)
            if ref.t_index is not None:
                np.testing.assert_array_equal(got.t_index, ref.t_index)
        assert rgba8 >= 6
        slider = shown.at(0)._slider
        held = [p for s in (slider.agg._front, slider.agg._back) for p in s.aggs.values()]
        assert held and all(p.rgba.dtype == np.float32 for p in held)  # partials stay float32


def test_a_small_or_inverting_window_slides_in_float32(series):
    """Below 32^3 voxels display frames are float32 as integrated; a mode sliding by its sums
    finishes them on the host side of its own kernel (float32)."""
    absolute = TimeTF.preset("rgb", positions="absolute")
    small = chronocl.TimeSeries.from_array(np.random.default_rng(1).random((8, 4, 8, 8), "f4"))
    with chronocl.Session(small, display=True, mode="alpha", time_tf=absolute) as s:
        s.set_window(0, 4)
        assert s.slide(1).rgba.dtype == np.float32
    with chronocl.Session(series, display=True, mode="additive", time_tf=absolute) as s:
        s.set_window(0, 4)
        assert s.slide(1).rgba.dtype == np.float32


def test_the_numpy_engine_refuses_to_combine_into_the_display_format():
    """Only an engine that writes the display format combines into it (`Engine.combine`'s
    rgba8); the numpy engine says so rather than give float32 where RGBA8 was asked."""
    from chronocl.core.errors import InvalidParameterError
    from chronocl.engine.numpy import NumpyEngine
    from chronocl.modes.base import Partial
    from chronocl.modes.spec import IntegrationSpec

    part = Partial(np.zeros((2, 2, 2, 4), np.float32), None)
    with pytest.raises(InvalidParameterError, match="float32 only"):
        NumpyEngine().combine(part, part, IntegrationSpec(mode="alpha"), rgba8=True)
