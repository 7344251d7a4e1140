"""TimeSeries' public seams: where a series' coarse levels come from (`level_source`, a
`LevelSource` of `chronocl.data.level_sources`) and how another variable of its source opens
(`open_variable`) are constructor parameters, which a format sets without reaching into the
series; probing is `chronocl.probe(series, ...)`; the viewer's default data TF is core's."""

from __future__ import annotations

import dataclasses

import dask.array as da
import numpy as np
import pytest

import chronocl
from chronocl.core.errors import InvalidParameterError
from chronocl.core.tf import DEFAULT_DATA_POINTS, DataTF
from chronocl.data.level_sources import POOLED, STORED, AdoptedLevels, LevelParts
from chronocl.data.probe import probe
from chronocl.data.pyramid import downsample, level_shapes
from chronocl.data.series import TimeSeries


@pytest.fixture(scope="module")
def full() -> np.ndarray:
    return np.random.default_rng(5).random((3, 80, 6, 10), dtype=np.float32)  # levels: 1


def test_a_level_source_given_to_the_constructor_gives_the_levels(full):
    """Level 1 "mean" is the given array as it is (not a pooling of the data); "max" and the
    levels the source lacks are pooled on the fly; the level keeps level 0's extent and range."""
    own = np.full((3, 40, 3, 5), 0.25, np.float32)
    plain = TimeSeries.from_array(full, spacing=(0.5, 1.0, 2.0))
    series = dataclasses.replace(plain, level_source=AdoptedLevels({1: da.from_array(own)}))
    assert series.n_levels == 1 + len(level_shapes(series.volume_shape)) == 2
    mean = series.level(1)
    np.testing.assert_array_equal(mean.read(range(3)), own)
    assert mean.spacing == (1.0, 2.0, 4.0) and (mean.vmin, mean.vmax) == (plain.vmin, plain.vmax)
    assert mean.stats.step_max == pytest.approx([0.25] * 3)
    np.testing.assert_array_equal(series.level(1, "max").read([2])[0], downsample(full[2], "max"))
    assert series.level(1) is mean and mean.level(0) is series  # kept, and back to level 0
    with pytest.raises(InvalidParameterError, match="level 2 is out of range: array has levels"):
        series.level(2)


class EveryOtherStep:
    """A LevelSource written outside the package: level 1 holds level 0's pooled steps."""

    def count(self, series) -> int:
        return 2

    def parts(self, series, n: int, pool: str) -> LevelParts:
        level = POOLED.parts(series, n, pool)
        return LevelParts(level.data * 2, level.stats, level.spacing)


def test_any_object_with_count_and_parts_is_a_level_source(full):
    series = dataclasses.replace(TimeSeries.from_array(full), level_source=EveryOtherStep())
    assert series.n_levels == 2
    np.testing.assert_allclose(series.level(1, "min").read([0])[0], 2 * downsample(full[0], "min"))


def test_without_a_source_a_store_reads_its_own_levels_and_memory_pools(tmp_path, full):
    memory = TimeSeries.from_array(full)
    stored = memory.save(tmp_path / "s.zarr")  # written with its levels
    assert stored.level_source is None and memory.level_source is None
    assert stored.n_levels == memory.n_levels == STORED.count(stored) == POOLED.count(memory)
    np.testing.assert_array_equal(stored.level(1).read([1]), memory.level(1).read([1]))


def test_open_variable_opens_the_other_variables_of_a_source(full):
    """A format whose variables are not a chronocl store's (OME-Zarr channels) gives the opener."""
    other = TimeSeries.from_array(full[::-1].copy(), source="b")
    opened = []

    def open_variable(name: str) -> TimeSeries:
        opened.append(name)
        return other

    series = dataclasses.replace(
        TimeSeries.from_array(full, source="a"),
        meta={"variable": "a", "variables": ["a", "b"]},
        open_variable=open_variable,
    )
    assert series.variables == ("a", "b")
    assert series.variable("a") is series and series.variable("b") is other
    assert opened == ["b"]


def test_an_omezarr_image_sets_its_seams_through_the_constructor(tmp_path, full):
    zarr = pytest.importorskip("zarr")
    path = tmp_path / "img.ome.zarr"
    group = zarr.open_group(str(path), mode="w", zarr_format=2)
    stacked = np.stack([full, full + 1], axis=1)  # t, c, z, y, x: two channels
    group.create_array("0", data=stacked, chunks=(1, 1, 80, 6, 10))
    group.create_array("1", data=stacked[:, :, ::2, ::2, ::2].copy(), chunks=(1, 1, 40, 3, 5))
    axes = [{"name": "t", "type": "time"}, {"name": "c", "type": "channel"}]
    axes += [{"name": a, "type": "space"} for a in "zyx"]
    scale = [{"type": "scale", "scale": [1, 1, 1, 1, 1]}]
    group.attrs["multiscales"] = [
        {
            "version": "0.4",
            "axes": axes,
            "datasets": [
                {"path": "0", "coordinateTransformations": scale},
                {
                    "path": "1",
                    "coordinateTransformations": [{"type": "scale", "scale": [1, 1, 2, 2, 2]}],
                },
            ],
        }
    ]
    series = chronocl.open(path)
    assert isinstance(series.level_source, AdoptedLevels) and set(series.level_source.arrays) == {1}
    np.testing.assert_array_equal(series.level(1).read([0])[0], full[0, ::2, ::2, ::2])
    assert series.variables == ("c0", "c1")
    np.testing.assert_array_equal(series.variable("c1").read([0])[0], full[0] + 1)
    assert series.variable("c1").level_source is not None


def test_probing_is_a_function_of_the_series(full):
    series = TimeSeries.from_array(full)
    assert not hasattr(series, "probe")
    curve = chronocl.probe(series, 1, 2, 3)
    assert chronocl.probe is probe
    np.testing.assert_array_equal(curve.values, full[:, 3, 2, 1].astype(np.float64))


def test_the_viewer_opens_with_cores_default_data_tf():
    from chronocl.viewer.view_state import ViewState

    assert ViewState().data_tf.points == DataTF().points == DEFAULT_DATA_POINTS
