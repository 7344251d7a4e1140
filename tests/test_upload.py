"""Display textures: the conversion helper, RGBA8 against float32 images, in-place updates."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl.core.errors import InvalidParameterError, RendererUnavailableError
from chronocl.core.memory import spares
from chronocl.core.tuning import TUNING
from chronocl.data import synthetic
from chronocl.integration import inmemory
from chronocl.render import Camera
from chronocl.render.camera import world_geometry
from chronocl.render.raycaster import Raycaster, occupied_box
from chronocl.render.upload import FORMATS, convert, occupancy
from chronocl.viewer.slots import ViewSlot, upload

from .strategies import examples

CAMERA = Camera(azimuth=30.0, elevation=20.0, zoom=1.2)  # the viewer's default view


@pytest.fixture(scope="module")
def rc() -> Raycaster:
    try:
        return Raycaster()
    except RendererUnavailableError as exc:  # no EGL: nothing to draw with
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def demo() -> dict[tuple[str, str], chronocl.Chronovolume]:
    """The demo data sets at 40^3 (8 steps) in three modes."""
    out = {}
    for name in ("vortex", "jet"):
        data = np.stack(list(synthetic.steps(name, 8, (40, 40, 40))))
        series = chronocl.TimeSeries.from_array(data)
        for mode in ("alpha", "additive", "max"):
            # as the viewer shows it: the default data TF over the series' range
            viewer_tf = chronocl.DataTF(value_range="global")
            out[name, mode] = chronocl.integrate(
                series, "0:8", mode, engine="numpy", data_tf=viewer_tf
            )
    return out


def random_rgba(shape, seed=0, empty=0.5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    alpha = rng.random((*shape, 1), dtype=np.float32)
    alpha[rng.random((*shape, 1)) < empty] = 0.0
    return np.concatenate([alpha * rng.random((*shape, 3), dtype=np.float32), alpha], axis=-1)


def cv_of(rgba: np.ndarray) -> chronocl.Chronovolume:
    return chronocl.Chronovolume(rgba, None, {"spacing": {"x": 1.0, "y": 1.0, "z": 1.0}})


@pytest.mark.parametrize("shape", [(1, 3, 5), (7, 5, 3), (33, 20, 70), (40, 64, 64)])
def test_convert_matches_numpy(shape):
    """Every format's bytes and the occupancy match plain numpy, serial and threaded alike
    (the last two shapes are above TUNING.upload_serial_voxels)."""
    rgba = random_rgba(shape, empty=0.7)
    rgba[: shape[0] // 2] = 0.0  # empty slices, rows and columns at the low end
    rgba[..., -1:, :] = 0.0
    f1, occ1 = convert(rgba, "f1")
    f2, occ2 = convert(rgba, "f2")
    f4, occ4 = convert(rgba, "f4")
    assert f1.dtype == np.uint8 and f2.dtype == np.float16
    np.testing.assert_array_equal(f1, np.clip(np.round(rgba * 255), 0, 255).astype(np.uint8))
    np.testing.assert_array_equal(f2, rgba.astype(np.float16))
    assert f4 is rgba  # float32, C-contiguous: sent as it is
    for occ, alpha in ((occ1, f1[..., 3]), (occ2, rgba[..., 3]), (occ4, rgba[..., 3])):
        ref = occupancy(alpha)
        for got, want in ((occ.z, ref.z), (occ.y, ref.y), (occ.x, ref.x)):
            np.testing.assert_array_equal(got, want)


@settings(max_examples=examples(30), deadline=None)
@given(
    shape=st.tuples(st.integers(1, 40), st.integers(1, 23), st.integers(1, 37)),
    seed=st.integers(0, 2**31),
    empty=st.sampled_from([0.0, 0.9, 0.999, 1.0]),
)
def test_rgba8_sent_as_it_is_finds_the_occupancy_numpy_does(shape, seed, empty):
    """A display chronovolume (RGBA8 from the kernels) is only scanned: its occupancy equals
    plain numpy's over its opacity, colour bytes of voxels with opacity 0 included."""
    rng = np.random.default_rng(seed)
    rgba = rng.integers(0, 256, (*shape, 4), dtype=np.uint8)
    rgba[..., 3][rng.random(shape) < empty] = 0
    data, occ = convert(rgba, "f1")
    assert data is rgba
    ref = occupancy(rgba[..., 3])
    for got, want in ((occ.z, ref.z), (occ.y, ref.y), (occ.x, ref.x)):
        np.testing.assert_array_equal(got, want)


def test_convert_reuses_staging_and_takes_strided_input():
    rgba = random_rgba((36, 40, 30), seed=1)
    staging, _ = convert(rgba, "f1")
    again, _ = convert(rgba[::-1], "f1", staging)  # a reversed view: not contiguous
    assert again is staging
    np.testing.assert_array_equal(again, np.round(rgba[::-1] * 255).astype(np.uint8))
    f4, _ = convert(rgba[::-1], "f4")
    assert f4.flags.c_contiguous and np.array_equal(f4, rgba[::-1])
    other, _ = convert(rgba[:20], "f1", staging)  # another shape: a new buffer
    assert other is not staging and other.shape == (20, 40, 30, 4)
    with pytest.raises(InvalidParameterError):
        convert(rgba, "f3")


