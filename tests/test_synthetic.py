"""Tests of the synthetic time-varying data sets (chronocl.data.synthetic)."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys

import numpy as np
import pytest

from chronocl.core.errors import ChronoclError, InvalidParameterError, UnknownNameError
from chronocl.data.synthetic import DATASETS, step, steps

NAMES = sorted(DATASETS)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 0.0


def test_datasets_lists_both_with_one_line_descriptions() -> None:
    assert set(DATASETS) == {"vortex", "jet"}
    for description in DATASETS.values():
        assert description and "\n" not in description


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("shape", [(5, 7, 9), (3, 4, 5), (1, 1, 1), (16, 8, 32)])
def test_dtype_shape_and_range_for_odd_shapes(name: str, shape: tuple[int, int, int]) -> None:
    for t in (0, 3, 6):
        v = step(name, t, 7, shape)
        assert v.dtype == np.float32
        assert v.shape == shape
        assert np.isfinite(v).all()
        assert v.min() >= 0.0
        assert v.max() <= 1.0


@pytest.mark.parametrize("name", NAMES)
def test_background_near_zero_and_features_near_one(name: str) -> None:
    for t in (0, 9):
        v = step(name, t, 10, (32, 32, 32))
        assert float(np.median(v)) < 0.01
        assert v.max() > 0.85
        # The features are a minority of the box, not a haze over all of it.
        assert 0.0 < float((v > 0.5).mean()) < 0.25


@pytest.mark.parametrize("name", NAMES)
def test_same_inputs_give_bit_identical_outputs(name: str) -> None:
    a = step(name, 4, 10, (20, 24, 28), seed=5)
    b = step(name, 4, 10, (20, 24, 28), seed=5)
    assert a.tobytes() == b.tobytes()


def _digest_script() -> str:
    return (
        "import hashlib, numpy as np\n"
        "from chronocl.data.synthetic import steps\n"
        "h = hashlib.sha256()\n"
        "for name in ('vortex', 'jet'):\n"
        "    for a in steps(name, 4, (19, 23, 41), seed=5):\n"
        "        h.update(a.tobytes())\n"
        "print(h.hexdigest())\n"
    )


def test_outputs_do_not_depend_on_numpys_simd_code_paths() -> None:
    """The same bits with every dispatched SIMD path of numpy turned off (an AVX2 or SSE
    machine) as with them on: golden digests recorded on one CPU hold on another."""
    simd = np.show_config(mode="dicts")["SIMD Extensions"]
    dispatched = [*simd.get("found", []), *simd.get("not found", [])]  # beyond the baseline
    runs = []
    for disabled in ("", " ".join(dispatched)):
        env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": disabled}
        done = subprocess.run(
            [sys.executable, "-c", _digest_script()],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
        runs.append(done.stdout.strip())
    assert runs[0] == runs[1], dispatched


@pytest.mark.parametrize("name", NAMES)
def test_seed_changes_the_field(name: str) -> None:
    a = step(name, 6, 10, (32, 32, 32), seed=0)
    b = step(name, 6, 10, (32, 32, 32), seed=1)
    assert not np.array_equal(a, b)
    assert float(np.abs(a - b).max()) > 0.2


@pytest.mark.parametrize("name", NAMES)
def test_steps_yields_each_step_in_order(name: str) -> None:
    got = list(steps(name, 4, (8, 9, 10), seed=2))
    assert len(got) == 4
    for t, v in enumerate(got):
        np.testing.assert_array_equal(v, step(name, t, 4, (8, 9, 10), seed=2))


@pytest.mark.parametrize("name", NAMES)
def test_time_is_normalised_so_any_step_count_spans_the_same_motion(name: str) -> None:
    shape = (12, 12, 12)
    np.testing.assert_array_equal(step(name, 0, 5, shape), step(name, 0, 30, shape))
    np.testing.assert_array_equal(step(name, 2, 5, shape), step(name, 1, 3, shape))
    np.testing.assert_array_equal(step(name, 4, 5, shape), step(name, 29, 30, shape))
    # A single step is the start of the motion.
    np.testing.assert_array_equal(step(name, 0, 1, shape), step(name, 0, 9, shape))


@pytest.mark.parametrize("name", NAMES)
def test_grids_sample_one_continuous_field(name: str) -> None:
    # Voxel i of a 16-voxel axis has the same centre as voxel 3i+1 of a 48-voxel axis.
    coarse = step(name, 3, 8, (16, 16, 16))
    fine = step(name, 3, 8, (48, 48, 48))
    np.testing.assert_allclose(coarse, fine[1::3, 1::3, 1::3], atol=1e-5)


@pytest.mark.parametrize("name", NAMES)
def test_fields_are_smooth(name: str) -> None:
    rng = np.random.default_rng(0)
    for t in (0, 5, 9):
        v = step(name, t, 10, (48, 48, 48))
        noisy = rng.permuted(v.ravel()).reshape(v.shape)
        span = float(v.max() - v.min())
        for axis in range(3):
            d = np.abs(np.diff(v, axis=axis))
            # Where there is something (either neighbour above 0.05), neighbours differ little...
            lo = np.take(v, range(v.shape[axis] - 1), axis=axis)
            hi = np.take(v, range(1, v.shape[axis]), axis=axis)
            active = np.maximum(lo, hi) > 0.05
            assert float(d[active].mean()) < 0.2 * span
            # ... never jump across most of the range ...
            assert float(d.max()) < 0.7 * span
            # ... and much less than the same values in random order.
            dn = np.abs(np.diff(noisy, axis=axis))
            active_n = np.maximum(
                np.take(noisy, range(v.shape[axis] - 1), axis=axis),
                np.take(noisy, range(1, v.shape[axis]), axis=axis),
            )
            assert float(d[active].mean()) < 0.6 * float(dn[active_n > 0.05].mean())


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_vortex_features_move_between_first_and_last_step(seed: int) -> None:
    n = 40
    first = step("vortex", 0, 20, (n, n, n), seed=seed) > 0.5
    last = step("vortex", 19, 20, (n, n, n), seed=seed) > 0.5
    assert first.sum() > 50 and last.sum() > 50
    assert _iou(first, last) < 0.2
    shift = np.argwhere(last).mean(axis=0) - np.argwhere(first).mean(axis=0)
    assert float(np.linalg.norm(shift)) > 0.08 * n


def test_vortex_changes_steadily_from_step_to_step() -> None:
    vols = [step("vortex", t, 10, (32, 32, 32)) > 0.5 for t in range(10)]
    for a, b in itertools.pairwise(vols):
        # Consecutive steps differ but stay related: motion, not a jump to a new field.
        assert 0.0 < _iou(a, b) < 0.95


def test_vortex_features_grow() -> None:
    first = step("vortex", 0, 10, (40, 40, 40)) > 0.5
    last = step("vortex", 9, 10, (40, 40, 40)) > 0.5
    assert last.sum() > 1.5 * first.sum()


def _jet_extent(v: np.ndarray) -> int:
    """How many voxels along x, from the inlet face, the thresholded plume reaches."""
    xs = np.flatnonzero((v > 0.5).any(axis=(0, 1)))
    return int(xs.max()) + 1 if xs.size else 0


@pytest.mark.parametrize("seed", [0, 3])
def test_jet_front_advances_across_most_of_the_box(seed: int) -> None:
    n = 32
    extents = [_jet_extent(v) for v in steps("jet", 12, (n, n, n), seed=seed)]
    assert all(b >= a for a, b in itertools.pairwise(extents)), extents
    assert extents[0] < 0.25 * n
    assert extents[-1] > 0.85 * n
    assert extents[-1] - extents[0] > 0.65 * n


def test_jet_enters_through_the_low_x_face_and_spreads_downstream() -> None:
    n = 40
    v = step("jet", 9, 10, (n, n, n)) > 0.5
    area = v.sum(axis=(0, 1))  # cross-section of the plume at each x
    assert area[0] > 0  # attached to the inlet
    assert area[int(0.7 * n)] > 3 * area[2]
    # Nothing at the inlet face far from the axis: a jet, not a wall.
    assert not v[:, :, 0][[0, -1], :].any() and not v[:, :, 0][:, [0, -1]].any()


def test_jet_works_in_a_non_cubic_box() -> None:
    shape = (16, 8, 32)
    assert _jet_extent(step("jet", 0, 5, shape)) < _jet_extent(step("jet", 4, 5, shape))


def test_unknown_name_raises_unknown_name_error_listing_known_names() -> None:
    with pytest.raises(UnknownNameError) as info:
        step("tornado", 0, 10, (8, 8, 8))
    message = str(info.value)
    assert "tornado" in message and "vortex" in message and "jet" in message
    assert "\n" not in message
    with pytest.raises(ValueError):
        steps("tornado", 10, (8, 8, 8))
    with pytest.raises(ChronoclError):
        step("Vortex", 0, 10, (8, 8, 8))


@pytest.mark.parametrize(
    ("t", "n_steps", "shape", "seed", "needle"),
    [
        (0, 0, (8, 8, 8), 0, "n_steps"),
        (0, -3, (8, 8, 8), 0, "n_steps"),
        (-1, 10, (8, 8, 8), 0, "t=-1"),
        (10, 10, (8, 8, 8), 0, "t=10"),
        (0, 10, (0, 8, 8), 0, "shape_zyx"),
        (0, 10, (8, -1, 8), 0, "shape_zyx"),
        (0, 10, (8, 8), 0, "3 entries"),
        (0, 10, (8, 8, 8, 8), 0, "3 entries"),
        (0, 10, (8, 8, 8.5), 0, "integer"),
        (1.5, 10, (8, 8, 8), 0, "integer"),
        (True, 10, (8, 8, 8), 0, "integer"),
        (0, 10, (8, 8, 8), -1, "seed"),
    ],
)
def test_bad_arguments_raise_invalid_parameter_error(
    t: object, n_steps: int, shape: tuple[int, ...], seed: int, needle: str
) -> None:
    for name in NAMES:
        with pytest.raises(InvalidParameterError) as info:
            step(name, t, n_steps, shape, seed=seed)  # type: ignore[arg-type]
        message = str(info.value)
        assert needle in message
        assert "\n" not in message
        assert isinstance(info.value, ValueError)


def test_steps_checks_its_arguments_at_the_call() -> None:
    with pytest.raises(InvalidParameterError):
        steps("jet", 0, (8, 8, 8))
    with pytest.raises(InvalidParameterError):
        steps("vortex", 5, (8, 0, 8))


def test_numpy_integers_are_accepted() -> None:
    a = step("jet", np.int64(2), np.int32(5), (np.int64(6), 7, 8), seed=np.uint8(1))
    np.testing.assert_array_equal(a, step("jet", 2, 5, (6, 7, 8), seed=1))
