"""Ingest: raw steps and .npy -> store -> same values, statistics, and every bad input."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import (
    ChronoclError,
    InputNotFoundError,
    InvalidDataError,
    InvalidParameterError,
    OutputExistsError,
    UnknownNameError,
)
from chronocl.data.formats.npy import ingest_npy
from chronocl.data.formats.raw import ingest_raw
from chronocl.data.ingest import ingest

SHAPE = (5, 4, 3)  # (Z, Y, X): dims NX NY NZ = 3 4 5


def write_raw(folder, series: np.ndarray, dtype: str, endian: str = "<", names=None) -> list:
    files = []
    for t, step in enumerate(series):
        name = names[t] if names else f"step{t}.raw"
        path = folder / name
        step.astype(np.dtype(dtype).newbyteorder(endian)).tofile(path)
        files.append(path)
    return files


def no_partial(folder) -> bool:
    return not [p for p in folder.iterdir() if ".partial-" in p.name]


@pytest.mark.parametrize(
    ("dtype", "endian"),
    [
        ("float32", "<"),
        ("float32", ">"),
        ("uint8", "<"),
        ("uint16", ">"),
        ("int16", "<"),
        ("float64", ">"),
    ],
)
def test_raw_round_trip(tmp_path, dtype, endian):
    rng = np.random.default_rng(1)
    data = (rng.random((4, *SHAPE)) * 200).astype(dtype)
    write_raw(tmp_path, data, dtype, endian)
    series = ingest_raw(
        [str(tmp_path / "step*.raw")],
        tmp_path / "s.zarr",
        dims=(3, 4, 5),
        dtype=dtype,
        endian="little" if endian == "<" else "big",
        spacing=(2.5, 1.0, 0.5),
    )
    reopened = chronocl.open(tmp_path / "s.zarr")
    for s in (series, reopened):
        assert s.shape == (4, *SHAPE)
        assert s.dtype == np.dtype(dtype)
        np.testing.assert_array_equal(s.read(range(4)), data)
        assert s.vmin == data.min() and s.vmax == data.max()
        np.testing.assert_allclose(s.stats.step_min, data.min(axis=(1, 2, 3)))
        np.testing.assert_allclose(s.stats.step_max, data.max(axis=(1, 2, 3)))
        np.testing.assert_allclose(s.stats.step_mean, data.astype(np.float64).mean(axis=(1, 2, 3)))
        assert s.spacing == (2.5, 1.0, 0.5)
        assert s.data.chunksize[0] == 1  # one time step per chunk


def test_files_are_sorted_naturally(tmp_path):
    data = np.arange(11 * 60, dtype=np.float32).reshape(11, *SHAPE)
    names = [f"v{t}.raw" for t in range(11)]  # v10 must come after v9, not after v1
    files = write_raw(tmp_path, data, "float32", names=names)
    series = ingest_raw([str(f) for f in reversed(files)], tmp_path / "s.zarr", dims=(3, 4, 5))
    np.testing.assert_array_equal(series.read(range(11)), data)


def test_npy_round_trip_and_big_endian(tmp_path):
    data = np.random.default_rng(2).random((3, *SHAPE)).astype(">f4")
    np.save(tmp_path / "a.npy", data)
    series = ingest([str(tmp_path / "a.npy")], tmp_path / "s.zarr", times=[0.0, 0.5, 1.0])
    np.testing.assert_array_equal(series.read([0, 1, 2]), data.astype("<f4"))
    assert series.times == (0.0, 0.5, 1.0)


def test_wrong_file_size(tmp_path):
    write_raw(tmp_path, np.zeros((2, *SHAPE)), "float32")
    with pytest.raises(InvalidDataError, match="has 240 bytes but --dims 3 4 6"):
        ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 6))
    with pytest.raises(InvalidDataError, match="--dtype float64 needs 480"):
        ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5), dtype="float64")
    assert not (tmp_path / "s.zarr").exists() and no_partial(tmp_path)


def test_mixed_sizes(tmp_path):
    write_raw(tmp_path, np.zeros((2, *SHAPE)), "float32")
    (tmp_path / "step2.raw").write_bytes(b"\0" * 236)
    with pytest.raises(InvalidDataError, match="differ in size"):
        ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5))


def test_missing_files_and_empty_glob(tmp_path):
    with pytest.raises(InputNotFoundError, match="no files match"):
        ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5))
    with pytest.raises(InputNotFoundError, match="does not exist"):
        ingest_raw([str(tmp_path / "gone.raw")], tmp_path / "s.zarr", dims=(3, 4, 5))
    with pytest.raises(InputNotFoundError, match="no input files"):
        ingest_raw([], tmp_path / "s.zarr", dims=(3, 4, 5))
    with pytest.raises(InputNotFoundError) as info:
        ingest_npy(tmp_path / "gone.npy", tmp_path / "s.zarr")
    assert isinstance(info.value, FileNotFoundError)


def test_zero_steps_and_bad_shapes(tmp_path):
    np.save(tmp_path / "empty.npy", np.zeros((0, *SHAPE), dtype=np.float32))
    with pytest.raises(InvalidDataError, match="zero time steps"):
        ingest_npy(tmp_path / "empty.npy", tmp_path / "s.zarr")
    np.save(tmp_path / "three.npy", np.zeros(SHAPE, dtype=np.float32))
    with pytest.raises(InvalidDataError, match="must be 4D"):
        ingest_npy(tmp_path / "three.npy", tmp_path / "s.zarr")
    with pytest.raises(InvalidDataError, match="zero time steps"):
        chronocl.TimeSeries.from_array(np.zeros((0, *SHAPE)))


def test_non_finite_values_rejected_or_filled(tmp_path):
    data = np.ones((3, *SHAPE), dtype=np.float32)
    data[1, 2, 1, 0] = np.nan
    data[2, 0, 0, 0] = np.inf
    write_raw(tmp_path, data, "float32")
    with pytest.raises(InvalidDataError, match=r"step1.raw \(step 1\) has 1 NaN/infinite"):
        ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5))
    assert not (tmp_path / "s.zarr").exists() and no_partial(tmp_path)
    series = ingest_raw(
        [str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5), nan_fill=0.0
    )
    assert series.read([1])[0, 2, 1, 0] == 0.0 and series.read([2])[0, 0, 0, 0] == 0.0
    assert series.vmin == 0.0 and series.vmax == 1.0
    with pytest.raises(InvalidDataError, match="NaN or infinite"):
        chronocl.TimeSeries.from_array(data)


def test_existing_output_needs_overwrite(tmp_path):
    write_raw(tmp_path, np.zeros((1, *SHAPE)), "float32")
    ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5))
    with pytest.raises(OutputExistsError, match="--overwrite") as info:
        ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5))
    assert isinstance(info.value, FileExistsError)
    write_raw(tmp_path, np.full((1, *SHAPE), 7.0), "float32")
    series = ingest_raw(
        [str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5), overwrite=True
    )
    assert series.vmax == 7.0 and no_partial(tmp_path)


def test_failed_overwrite_keeps_the_old_store(tmp_path):
    write_raw(tmp_path, np.full((2, *SHAPE), 3.0), "float32")
    ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5))
    bad = np.full((2, *SHAPE), np.nan, dtype=np.float32)
    write_raw(tmp_path, bad, "float32")
    with pytest.raises(InvalidDataError):
        ingest_raw([str(tmp_path / "*.raw")], tmp_path / "s.zarr", dims=(3, 4, 5), overwrite=True)
    assert chronocl.open(tmp_path / "s.zarr").vmax == 3.0 and no_partial(tmp_path)


def test_bad_options(tmp_path):
    write_raw(tmp_path, np.zeros((1, *SHAPE)), "float32")
    files = [str(tmp_path / "step0.raw")]
    with pytest.raises(UnknownNameError, match="complex64"):
        ingest_raw(files, tmp_path / "s.zarr", dims=(3, 4, 5), dtype="complex64")
    with pytest.raises(UnknownNameError, match="middle"):
        ingest_raw(files, tmp_path / "s.zarr", dims=(3, 4, 5), endian="middle")
    with pytest.raises(InvalidParameterError, match="needs --dims"):
        ingest(files, tmp_path / "s.zarr")
    with pytest.raises(InvalidParameterError, match="three positive sizes"):
        ingest_raw(files, tmp_path / "s.zarr", dims=(3, 0, 5))
    with pytest.raises(ChronoclError, match="spacing"):
        ingest_raw(files, tmp_path / "s.zarr", dims=(3, 4, 5), spacing=(1, -1, 1))


@pytest.mark.parametrize(
    ("data", "given", "warned"),
    [
        ("smooth", (56, 96, 64), "--dims 64 96 56 but not with --dims 56 96 64"),
        ("smooth", (96, 64, 56), "--dims 64 96 56 but not with --dims 96 64 56"),
        ("smooth", (64, 96, 56), None),  # the right order
        ("noise", (56, 96, 64), None),  # nothing to tell the orders apart
    ],
)
def test_dims_in_a_wrong_order_get_a_one_line_warning(
    tmp_path, monkeypatch, capsys, data, given, warned
):
    """Raw steps read with --dims in another order (the same byte count) come out as sheared
    copies; ingest says so in one line and goes on (it cannot always know)."""
    import sys

    from chronocl.cli import main
    from chronocl.data import synthetic

    if data == "smooth":  # (Z, Y, X) = (56, 96, 64): NX 64, NY 96, NZ 56
        step = next(synthetic.steps("vortex", 1, (56, 96, 64), 0)).astype(np.float32)
    else:
        step = np.random.default_rng(0).random((56, 96, 64)).astype(np.float32)
    step.tofile(tmp_path / "s.raw")
    dims = [str(n) for n in given]
    argv = ["chronocl", "ingest", str(tmp_path / "s.raw"), "-o", str(tmp_path / "o.zarr")]
    monkeypatch.setattr(sys, "argv", [*argv, "--dims", *dims])
    with pytest.raises(SystemExit) as info:
        main()
    assert (info.value.code or 0) == 0 and (tmp_path / "o.zarr").exists()
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "warning" in ln]
    if warned is None:
        assert lines == []
    else:
        assert len(lines) == 1 and lines[0].startswith("chronocl: warning: s.raw reads")
        assert warned in lines[0] and "check the order of --dims" in lines[0]


def test_the_dims_check_leaves_thin_volumes_alone():
    """A 2D step (NZ = 1) or a few slices cannot tell a neighbour from a sheared copy."""
    from chronocl.data import synthetic
    from chronocl.data.formats.raw import likelier_dims

    smooth = next(synthetic.steps("vortex", 1, (2, 48, 64), 0)).astype(np.float32)
    noise = np.random.default_rng(0).random((1, 48, 64)).astype(np.float32)
    assert likelier_dims(smooth[:1].ravel(), (64, 48, 1)) is None
    assert likelier_dims(noise.ravel(), (64, 48, 1)) is None
    assert likelier_dims(smooth.ravel(), (64, 48, 2)) is None


# ---------------------------------------------------------------- byte order and type
def _field(name: str) -> np.ndarray:
    """Steps (2, Z, Y, X) of a smooth field users bring, as float64 in its own units."""
    from chronocl.data import synthetic
    from chronocl.data.simulations import simulate

    if name == "vortex":  # mostly empty space
        return np.stack(list(synthetic.steps("vortex", 2, (40, 48, 56), 0))).astype(np.float64)
    return simulate(name, (20, 24, 28), 6)[-2:].astype(np.float64)


def _as(data: np.ndarray, dtype: str) -> np.ndarray:
    if np.dtype(dtype).kind == "f":
        return data.astype(dtype)
    scaled = (data - data.min()) / (np.ptp(data) or 1) * 30000  # 16-bit values
    return (scaled - (15000 if dtype == "int16" else 0)).astype(dtype)


SOURCES = ["float32", "float64", "uint16", "int16"]
# the mistakes a user makes with them: the other byte order, or another type whose byte
# count matches once --dims is scaled (NZ doubled or halved) to the file's size
MISTAKES = [
    (src, wrong)
    for src in SOURCES
    for wrong in ["endian", *(d for d in SOURCES if np.dtype(d).itemsize != np.dtype(src).itemsize)]
]


@pytest.mark.parametrize("field", ["gray-scott", "plume", "vortex"])
@pytest.mark.parametrize(("src", "wrong"), MISTAKES)
def test_a_wrong_endian_or_dtype_is_refused_naming_the_right_one(tmp_path, field, src, wrong):
    """Raw steps read with a wrong --endian or --dtype (the byte count matching) are refused
    in one line naming the flags that read them, before anything is written; read right,
    they ingest (issue 48)."""
    data = _as(_field(field), src)
    nz, ny, nx = data.shape[1:]
    files = write_raw(tmp_path, data, src, ">")  # written big-endian
    out = tmp_path / "o.zarr"
    if wrong == "endian":
        dtype, dims, fix = src, (nx, ny, nz), "pass --endian big"
    else:
        dtype = wrong
        z = nz * np.dtype(src).itemsize // np.dtype(wrong).itemsize
        dims, fix = (nx, ny, z), f"pass --dtype {src} --endian big --dims {nx} {ny} {nz}"
    with pytest.raises(InvalidDataError) as info:
        ingest_raw([str(f) for f in files], out, dims=dims, dtype=dtype, endian="little")
    message = str(info.value)
    assert message.endswith(fix) and "\n" not in message, message
    assert not out.exists() and no_partial(tmp_path)
    series = ingest_raw([str(f) for f in files], out, dims=(nx, ny, nz), dtype=src, endian="big")
    np.testing.assert_array_equal(series.read(range(2)), data)


def test_a_later_step_misread_is_refused_too(tmp_path):
    """The first step all zeros (a plume before it starts) reads alike in every byte order;
    the next step, misread, is refused before the store appears, and --nan-fill does not
    let junk through."""
    data = _as(_field("gray-scott"), "float32")
    data[0] = 0
    files = write_raw(tmp_path, data, "float32", ">")
    out = tmp_path / "o.zarr"
    for nan_fill in (None, 0.0):
        with pytest.raises(InvalidDataError, match=r"step1\.raw reads as .* pass --endian big$"):
            ingest_raw([str(f) for f in files], out, dims=(28, 24, 20), nan_fill=nan_fill)
        assert not out.exists() and no_partial(tmp_path)


@pytest.mark.parametrize("dtype", ["float32", "uint16", "uint8"])
def test_noise_and_masked_data_are_read_as_given(tmp_path, dtype):
    """Nothing reads white noise (uniform or Gaussian) or a regular pattern as clearly smooth
    data, so they ingest as given; NaN in float data (a land mask) is NaN, not a misread:
    ingest asks for --nan-fill as before."""
    rng = np.random.default_rng(3)
    noises = [(rng.random((2, 20, 24, 28)) * 200).astype(dtype)]
    if dtype == "float32":  # zero-mean Gaussian, small and offset: by value, a float64
        gauss = rng.standard_normal((2, 20, 24, 28))  # reading of it looks smooth
        noises += [(gauss * k + b).astype(dtype) for k, b in ((1, 0), (1e-3, 0), (1, 3))]
    if dtype == "uint16":  # a pattern alternating along x: constant when read as float32
        noises.append(np.resize(np.array([5, 1005], dtype), (2, 20, 24, 28)))
    for i, noise in enumerate(noises):
        (tmp_path / str(i)).mkdir()
        files = write_raw(tmp_path / str(i), noise, dtype)
        out = tmp_path / f"n{i}.zarr"
        series = ingest_raw([str(f) for f in files], out, dims=(28, 24, 20), dtype=dtype)
        np.testing.assert_array_equal(series.read(range(2)), noise)
    if dtype == "float32":
        masked = _as(_field("gray-scott"), "float32")
        masked[:, :, :, :9] = np.nan  # a third of every step
        (tmp_path / "m").mkdir()
        files = write_raw(tmp_path / "m", masked, "float32")
        with pytest.raises(InvalidDataError, match="NaN/infinite values; pass --nan-fill"):
            ingest_raw([str(f) for f in files], tmp_path / "m.zarr", dims=(28, 24, 20))


# ---------------------------------------------------------------- --meta
def test_meta_gives_dims_spacing_type_order_and_times(tmp_path):
    """A simulation's JSON gives what raw input needs (issue 48): ingest uses it where no flag
    is given, says what it used and where, and the steps read back equal."""
    from chronocl.data.simulations import simulate

    from .test_cli import assert_one_line_error, cli

    steps = simulate("gray-scott", (20, 24, 28), 4)
    for t, step in enumerate(steps):
        step.astype(">f4").tofile(tmp_path / f"gs_{t}.raw")
    meta = tmp_path / "run.json"
    meta.write_text(
        '{"grid": {"nx": 28, "ny": 24, "nz": 20, "spacing": {"x": 0.5, "y": 0.5, "z": 2}},'
        ' "output": {"dtype": ">f4", "dt": 0.25, "save_every": 2, "time_unit": "ms"}}'
    )
    glob = str(tmp_path / "gs_*.raw")
    done = cli("ingest", glob, "-o", str(tmp_path / "a.zarr"), "--meta", str(meta))
    assert done.returncode == 0, done.stderr
    said = " ".join(done.stderr.split())
    for line in (
        "from --meta: dims 28 24 20 (", "run.json:grid.nx/ny/nz)",
        "from --meta: spacing 0.5 0.5 2.0 (", "from --meta: dtype float32 (",
        "from --meta: endian big (", "run.json:output.dtype)",
        "times: 0.0 .. 1.5 ms, from",
    ):  # fmt: skip
        assert line in said, said
    series = chronocl.open(tmp_path / "a.zarr")
    np.testing.assert_array_equal(series.read(range(4)), steps)
    assert series.spacing == (0.5, 0.5, 2.0) and list(series.times) == [0.0, 0.5, 1.0, 1.5]
    # a flag wins over the file; the npy takes the spacing and times only
    done = cli("ingest", glob, "-o", str(tmp_path / "b.zarr"), "--meta", str(meta),
               "--spacing", "1", "1", "1")  # fmt: skip
    assert done.returncode == 0 and "from --meta: spacing" not in done.stderr
    assert chronocl.open(tmp_path / "b.zarr").spacing == (1.0, 1.0, 1.0)
    np.save(tmp_path / "gs.npy", steps)
    done = cli(
        "ingest", str(tmp_path / "gs.npy"), "-o", str(tmp_path / "c.zarr"), "--meta", str(meta)
    )
    assert done.returncode == 0, done.stderr
    assert "from --meta: spacing" in done.stderr and "from --meta: dims" not in done.stderr
    # two sizes in one file: which one is meant is not guessed
    meta.write_text('{"dims": [28, 24, 20], "grid": {"dims": [20, 24, 28]}}')
    done = cli("ingest", glob, "-o", str(tmp_path / "d.zarr"), "--meta", str(meta))
    assert_one_line_error(done, "gives two dims")
    meta.write_text('{"dims": [28, 24, 20], "dtype": "complex64"}')
    done = cli("ingest", glob, "-o", str(tmp_path / "d.zarr"), "--meta", str(meta))
    assert_one_line_error(done, "not a type chronocl reads")
    assert not (tmp_path / "d.zarr").exists()
    # a flag settles what the file leaves open (or gets wrong), as the errors say; keys that
    # hold something else (a camera's resolution, a particle list's type) are passed over
    meta.write_text(
        '{"dims": [28, 24, 20], "grid": {"dims": [20, 24, 28]}, "dtype": "Float32",'
        ' "byte_order": "big-endian", "camera": {"resolution": [1920, 1080]},'
        ' "particles": {"dtype": "int64"}, "dt": 0.5, "time_unit": "not a unit at all"}'
    )
    done = cli("ingest", glob, "-o", str(tmp_path / "e.zarr"), "--meta", str(meta),
               "--dims", "28", "24", "20", "--time-unit", "s")  # fmt: skip
    assert done.returncode == 0, done.stderr
    series = chronocl.open(tmp_path / "e.zarr")
    np.testing.assert_array_equal(series.read(range(4)), steps)
    assert series.time_unit == "s" and list(series.times) == [0.0, 0.5, 1.0, 1.5]