def test_occupied_box_empty_and_clipped():
    extent = np.array([1.0, 0.5, 0.25])
    voxel = extent / np.array([8, 4, 2])
    lo, hi = occupied_box(np.zeros((2, 4, 8), np.float32), extent, voxel)
    assert (lo > hi).all()  # every ray misses
    alpha = np.zeros((2, 4, 8), np.float32)
    alpha[0, 0, 7] = 0.5
    lo, hi = occupied_box(alpha, extent, voxel)
    np.testing.assert_allclose(lo, [-0.5 + 6 * 0.125, -0.25, -0.125])
    np.testing.assert_allclose(hi, [0.5, -0.25 + 2 * 0.125, 0.125])


def test_rgba8_image_difference_is_invisible(rc, demo):
    """RGBA8 against float32 textures, jitter off, the viewer's camera, on black and white.

    Measured (docs/display.md, 128^3 and 256^3 at 512^2): PSNR 56-60 dB, 99.9 % of pixel
    values within 3/255, the largest difference 7/255 at a few silhouette pixels; here
    (40^3 at 160^2, llvmpipe) PSNR 56.4-60.8 dB, at most 0.007 % of values beyond 3/255, the
    largest 5/255; with the default TF translucent from u = 0.05 (more faint material along
    each ray) up to 0.15 % beyond 3/255. The bounds (50 dB, 0.3 %, 10/255) leave room for
    another driver's filtering of 8-bit texels and stay where no one sees a difference on a
    still: the viewer's own JPEG frames (quality 88) move pixel values by far more (43 dB,
    up to 50/255).
    """
    for (name, mode), cv in demo.items():
        slot4, slot1 = ViewSlot(), ViewSlot()
        vol4 = upload_as(rc, slot4, cv, "f4")
        vol1 = upload_as(rc, slot1, cv, "f1")
        for background in ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)):
            a = rc.draw(vol4, CAMERA, (160, 160), background=background, jitter=False)
            b = rc.draw(vol1, CAMERA, (160, 160), background=background, jitter=False)
            diff = np.abs(a.astype(int) - b.astype(int))
            mse = float(np.mean(diff.astype(float) ** 2))
            psnr = 10 * np.log10(255.0**2 / mse) if mse else np.inf
            where = f"{name} {mode} on {background}"
            assert (a != a[0, 0]).any(), where  # something drawn
            assert psnr >= 50.0, f"{where}: PSNR {psnr:.1f} dB"
            assert (diff > 3).mean() <= 0.003, f"{where}: {(diff > 3).mean():.3%} beyond 3/255"
            assert diff.max() <= 10, f"{where}: largest difference {diff.max()}/255"
        slot4.release_gl()
        slot1.release_gl()


def upload_as(rc, slot: ViewSlot, cv, fmt: str):
    """The viewer's upload with the format forced (the size rule would pick f4 here)."""
    saved = inmemory.DISPLAY_VOXELS
    inmemory.DISPLAY_VOXELS = 0 if fmt == "f1" else 2**40
    try:
        vol = upload(rc, slot, cv)
    finally:
        inmemory.DISPLAY_VOXELS = saved
    assert vol.texture.dtype == fmt
    return vol


@pytest.mark.parametrize("fmt", ["f4", "f1"])
def test_in_place_update_draws_what_a_fresh_upload_draws(rc, demo, fmt):
    first, second = demo["vortex", "alpha"], demo["jet", "max"]
    slot = ViewSlot()
    vol = upload_as(rc, slot, first, fmt)
    texture = vol.texture
    vol = upload_as(rc, slot, second, fmt)
    assert vol.texture is texture and slot.allocated == 1  # written in place, not reallocated
    fresh_slot = ViewSlot()
    fresh = upload_as(rc, fresh_slot, second, fmt)
    assert fresh.texture is not texture
    np.testing.assert_array_equal(vol.occupied[0], fresh.occupied[0])
    np.testing.assert_array_equal(vol.occupied[1], fresh.occupied[1])
    a = rc.draw(vol, CAMERA, (96, 96), jitter=False)
    b = rc.draw(fresh, CAMERA, (96, 96), jitter=False)
    np.testing.assert_array_equal(a, b)
    assert a.max() > 0
    slot.release_gl()
    fresh_slot.release_gl()
    assert slot.volume is None


