"""Empty-space skipping: the brick grid against brute force, the same picture with and without
skipping on sparse random volumes, and fewer samples per ray where the volume is sparse."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl.core.errors import InvalidParameterError, RendererUnavailableError
from chronocl.core.tuning import TUNING
from chronocl.render import Camera, Shading, brick_grid
from chronocl.render.raycaster import Raycaster
from chronocl.render.upload import convert
from chronocl.viewer.slots import ViewSlot, upload
from tests.strategies import examples

SIZE = (120, 90)
VIEWS = [
    dict(camera=Camera(30.0, 20.0, zoom=1.2)),
    dict(camera=Camera(-115.0, -40.0, zoom=1.6), step=0.45),
    dict(camera=Camera(90.0, 0.0, projection="orthographic"), jitter=False, step=1.7),
    dict(camera=Camera(200.0, 65.0), clip=(1.0, -0.5, 0.3, 0.1)),
    dict(camera=Camera(10.0, -5.0, zoom=2.5), shading=Shading()),
]


@pytest.fixture(scope="module")
def rc() -> Raycaster:
    try:
        return Raycaster()
    except RendererUnavailableError as exc:  # no EGL: nothing to draw with
        pytest.skip(str(exc))


def brute_grid(alpha: np.ndarray, brick: int) -> np.ndarray:
    """Each brick's largest opacity over its voxels grown by one, cell by cell."""
    out = np.zeros(brick_grid.grid_shape(alpha.shape, brick), dtype=alpha.dtype)
    for k, j, i in np.ndindex(out.shape):
        lo = [max(c * brick - 1, 0) for c in (k, j, i)]
        out[k, j, i] = alpha[
            lo[0] : (k + 1) * brick + 1, lo[1] : (j + 1) * brick + 1, lo[2] : (i + 1) * brick + 1
        ].max()
    return out


@settings(max_examples=examples(60))
@given(
    shape=st.tuples(st.integers(1, 37), st.integers(1, 21), st.integers(1, 29)),
    brick=st.sampled_from([1, 2, 3, 8, 16]),
    fill=st.sampled_from([0.0, 0.003, 0.05, 1.0]),
    seed=st.integers(0, 2**16),
)
def test_grid_is_the_grown_brick_maximum(shape, brick, fill, seed):
    rng = np.random.default_rng(seed)
    alpha = (rng.random(shape) < fill) * rng.random(shape, dtype=np.float32)
    expected = brute_grid(alpha, brick)
    got = brick_grid.grid(alpha, brick)
    assert got.dtype == np.uint8 and got.shape == expected.shape
    assert np.array_equal(got, np.clip(np.ceil(expected.astype(np.float64) * 255), 0, 255))
    assert np.array_equal(got > 0, expected > 0)  # any opacity above 0 stays above 0
    rgba8 = (rng.random((*shape, 4)) * 255).astype(np.uint8)
    rgba8[..., 3] = np.round(alpha * 255)
    assert np.array_equal(brick_grid.from_rgba(rgba8, brick), brute_grid(rgba8[..., 3], brick))
    assert np.array_equal(
        brick_grid.from_rgba(rgba8[:, ::-1], brick), brick_grid.grid(rgba8[:, ::-1, :, 3], brick)
    )


@settings(max_examples=examples(60))
@given(
    shape=st.tuples(st.integers(1, 37), st.integers(1, 21), st.integers(1, 29)),
    brick=st.sampled_from([1, 2, 3, 8, 16]),
    points=st.integers(0, 6),
    seed=st.integers(0, 2**16),
)
def test_occupied_bounds_from_the_grid_equal_the_volume_s(shape, brick, points, seed):
    """The viewer's and renderer's occupied box, found from the brick grid and the planes it
    points at, is the one a pass over the volume finds (`Occupancy.bounds`): a few opaque voxels
    anywhere (on brick edges, in a short last brick), colour without opacity, RGBA8 and float."""
    rng = np.random.default_rng(seed)
    rgba = np.zeros((*shape, 4), dtype=np.uint8)
    rgba[..., 0] = rng.integers(0, 256, shape)  # colour where nothing is opaque
    for _ in range(points):
        rgba[(*(int(rng.integers(0, n)) for n in shape), 3)] = rng.integers(1, 256)
    for volume in (rgba, rgba.astype(np.float32) / 255):
        want = convert(volume, "f4" if volume.dtype == np.float32 else "f1")[1].bounds()
        got = brick_grid.occupied_bounds(brick_grid.from_rgba(volume, brick), volume, brick)
        assert np.array_equal(got, want), (got, want)


