"""Transfer functions: presets, LUT, JSON round trip and validation."""

from __future__ import annotations

import numpy as np
import pytest

from chronocl.core.errors import (
    ChronoclError,
    InputNotFoundError,
    InvalidTransferFunctionError,
    UnknownNameError,
)
from chronocl.core.tf import DataTF, TFSetting, TimeAlpha, TimeColor, TimeTF, lut_lookup


def test_rgb_ramp_is_blue_green_red():
    rgb = TimeColor("rgb").evaluate(np.array([0.0, 0.25, 0.5, 1.0]))
    np.testing.assert_allclose(rgb, [[0, 0, 1], [0, 0.5, 0.5], [0, 1, 0], [1, 0, 0]])


def test_luminance_is_white_at_focus_fading_to_black():
    lum = TimeColor("luminance", focus=0.5, falloff=0.5).evaluate(np.array([0.0, 0.25, 0.5, 1.0]))
    np.testing.assert_allclose(lum[:, 0], [0, 0.5, 1, 0])
    np.testing.assert_allclose(lum[:, 0], lum[:, 2])


def test_warm_cool_goes_from_cool_to_warm():
    rgb = TimeColor("warm-cool").evaluate(np.array([0.0, 1.0]))
    assert rgb[0, 2] > rgb[0, 0] and rgb[1, 0] > rgb[1, 2]


def test_hat_and_inverted_hat():
    p = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    hat = TimeAlpha("hat", center=0.5, width=1.0, floor=0.0).evaluate(p)
    np.testing.assert_allclose(hat, [0, 0.5, 1, 0.5, 0])
    inv = TimeAlpha("inverted-hat", center=0.5, width=1.0, floor=0.2).evaluate(p)
    np.testing.assert_allclose(inv, [1, 0.6, 0.2, 0.6, 1])
    np.testing.assert_allclose(TimeAlpha("constant", value=0.3).evaluate(p), 0.3)


def test_positions_relative_and_absolute():
    tf_rel, tf_abs = TimeTF(), TimeTF(positions="absolute")
    np.testing.assert_allclose(tf_rel.positions_of([3, 5, 9], 11), [0, 0.5, 1])
    np.testing.assert_allclose(tf_abs.positions_of([3, 5, 9], 11), [0.3, 0.5, 0.9])
    np.testing.assert_allclose(tf_rel.positions_of([4], 11), [0])
    np.testing.assert_allclose(tf_abs.positions_of([0], 1), [0])


def test_lut_interpolates_linearly_between_entries():
    tf = DataTF(points=[(0, 0, 0, 0, 0), (1, 1, 1, 1, 1)], size=256)
    lut = tf.lut
    assert lut.shape == (256, 4) and lut.dtype == np.float32
    u = np.array([0.0, 0.3, 0.77, 1.0])
    np.testing.assert_allclose(lut_lookup(lut, u)[:, 3], u, atol=1e-6)
    step = DataTF(points=[(0, 0, 0, 0, 0), (0.5, 0, 0, 0, 0), (0.6, 1, 0, 0, 1), (1, 1, 0, 0, 1)])
    assert lut_lookup(step.lut, np.array([0.4]))[0, 3] == 0
    assert lut_lookup(step.lut, np.array([0.7]))[0, 3] == pytest.approx(1)


def test_json_round_trip(tmp_path):
    setting = TFSetting(
        data_tf=DataTF(points=[(0, 1, 0, 0, 0), (0.4, 0, 1, 0, 0.3), (1, 0, 0, 1, 1)], size=512),
        time_tf=TimeTF(
            color=TimeColor("luminance", focus=0.3, falloff=0.5),
            alpha=TimeAlpha("hat", center=0.7, width=0.4, floor=0.1),
            positions="absolute",
        ),
    )
    path = tmp_path / "tf.json"
    setting.save(path)
    assert TFSetting.load(path) == setting
    custom = TFSetting(
        time_tf=TimeTF(color=TimeColor("points", points=[(0, 1, 0, 0), (1, 0, 1, 0)]))
    )
    custom.save(path)
    assert TFSetting.load(path) == custom


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        ("{not json", "not valid JSON"),
        ('{"data_tf": {"points": [[0, 1, 1, 1, NaN], [1, 1, 1, 1, 1]]}}', "NaN"),
        ('{"data_tf": {"points": [[0.5, 1, 1, 1, 0], [0.2, 1, 1, 1, 1]]}}', "sorted"),
        ('{"data_tf": {"points": [[0, 1, 1, 1, 0], [1, 1, 1, 1.5, 1]]}}', "outside [0, 1]"),
        ('{"data_tf": {"points": [[0, 1, 1, 0], [1, 1, 1, 1, 1]]}}', "expected 5"),
        ('{"data_tf": {"points": []}}', "non-empty"),
        ('{"data_tf": {"size": 16}}', "256 to 65536"),
        ('{"time_tf": {"alpha": {"shape": "hat", "width": 0}}}', "width"),
        ('{"time_tf": {"color": {"preset": "rainbow"}}}', "rainbow"),
        ('{"time_tf": {"colour": {}}}', "unknown key 'colour'"),
        ("[1, 2]", "JSON object"),
        ('{"data_tf": {"value_range": "01"}}', "value_range must be a list of two numbers"),
        ('{"data_tf": {"value_range": 5}}', "value_range must be a list of two numbers"),
        ('{"data_tf": {"value_range": [0, 1, 2]}}', "value_range must be a list of two numbers"),
        ('{"data_tf": {"value_range": ["0", 1]}}', "must be a number, got the string"),
        ('{"data_tf": {"value_range": [0, 1e300]}}', "outside float32"),
        ('{"data_tf": {"value_range": [1, 1]}}', "min < max"),
        ('{"time_tf": {"alpha": {"shape": "hat", "width": "0.5"}}}', "width must be a number"),
        ('{"time_tf": {"color": {"preset": "luminance", "falloff": null}}}', "got null"),
        ('{"time_tf": {"color": {"preset": "luminance", "falloff": 0}}}', "falloff is 0"),
        ('{"time_tf": {"alpha": {"value": true}}}', "got true"),
        ('{"data_tf": {"points": [[0, 1, 1, 1, "0"], [1, 1, 1, 1, 1]]}}', "got the string '0'"),
        ('{"data_tf": {"points": [5, [1, 1, 1, 1, 1]]}}', "must be a list of 5 numbers"),
        ('{"data_tf": {"size": 256.0}}', "size must be an integer"),
        ('{"data_tf": null}', "data_tf must be a JSON object"),
        ("[" * 100_000 + "]" * 100_000, "too deeply"),
        ('{"data_tf": {"points": ' + "[" * 990 + "]" * 990 + "}}", "bad.json"),  # either message
    ],
)
def test_bad_tf_json_gives_one_clear_line(tmp_path, content, needle):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(ChronoclError) as info:
        TFSetting.load(path)
    assert needle in str(info.value)
    assert "\n" not in str(info.value)
    assert isinstance(info.value, ValueError)