def test_a_slots_staging_goes_back_to_the_pool_and_the_next_frame_writes_on_it(rc):
    """The texture data's host staging is the pool's, not the panel's (issue 47): given back
    once written, so the next frame, of this view or another, converts into the same memory
    (already faulted in), and an idle panel holds none."""
    shape = (64, 256, 256)  # its RGBA8 staging is 16 MiB: TUNING.mapped_bytes, pooled
    nbytes = int(np.prod(shape)) * 4
    assert nbytes >= TUNING.mapped_bytes
    spares.clear()
    slot, other = ViewSlot(), ViewSlot()
    first, second = np.zeros((*shape, 4), np.float32), np.zeros((*shape, 4), np.float32)
    first[10:20, 30:40, 50:60] = 0.5
    second[40:50, 100:140, 7:9] = 0.25
    upload_as(rc, slot, cv_of(first), "f1")
    (given,) = [m for m in spares.maps if len(m) == nbytes]  # back in the pool, not the slot's
    vol = upload_as(rc, other, cv_of(second), "f1")
    (again,) = [m for m in spares.maps if len(m) == nbytes]
    assert again is given  # the second frame took it, wrote on it, and gave it back
    texels = np.empty((*shape, 4), np.uint8)
    vol.texture.read_into(texels)
    np.testing.assert_array_equal(texels, np.round(second * 255).astype(np.uint8))
    slot.release_gl()
    other.release_gl()


def test_shape_or_format_change_reallocates(rc):
    slot = ViewSlot()
    small = cv_of(random_rgba((12, 10, 8), seed=2))
    vol = upload_as(rc, slot, small, "f1")
    texture = vol.texture
    assert texture.size == (8, 10, 12)
    other = cv_of(random_rgba((6, 10, 8), seed=3))
    vol = upload_as(rc, slot, other, "f1")
    assert vol.texture is not texture and vol.texture.size == (8, 10, 6)
    extent, voxel = world_geometry(other.shape, other.spacing)
    np.testing.assert_allclose(vol.extent, extent)
    assert vol.unit == pytest.approx(float(voxel.min()))
    texture = vol.texture
    vol = upload_as(rc, slot, other, "f4")
    assert vol.texture is not texture and vol.texture.dtype == "f4"
    assert slot.allocated == 3
    # Shapes that alternate (a coarse level, then full resolution) reuse their kept textures.
    first = upload_as(rc, slot, small, "f1").texture
    assert upload_as(rc, slot, other, "f1").texture is texture
    again = upload_as(rc, slot, small, "f1")
    assert again.texture is first and slot.allocated == 3
    fresh_slot = ViewSlot()
    a = rc.draw(again, CAMERA, (64, 64), jitter=False)
    b = rc.draw(upload_as(rc, fresh_slot, small, "f1"), CAMERA, (64, 64), jitter=False)
    np.testing.assert_array_equal(a, b)
    assert len(slot.kept) <= 2
    slot.release_gl()
    fresh_slot.release_gl()
    assert not slot.kept


def test_raycaster_upload_formats_agree(rc):
    """`Raycaster.upload` shares the helper: f4, f2 and f1 give the same nearest-sample view
    within the format's rounding, and the default (f2) is unchanged."""
    cv = cv_of(random_rgba((16, 18, 20), seed=4) * 0.6)
    images = {}
    for fmt in FORMATS:
        vol = rc.upload(cv, dtype=fmt, nearest=True)
        assert vol.texture.dtype == fmt
        images[fmt] = rc.draw(vol, CAMERA, (64, 64), jitter=False).astype(int)
        vol.release()
    vol = rc.upload(cv)
    assert vol.texture.dtype == "f2"
    vol.release()
    assert np.abs(images["f2"] - images["f4"]).max() <= 1
    assert np.abs(images["f1"] - images["f4"]).max() <= 12


def test_a_refines_upload_is_given_up_between_slabs_and_written_again(rc, monkeypatch):
    """A refine's texture write stops between z-slabs once newer input comes; the slot then
    shows nothing uploaded, and its next upload draws what a fresh one draws."""
    from chronocl.core.errors import SupersededError

    slot = ViewSlot()
    first, second = cv_of(random_rgba((24, 10, 8), seed=4)), cv_of(random_rgba((24, 10, 8), 5))
    upload_as(rc, slot, first, "f1")
    asked = []

    def given_up() -> bool:
        asked.append(1)
        return len(asked) > 2  # newer input after two slabs

    monkeypatch.setattr(inmemory, "DISPLAY_VOXELS", 0)  # RGBA8, as upload_as(..., "f1")
    with pytest.raises(SupersededError):
        upload(rc, slot, second, given_up)
    assert slot.uploaded is None and slot.volume is not None and len(asked) == 3
    vol = upload_as(rc, slot, second, "f1")
    fresh_slot = ViewSlot()
    a = rc.draw(vol, CAMERA, (64, 64), jitter=False)
    b = rc.draw(upload_as(rc, fresh_slot, second, "f1"), CAMERA, (64, 64), jitter=False)
    np.testing.assert_array_equal(a, b)
    slot.release_gl()
    fresh_slot.release_gl()
