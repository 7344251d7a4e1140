"""Bad-input corpus, part one: damaged stores, every ingest format, and the Python API.

Each CLI case runs the real command and checks what `bad_input.assert_rejected` promises: exit
code 2, one line on stderr that names the problem, no traceback, the input byte-identical, no
output and no hidden partial. Each API case checks the error is a ChronoclError and also the
matching builtin.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import (
    ChronoclError,
    InvalidDataError,
    InvalidParameterError,
    InvalidSelectionError,
    StoreCorruptError,
)
from chronocl.data import synthetic
from chronocl.data.series import write_series

from .bad_input import assert_rejected, digest

SHAPE = (8, 10, 12)  # Z, Y, X: two stored chunks of 4 rows per step
STEPS = 6


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("base") / "s.zarr"
    write_series(
        path,
        synthetic.steps("vortex", STEPS, SHAPE, 0),
        n_steps=STEPS,
        volume_shape=SHAPE,
        dtype="float32",
        chunk_bytes=4 * 10 * 12 * 4,
    )
    return path


@pytest.fixture
def store(base, tmp_path) -> Path:
    """A private copy of the base store, to damage."""
    copy = tmp_path / "in" / "s.zarr"
    shutil.copytree(base, copy)
    return copy


def _json(path: Path, edit) -> None:
    d = json.loads(path.read_text())
    edit(d)
    path.write_text(json.dumps(d))


def _attrs(edit):
    return lambda s: _json(s / "zarr.json", lambda d: edit(d["attributes"]["chronocl"]))


def _chunk(s: Path, t: int = 3, zc: int = 1) -> Path:
    return s / "data" / "c" / str(t) / str(zc) / "0" / "0"


def _flip_byte(s: Path) -> None:
    f = _chunk(s)
    raw = bytearray(f.read_bytes())
    raw[len(raw) // 2] ^= 0x10
    f.write_bytes(bytes(raw))


def _set(key, value):
    def edit(a):
        a[key] = value

    return _attrs(edit)


DAMAGE = {
    "missing chunk": (lambda s: _chunk(s).unlink(), "chunk data/c/3/1/0/0 (step 3) is missing"),
    "all chunks of the array gone": (
        lambda s: shutil.rmtree(s / "data" / "c"),
        "is missing",
    ),
    "garbage chunk": (
        lambda s: _chunk(s).write_bytes(b"\x00garbage" * 40),
        "chunk data/c/3/1/0/0 (step 3) cannot be decoded",
    ),
    "truncated chunk": (
        lambda s: _chunk(s).write_bytes(_chunk(s).read_bytes()[:50]),
        "cannot be decoded",
    ),
    "empty chunk file": (lambda s: _chunk(s).write_bytes(b""), "cannot be decoded"),
    "one flipped bit (checksum)": (
        _flip_byte,
        "cannot be decoded (its checksum does not match its bytes: the file was damaged or cut",
    ),
    "garbled array metadata": (
        lambda s: (s / "data" / "zarr.json").write_text("{garbled"),
        "metadata file data/zarr.json cannot be read",
    ),
    "garbled group metadata": (
        lambda s: (s / "zarr.json").write_text('{"zarr_format": 3, "node'),
        "metadata file zarr.json cannot be read",
    ),
    "time length disagrees with statistics": (
        lambda s: _json(s / "data" / "zarr.json", lambda d: d["shape"].__setitem__(0, 5)),
        "5 time steps but 6 entries",
    ),
    "chunk shape changed": (
        lambda s: _json(
            s / "data" / "zarr.json",
            lambda d: d["chunk_grid"]["configuration"].__setitem__("chunk_shape", [1, 4, 5, 12]),
        ),
        "chunk shape",
    ),
    "vmin not a number": (_set("vmin", "abc"), "vmin is 'abc', not a number"),
    "vmax missing": (_attrs(lambda a: a.pop("vmax")), "lack 'vmax'"),
    "inverted value range": (
        _attrs(lambda a: a.update(vmin=a["vmax"], vmax=a["vmin"])),
        "is inverted",
    ),
    "vmin == vmax on varying data": (
        _attrs(lambda a: a.update(vmin=a["vmax"])),
        "disagrees with its per-step statistics",
    ),
    "statistics list cut short": (
        _attrs(lambda a: a.update(step_max=a["step_max"][:-1])),
        "entries in its step_max",
    ),
    "non-finite statistic": (
        _attrs(lambda a: a["step_mean"].__setitem__(0, "NaN")),
        "step_mean[0]",
    ),
    "negative spacing": (_set("spacing", {"x": -1, "y": 1, "z": 1}), "voxel spacing"),
    "time labels of the wrong length": (_set("times", [0, 1]), "2 time labels"),
    "byte order flipped in the metadata": (
        lambda s: _json(
            s / "data" / "zarr.json",
            lambda d: [c["configuration"].update(endian="big") for c in d["codecs"][:1]],
        ),
        "its array data is marked big-endian, not as written",
    ),
    "unsupported data type": (
        lambda s: _json(s / "data" / "zarr.json", lambda d: d.update(data_type="complex64")),
        "",
    ),
}


@pytest.mark.parametrize("damage", DAMAGE)
def test_damaged_store_is_reported_by_integrate(store, tmp_path, damage):
    harm, needle = DAMAGE[damage]
    harm(store)
    out = tmp_path / "o.zarr"
    assert_rejected(["integrate", store, out], needle, [store], [out], tmp_path)


@pytest.mark.parametrize(
    ("command", "damage"),
    [
        (["export", "{s}", "-o", "{o}/x.npy", "--format", "npy"], "missing chunk"),
        (["export", "{s}", "-o", "{o}/vti", "--format", "vti"], "garbage chunk"),
        (["export", "{s}", "-o", "{o}/raw", "--format", "raw"], "truncated chunk"),
        (["render", "{s}", "-o", "{o}/r.png", "--size", "32x32"], "missing chunk"),
        (["render", "{s}", "-o", "{o}/r.png", "--size", "32x32"], "garbage chunk"),
        (["integrate", "{s}", "{o}/o.zarr", "--engine", "numpy"], "missing chunk"),
        (["integrate", "{s}", "{o}/o.vti", "--mode", "max"], "garbage chunk"),
        (["info", "{s}"], "vmax missing"),
        (["info", "{s}"], "garbled array metadata"),
    ],
)
def test_damaged_store_is_reported_by_every_command(store, tmp_path, command, damage):
    harm, needle = DAMAGE[damage]
    harm(store)
    out = tmp_path / "out"
    out.mkdir()
    args = [a.format(s=store, o=out) for a in command]
    assert_rejected(args, needle, [store], folder=tmp_path)
    assert list(out.iterdir()) == []


def test_damage_found_while_streaming_leaves_nothing(tmp_path):
    """Integration streamed slab by slab under --memory stops at the damaged chunk, cleanly."""
    shape = (32, 64, 64)
    store = tmp_path / "in" / "big.zarr"
    write_series(
        store,
        synthetic.steps("vortex", 8, shape, 0),
        n_steps=8,
        volume_shape=shape,
        dtype="float32",
        chunk_bytes=4 * 64 * 64 * 4,
    )
    (store / "data" / "c" / "5" / "6" / "0" / "0").write_bytes(b"not zstd")
    out = tmp_path / "o.zarr"
    args = ["integrate", store, out, "--memory", "3MB"]
    assert_rejected(
        args, "chunk data/c/5/6/0/0 (step 5) cannot be decoded", [store], [out], tmp_path
    )


def test_verify_reports_each_damage_and_passes_a_sound_store(store, base):
    from .test_cli import cli

    assert cli("verify", base).returncode == 0
    _chunk(store, 1, 0).unlink()
    assert_rejected(["verify", store], "chunk data/c/1/0/0/0 (step 1) is missing", [store])


def test_verify_finds_data_that_disagree_with_the_statistics(store):
    """Values changed on disk but still decodable (an older store without checksums)."""
    _attrs(lambda a: a["step_max"].__setitem__(2, a["step_max"][2] * 0.5))(store)
    _attrs(lambda a: a.update(vmax=max(a["step_max"])))(store)
    assert_rejected(["verify", store], "step 2", [store])


def test_store_written_before_chunks_were_kept_still_opens(tmp_path):
    """Older stores left out chunks of only the fill value: those are not damage."""
    data = np.zeros((3, 4, 5, 6), np.float32)
    data[1] = 2.0
    path = tmp_path / "old.zarr"
    chronocl.TimeSeries.from_array(data).save(path)
    _attrs(lambda a: a.pop("chunks"))(path)
    shutil.rmtree(path / "data" / "c" / "0")  # step 0 is all zeros, as older stores left it
    series = chronocl.open(path)
    np.testing.assert_array_equal(series.read([0, 1, 2]), data)
    shutil.rmtree(path / "data" / "c" / "1")  # step 1 has data: its chunk is damage
    with pytest.raises(StoreCorruptError, match="step 1"):
        chronocl.open(path).read([1])


def test_damaged_chronovolume_is_reported(tmp_path):
    cv_path = tmp_path / "cv.zarr"
    series = chronocl.TimeSeries.from_array(np.random.default_rng(1).random((3, 4, 5, 6)))
    chronocl.integrate(series, None, "max").save(cv_path)
    chunk = next(
        p for p in (cv_path / "t_index").rglob("*") if p.is_file() and p.name != "zarr.json"
    )
    chunk.unlink()
    with pytest.raises(StoreCorruptError, match="t_index/c/"):
        chronocl.Chronovolume.load(cv_path)
    rgba = next(p for p in (cv_path / "rgba").rglob("*") if p.is_file() and p.name != "zarr.json")
    rgba.write_bytes(b"\x01" * 10)
    result_before = digest(cv_path)
    assert_rejected(["info", cv_path], "is damaged", [cv_path])
    assert digest(cv_path) == result_before


# -- ingest: every format --------------------------------------------------------------------


def _raw_steps(folder: Path, n: int = 3, dims=(4, 3, 2), dtype="float32") -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for t in range(n):
        np.full(dims[::-1], t, dtype=dtype).tofile(folder / f"v{t}.raw")


def _nan_step(folder: Path) -> None:
    _raw_steps(folder)
    np.full((2, 3, 4), np.nan, np.float32).tofile(folder / "v1.raw")


def _write(name: str, data: bytes):
    def make(folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)

    return make


def _npy(name: str, array) -> object:
    def make(folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        np.save(folder / name, array, allow_pickle=True)

    return make


def _tiffs(folder: Path) -> None:
    import tifffile

    folder.mkdir(parents=True, exist_ok=True)
    tifffile.imwrite(folder / "t0.tif", np.zeros((2, 5, 6), np.uint16))
    tifffile.imwrite(folder / "t1.tif", np.zeros((2, 5, 7), np.uint16))


def _netcdf(folder: Path) -> None:
    import h5py

    folder.mkdir(parents=True, exist_ok=True)
    with h5py.File(folder / "d.h5", "w") as f:
        f["temp"] = np.zeros((2, 3, 4, 5), np.float32)


RAW = ["--dims", "4", "3", "2"]
INGEST = {
    "raw: size does not match dims": (_raw_steps, ["{i}/*.raw", *RAW[:-1], "3"], "needs"),
    "raw: no --dims": (_raw_steps, ["{i}/*.raw"], "needs --dims"),
    "raw: unknown dtype": (_raw_steps, ["{i}/*.raw", *RAW, "--dtype", "int128"], "int128"),
    "raw: unknown endianness": (_raw_steps, ["{i}/*.raw", *RAW, "--endian", "middle"], "middle"),
    "raw: NaN without --nan-fill": (_nan_step, ["{i}/*.raw", *RAW], "--nan-fill"),
    "raw: --nan-fill nan": (_nan_step, ["{i}/*.raw", *RAW, "--nan-fill", "nan"], "finite"),
    "raw: --nan-fill inf": (_nan_step, ["{i}/*.raw", *RAW, "--nan-fill", "inf"], "finite"),
    "raw: empty file": (_write("v0.raw", b""), ["{i}/v0.raw", *RAW], "has 0 bytes"),
    "raw: folder as input": (_raw_steps, ["{i}", "--format", "raw", *RAW], "is a folder"),
    "raw: glob matches nothing": (_raw_steps, ["{i}/*.nothing", *RAW], "no files match"),
    "npy: not a .npy": (_write("d.npy", b"not numpy at all"), ["{i}/d.npy"], "not a readable"),
    "npy: 3-D": (_npy("d.npy", np.zeros((2, 3, 4))), ["{i}/d.npy"], "must be 4D"),
    "npy: complex": (_npy("d.npy", np.zeros((2, 2, 2, 2), complex)), ["{i}/d.npy"], "complex"),
    "npy: objects (pickle)": (
        _npy("d.npy", np.empty((2, 2, 2, 2), object)),
        ["{i}/d.npy"],
        "not a readable",
    ),
    "npy: zero steps": (_npy("d.npy", np.zeros((0, 2, 2, 2))), ["{i}/d.npy"], "zero time steps"),
    "netcdf: not a netcdf file": (_write("d.nc", b"CDF? no"), ["{i}/d.nc"], "d.nc"),
    "netcdf: unknown variable": (_netcdf, ["{i}/d.h5", "--var", "salt"], "salt"),
    "tiff: not a tiff": (_write("t0.tif", b"II*\x00broken"), ["{i}/t0.tif"], "t0.tif"),
    "tiff: stacks of different shapes": (_tiffs, ["{i}/t*.tif"], "shape"),
    "omezarr: folder that is not OME-Zarr": (
        lambda f: (f / "x.ome.zarr").mkdir(parents=True),
        ["{i}/x.ome.zarr", "--format", "omezarr"],
        "x.ome.zarr",
    ),
}


@pytest.mark.parametrize("case", INGEST)
def test_bad_ingest_input(tmp_path, case):
    make, args, needle = INGEST[case]
    inputs = tmp_path / "in"
    inputs.mkdir()
    make(inputs)
    out = tmp_path / "o.zarr"
    argv = ["ingest", *(a.format(i=inputs) for a in args), "-o", out]
    assert_rejected(argv, needle, [inputs], [out], tmp_path)


# -- the Python API --------------------------------------------------------------------------

API = {
    "from_array 2-D": (lambda: chronocl.TimeSeries.from_array(np.zeros((3, 4))), InvalidDataError),
    "from_array complex": (
        lambda: chronocl.TimeSeries.from_array(np.zeros((2, 2, 2, 2), complex)),
        InvalidDataError,
    ),
    "from_array object": (
        lambda: chronocl.TimeSeries.from_array(np.empty((2, 2, 2, 2), object)),
        InvalidDataError,
    ),
    "from_array ragged lists": (
        lambda: chronocl.TimeSeries.from_array([[[[1.0]]], [[[1.0, 2.0]]]]),
        InvalidDataError,
    ),
    "from_array NaN": (
        lambda: chronocl.TimeSeries.from_array(np.full((2, 2, 2, 2), np.nan)),
        InvalidDataError,
    ),
    "from_array zero steps": (
        lambda: chronocl.TimeSeries.from_array(np.zeros((0, 2, 2, 2))),
        InvalidDataError,
    ),
    "window beyond T": (
        lambda: chronocl.integrate(chronocl.TimeSeries.from_array(np.zeros((3, 2, 2, 2))), "0:9"),
        InvalidSelectionError,
    ),
    "write_series nan_fill=nan": (
        lambda: write_series(
            "/nonexistent/never.zarr",
            iter([np.zeros((1, 1, 1))]),
            n_steps=1,
            volume_shape=(1, 1, 1),
            dtype="float32",
            nan_fill=float("nan"),
        ),
        InvalidParameterError,
    ),
    "open a URL without a host": (lambda: chronocl.open("http://"), InvalidParameterError),
    "open an s3 URL without a bucket": (lambda: chronocl.open("s3://"), InvalidParameterError),
    "open a URL of another scheme": (
        lambda: chronocl.open("ftp://h/x.zarr"),
        InvalidParameterError,
    ),
    "open a URL with a bad port": (
        lambda: chronocl.open("http://h:x/s.zarr"),
        InvalidParameterError,
    ),
    "open a URL with an unclosed IPv6 bracket": (
        lambda: chronocl.open("http://[::1/x.zarr"),
        InvalidParameterError,
    ),
    "storage options for a local path": (
        lambda: chronocl.open("/nonexistent/x.zarr", storage_options={"anon": True}),
        InvalidParameterError,
    ),
}


@pytest.mark.parametrize("case", API)
def test_bad_api_input(case):
    call, kind = API[case]
    with pytest.raises(kind) as info:
        call()
    assert isinstance(info.value, ChronoclError) and isinstance(info.value, ValueError)
    assert "\n" not in str(info.value)


def test_damaged_store_through_the_api_is_a_value_error(store):
    _chunk(store).unlink()
    series = chronocl.open(store)
    with pytest.raises(ValueError, match="is missing"):
        series.read([3])
    with pytest.raises(StoreCorruptError):
        series.data[3].compute()  # dask reads are checked too
    np.testing.assert_array_equal(series.read([2]).shape, (1, *SHAPE))


def test_info_on_neither_a_series_nor_a_chronovolume_names_both_readings(tmp_path):
    import zarr

    group = tmp_path / "g.zarr"
    zarr.open_group(str(group), mode="w")
    assert_rejected(
        ["info", group],
        "is neither a series store nor a chronovolume: as a series, ",
        [group],
        folder=tmp_path,
    )


def test_repr_of_a_chronovolume_is_one_line():
    data = np.random.default_rng(0).random((12, 4, 5, 6)).astype(np.float32)
    series = chronocl.TimeSeries.from_array(data, source="demo")
    cv = chronocl.integrate(series, "0:12:3", "max", engine="numpy")
    assert repr(cv) == (
        "Chronovolume(6×5×4 (x, y, z), mode=max, steps 0:10:3 (4 of 12), from 'demo', with t_index)"
    )


@pytest.mark.parametrize(
    ("url", "needle"),
    [
        ("http://", "'http://' names no host"),
        ("s3://", "'s3://' names no bucket"),
        ("ftp://h/x.zarr", "cannot read a ftp:// store"),
        ("gs://b/x.zarr", "cannot read a gs:// store"),
        ("http://h:x/s.zarr", "is not a URL (Port could not be cast"),
    ],
)
def test_a_url_chronocl_cannot_read_is_one_line_from_the_cli(tmp_path, url, needle):
    """A store's URL is checked before anything is opened (`remote_store.check_url`): `info
    http://` died in a traceback (an AttributeError), `ftp://...` said the store did not exist
    as a local path."""
    from .bad_input import assert_rejected

    assert_rejected(["info", url], needle, inputs=[], folder=tmp_path)


def test_a_level_array_marked_in_another_byte_order_is_reported(tmp_path):
    """A level array's metadata edited to another byte order (its checksums still match: they
    cover the bytes, not their order) is reported, not read as other values."""
    path = tmp_path / "s.zarr"
    data = np.random.default_rng(0).random((3, 4, 5, 70), dtype=np.float32)
    chronocl.TimeSeries.from_array(data).save(path)
    meta = path / "levels" / "1" / "mean" / "zarr.json"
    _json(meta, lambda d: [c["configuration"].update(endian="big") for c in d["codecs"][:1]])
    with pytest.raises(StoreCorruptError, match="levels/1/mean is marked big-endian"):
        chronocl.open(path).level(1).read([0], 0, 2)


def test_a_chronovolume_marked_in_another_byte_order_is_reported(tmp_path):
    """A chronovolume's RGBA array marked big-endian in edited metadata is reported as
    damaged where it is opened, not loaded as other values (1e37 off)."""
    path = tmp_path / "cv.zarr"
    series = chronocl.TimeSeries.from_array(np.random.default_rng(1).random((3, 4, 5, 6)))
    chronocl.integrate(series, None, "max").save(path)
    _json(
        path / "rgba" / "zarr.json", lambda d: d["codecs"][0]["configuration"].update(endian="big")
    )
    with pytest.raises(StoreCorruptError, match="its array rgba is marked big-endian"):
        chronocl.Chronovolume.load(path)