def test_missing_tf_file(tmp_path):
    with pytest.raises(InputNotFoundError):
        TFSetting.load(tmp_path / "nope.json")


def test_unknown_presets():
    with pytest.raises(UnknownNameError, match="rainbow"):
        TimeTF.preset("rainbow")
    with pytest.raises(UnknownNameError):
        TimeTF(positions="sideways")
    with pytest.raises(InvalidTransferFunctionError, match="min < max"):
        DataTF(value_range=(2.0, 1.0))


def test_tf_path_that_is_not_a_file_says_what_it_is(tmp_path):
    from chronocl.core.errors import InvalidParameterError

    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(InputNotFoundError, match="symlink loop"):
        TFSetting.load(tmp_path / "a")
    (tmp_path / "gone").symlink_to(tmp_path / "nothing.json")
    with pytest.raises(InputNotFoundError, match="broken symlink"):
        TFSetting.load(tmp_path / "gone")
    with pytest.raises(InvalidParameterError, match="is a folder, not a file"):
        TFSetting.load(tmp_path)
    with pytest.raises(InvalidParameterError, match="not a regular file"):
        TFSetting.load("/dev/null")


def test_value_range_accepts_numpy_numbers_and_rejects_strings():
    assert DataTF(value_range=(np.float32(-1), np.int64(3))).value_range == (-1.0, 3.0)
    with pytest.raises(InvalidTransferFunctionError, match="got the string"):
        TimeAlpha("hat", width="0.5")  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["viridis", "grey", "coolwarm"])
def test_a_colour_map_recolours_and_keeps_the_opacity_curve(name):
    from matplotlib import colormaps

    from chronocl.core.colormaps import STOPS, colormap_stops
    from chronocl.core.tf_input import interp_points

    before = DataTF()
    after = before.with_colormap(name)
    u = np.linspace(0.0, 1.0, 2001)
    # The same curve: a point inserted on a segment moves the interpolation by rounding only.
    np.testing.assert_allclose(
        interp_points(after.points, u)[:, 3], interp_points(before.points, u)[:, 3], atol=1e-12
    )
    stops = np.linspace(0.0, 1.0, STOPS)
    want = colormaps[{"grey": "gray"}.get(name, name)](stops)[:, :3]
    np.testing.assert_allclose(interp_points(after.points, stops)[:, :3], want, atol=1e-6)
    assert [s[0] for s in colormap_stops(name)] == pytest.approx(list(stops))


def test_unknown_colour_map_is_one_line():
    with pytest.raises(InvalidTransferFunctionError, match="unknown colour map 'nope'; use one of"):
        DataTF().with_colormap("nope")


def test_the_presets_table_is_matplotlibs():
    """The presets' stops shipped as a table (`colormap_presets.json`) are matplotlib's own."""
    from chronocl.core.colormaps import PRESETS, _presets, colormap_stops, matplotlib_stops

    assert list(_presets()) == list(PRESETS)
    for name in PRESETS:
        assert colormap_stops(name) == [list(stop) for stop in matplotlib_stops(name)], name


def test_the_viewers_info_needs_no_matplotlib():
    """A viewer's or widget's first message (its menus, the presets' stops) imports no
    matplotlib: its import would delay the first picture."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import numpy as np\n"
        "import chronocl\n"
        "from chronocl.viewer.datasets import Dataset\n"
        "from chronocl.viewer.sockets import info_message\n"
        "series = chronocl.TimeSeries.from_array(np.zeros((3, 4, 4, 4), np.float32))\n"
        "info = info_message([Dataset('v', series)])\n"
        "assert len(info['colormaps']['viridis']) == 33\n"
        "print('matplotlib' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stderr