def test_float_volumes_find_their_box_in_a_pass_and_a_foreign_grid_is_refused(rc):
    """The grid's maxima carry a NaN through, so a brick holding one and an opaque voxel reads
    as empty: float volumes (which may hold NaN) keep the pass over the volume, which skips
    the NaN alone, and only RGBA8 takes the grid's bounds. A grid of other bricks is refused."""
    spacing = {"x": 1.0, "y": 1.0, "z": 1.0}
    rgba = np.zeros((24, 4, 4, 4), dtype=np.float32)
    rgba[8, 1, 1, 3], rgba[12, 1, 1, 3] = 0.5, np.nan  # one brick: the NaN and the opaque voxel
    clean = np.nan_to_num(rgba)
    got = rc.upload(chronocl.Chronovolume(rgba, None, {"spacing": spacing}), dtype="f4")
    want = rc.upload(chronocl.Chronovolume(clean, None, {"spacing": spacing}), dtype="f4")
    np.testing.assert_array_equal(got.occupied[0], want.occupied[0])
    np.testing.assert_array_equal(got.occupied[1], want.occupied[1])
    with pytest.raises(InvalidParameterError, match="brick grid of shape"):
        brick_grid.occupied_bounds(brick_grid.from_rgba(clean, 4), clean)


def test_grid_on_the_pool_equals_serial():
    rng = np.random.default_rng(3)
    # above TUNING.brick_grid_serial_voxels: slab tasks
    alpha = np.zeros((140, 131, 129), dtype=np.uint8)
    for _ in range(30):
        z, y, x = rng.integers(0, 128, 3)
        alpha[z : z + 3, y : y + 2, x] = rng.integers(1, 256)
    assert alpha.size > TUNING.brick_grid_serial_voxels
    assert np.array_equal(brick_grid.grid(alpha), brute_grid(alpha, brick_grid.BRICK))


def test_grid_bad_input():
    with pytest.raises(InvalidParameterError, match="expected"):
        brick_grid.grid(np.zeros((4, 4)))
    with pytest.raises(InvalidParameterError, match="brick size"):
        brick_grid.grid(np.zeros((4, 4, 4)), 0)
    with pytest.raises(InvalidParameterError, match="expected"):
        brick_grid.from_rgba(np.zeros((4, 4, 4, 3), np.uint8))


def sparse_chronovolume(shape, seed: int, blobs: int = 4) -> chronocl.Chronovolume:
    """Premultiplied RGBA zero everywhere but a few random blobs and specks of random size,
    with some colour where opacity is 0 (which draws nothing, skipped or not)."""
    rng = np.random.default_rng(seed)
    zz, yy, xx = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in shape), indexing="ij")
    alpha = np.zeros(shape, dtype=np.float32)
    for _ in range(blobs):
        c = rng.random(3) * np.array(shape)
        r = 1.0 + rng.random() * min(shape) / 6
        d2 = ((zz - c[0]) ** 2 + (yy - c[1]) ** 2 + (xx - c[2]) ** 2) / r**2
        alpha = np.maximum(alpha, np.where(d2 < 1, (1 - d2) * rng.uniform(0.2, 0.9), 0))
    specks = rng.random(shape) < 2e-4
    alpha[specks] = rng.uniform(0.05, 1.0, int(specks.sum()))
    rgb = rng.random((*shape, 3), dtype=np.float32) * alpha[..., None]
    rgb[(alpha == 0) & (rng.random(shape) < 0.01)] = 0.3
    rgba = np.concatenate([rgb, alpha[..., None]], axis=-1).astype(np.float32)
    spacing = dict(zip("xyz", rng.uniform(0.6, 1.4, 3).tolist(), strict=True))
    return chronocl.Chronovolume(rgba, None, {"spacing": spacing})


def hollow_chronovolume(shape, seed: int) -> chronocl.Chronovolume:
    """A translucent box of varied colour with an empty brick inside: voxels 7-16 along every
    axis are empty, so the bricks of voxels 8-15 (grown by a voxel) are skipped, and every ray
    through them lands on coloured samples (voxels 6 and 17 on), where a skip one sample late
    changes the picture (random blobs only sometimes put colour there)."""
    rng = np.random.default_rng(seed)
    idx = np.indices(shape)
    hole = np.all((idx >= 7) & (idx < 17), axis=0)
    alpha = np.where(hole, 0, rng.uniform(0.02, 0.15, shape)).astype(np.float32)
    rgb = rng.random((*shape, 3), dtype=np.float32) * alpha[..., None]
    rgba = np.concatenate([rgb, alpha[..., None]], axis=-1)
    spacing = dict(zip("xyz", rng.uniform(0.6, 1.4, 3).tolist(), strict=True))
    return chronocl.Chronovolume(rgba, None, {"spacing": spacing})


@pytest.mark.parametrize(
    "shape,seed,hollow",
    [
        ((19, 27, 35), 1, False),
        ((40, 9, 23), 2, False),
        ((33, 33, 17), 3, False),
        ((8, 16, 24), 4, False),
        ((25, 26, 24), 5, True),
        ((24, 31, 27), 6, True),
    ],
)
def test_skipping_draws_the_unskipped_picture(rc, shape, seed, hollow):
    cv = (hollow_chronovolume if hollow else sparse_chronovolume)(shape, seed)
    volumes = [rc.upload(cv), rc.upload(cv, "f1", nearest=True)]
    try:
        for vol in volumes:
            for view in VIEWS:
                args = {k: v for k, v in view.items() if k != "camera"}
                skipped = rc.draw(vol, view["camera"], SIZE, **args)
                plain = rc.draw(vol, view["camera"], SIZE, skip=False, **args)
                assert skipped.max() > 0
                assert np.array_equal(skipped, plain), (view, int(np.abs(skipped - plain).max()))
    finally:
        for vol in volumes:
            vol.release()


def test_samples_per_ray_drop_on_a_sparse_volume(rc):
    cv = sparse_chronovolume((64, 64, 64), seed=7, blobs=3)
    vol = rc.upload(cv, "f1")
    try:
        camera = Camera(30.0, 20.0, zoom=1.2)
        before = rc.samples(vol, camera, SIZE, skip=False)
        after = rc.samples(vol, camera, SIZE)
        hit = before[..., 0] > 0
        assert hit.mean() > 0.1
        assert (before[..., 1] == 0).all()  # no grid reads without skipping
        assert (after[..., 0] <= before[..., 0]).all()  # never more samples on any ray
        assert after[..., 0][hit].mean() < 0.5 * before[..., 0][hit].mean()
        assert (after[..., 1][hit] >= 1).all()
    finally:
        vol.release()


def test_a_full_volume_takes_every_sample(rc):
    """With no empty brick, skipping takes exactly the unskipped samples on every ray."""
    rng = np.random.default_rng(5)
    alpha = rng.uniform(0.001, 0.02, (21, 30, 26, 1)).astype(np.float32)
    rgba = np.concatenate([alpha * rng.random((21, 30, 26, 3), dtype=np.float32), alpha], -1)
    vol = rc.upload(chronocl.Chronovolume(rgba, None, {}))
    try:
        for view in VIEWS[:3]:
            camera = view["camera"]
            before = rc.samples(vol, camera, SIZE, skip=False)
            after = rc.samples(vol, camera, SIZE)
            assert before[..., 0].max() > 10
            assert np.array_equal(before[..., 0], after[..., 0])
    finally:
        vol.release()


def test_viewer_slot_keeps_its_grid_in_step(rc):
    """The viewer's upload rewrites the grid texture with the volume; pictures stay equal."""
    slot = ViewSlot()
    camera = Camera(30.0, 20.0, zoom=1.2)
    try:
        vol = upload(rc, slot, sparse_chronovolume((48, 40, 44), 11))
        grid = vol.bricks
        assert grid is not None and tuple(grid.size) == (6, 5, 6)
        for seed in (12, 13):
            cv = sparse_chronovolume((48, 40, 44), seed)
            vol = upload(rc, slot, cv)
            assert vol.bricks is grid  # the same texture, rewritten in place
            data = np.frombuffer(grid.read(), np.uint8).reshape(6, 5, 6)
            assert np.array_equal(data, brick_grid.from_rgba(convert(cv.rgba, "f1")[0]))
            assert np.array_equal(
                rc.draw(vol, camera, SIZE), rc.draw(vol, camera, SIZE, skip=False)
            )
    finally:
        slot.release_gl()


def test_a_draw_that_may_be_given_up_is_the_same_picture_and_stops_between_bands(rc):
    """A refine's draw goes in bands of rows with a look at newer input before each: the
    picture is the one drawn at once, and the draw stops at the first band after input."""
    from chronocl.core.errors import SupersededError

    cv = sparse_chronovolume((33, 33, 17), 7)
    vol = rc.upload(cv)
    size = (61, 47)
    try:
        wholes = []
        for view in VIEWS:
            args = {k: v for k, v in view.items() if k != "camera"}
            wholes.append(rc.draw(vol, view["camera"], size, **args))
            looks: list[int] = []
            banded = rc.draw(
                vol, view["camera"], size, stop=lambda seen=looks: seen.append(1) or False, **args
            )
            assert np.array_equal(wholes[-1], banded) and len(looks) == TUNING.draw_bands
        calls = iter([False, False, True])
        with pytest.raises(SupersededError):
            rc.draw(vol, VIEWS[0]["camera"], size, stop=lambda: next(calls))
        args = {k: v for k, v in VIEWS[0].items() if k != "camera"}
        again = rc.draw(vol, VIEWS[0]["camera"], size, **args)  # no band's scissor left behind
        assert np.array_equal(again, wholes[0]) and again.max() > 0
    finally:
        vol.release()
