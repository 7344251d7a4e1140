"""Vector magnitudes (`ingest --magnitude`) and stores of several variables (`--variables`,
`chronocl.open(...).variable(name)`, `chronocl render --variables`)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import StoreCorruptError, UnknownNameError
from chronocl.data.ingest import ingest
from chronocl.data.verify import verify

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

T, Z, Y, X = 3, 4, 5, 72  # X > 64: the stores get one coarse level


def components(dtype=np.float32) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(18)
    return {n: (rng.standard_normal((T, Z, Y, X)) * 10).astype(dtype) for n in "uvw"}


def netcdf(path, arrays: dict[str, np.ndarray]):
    coords = {"time": np.arange(T) * 0.5, "z": np.arange(Z) * 2.0, "y": np.arange(Y) * 1.0}
    coords["x"] = np.arange(X) * 0.25
    dims = ("time", "z", "y", "x")
    xr.Dataset({n: (dims, a) for n, a in arrays.items()}, coords=coords).to_netcdf(
        path, engine="h5netcdf"
    )
    return path


def run_cli(monkeypatch, capsys, *args) -> tuple[int, str]:
    """`chronocl ARGS` in this process: (exit code, stderr)."""
    from chronocl.cli import main

    monkeypatch.setattr(sys, "argv", ["chronocl", *map(str, args)])
    with pytest.raises(SystemExit) as info:
        main()
    return info.value.code or 0, capsys.readouterr().err


def one_line_error(code: int, err: str, needle: str) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("chronocl: error:") and needle in lines[0], lines[0]


def expected_magnitude(c: dict[str, np.ndarray]) -> np.ndarray:
    u, v, w = (c[n].astype(np.float32) for n in "uvw")
    return np.sqrt(u * u + v * v + w * w)


def test_netcdf_magnitude_equals_numpy(tmp_path):
    c = components()
    c["w"] = (c["w"] * 100).astype(np.int16)  # components of any numeric type
    src = netcdf(tmp_path / "flow.nc", c)
    series = ingest([src], tmp_path / "m.zarr", magnitude="u,v,w")
    np.testing.assert_allclose(series.read(range(T)), expected_magnitude(c), rtol=1e-6)
    assert series.dtype == np.float32 and series.spacing == (0.25, 1.0, 2.0)
    assert series.meta["quantity"] == "magnitude" and series.meta["components"] == ["u", "v", "w"]
    reopened = chronocl.open(tmp_path / "m.zarr")
    assert reopened.meta == series.meta and reopened.n_levels == 2
    assert reopened.describe()["components"] == ["u", "v", "w"]


def test_raw_and_npy_magnitude_equal_numpy(tmp_path, monkeypatch, capsys):
    c = components()
    for name, a in c.items():
        np.save(tmp_path / f"{name}.npy", a)
        for t in range(T):
            a[t].tofile(tmp_path / f"{name}_{t}.raw")
    series = ingest(
        [], tmp_path / "n.zarr", magnitude=",".join(str(tmp_path / f"{n}.npy") for n in "uvw")
    )
    np.testing.assert_allclose(series.read(range(T)), expected_magnitude(c), rtol=1e-6)
    globs = ",".join(str(tmp_path / f"{n}_*.raw") for n in "uvw")
    code, err = run_cli(
        monkeypatch, capsys, "ingest", "-o", tmp_path / "r.zarr", "--magnitude", globs,
        "--dims", X, Y, Z,
    )  # fmt: skip
    assert code == 0, err
    raw = chronocl.open(tmp_path / "r.zarr")
    np.testing.assert_allclose(raw.read(range(T)), expected_magnitude(c), rtol=1e-6)
    assert raw.meta["quantity"] == "magnitude" and raw.n_levels == 2


def test_magnitude_refusals_write_nothing(tmp_path, monkeypatch, capsys):
    c = components()
    src = netcdf(tmp_path / "flow.nc", c)
    np.save(tmp_path / "u.npy", c["u"])
    np.save(tmp_path / "v.npy", c["v"][:, :, :, :10])
    out = tmp_path / "m.zarr"
    cases = [
        ((src, "--magnitude", "u,v,speed"), "no variable 'speed'"),
        ((src, "--magnitude", "u"), "takes 2 or 3"),
        ((src, "--magnitude", "u,v", "--var", "u"), "exclude each other"),
        (("--magnitude", f"{tmp_path / 'u.npy'},{tmp_path / 'v.npy'}"), "differ in volume shape"),
        ((tmp_path / "u.npy", "--magnitude", "u,v"), "names the component inputs"),
    ]
    for args, needle in cases:
        one_line_error(*run_cli(monkeypatch, capsys, "ingest", "-o", out, *args), needle)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flow.nc", "u.npy", "v.npy"]


def test_variables_in_one_store(tmp_path, monkeypatch, capsys):
    c = components()
    src = netcdf(tmp_path / "flow.nc", c)
    store = tmp_path / "uvw.zarr"
    code, err = run_cli(monkeypatch, capsys, "ingest", src, "-o", store, "--variables", "w,u")
    assert code == 0 and "variables: w, u" in err, err
    first = chronocl.open(store)  # the first variable, as a one-variable store would be
    assert first.variables == ("w", "u") and first.meta["variable"] == "w"
    assert "this is w" in first.describe()["variables"]
    np.testing.assert_array_equal(first.read(range(T)), c["w"])
    u = first.variable("u")
    np.testing.assert_array_equal(u.read(range(T)), c["u"])
    assert (u.vmin, u.vmax) == (c["u"].min(), c["u"].max()) != (first.vmin, first.vmax)
    assert u.n_levels == 2 and u.level(1).shape == (T, 2, 3, 36)
    assert u.variables == ("w", "u") and u.variable("w").path == store
    assert chronocl.open(store, variable="u").path == u.path
    with pytest.raises(UnknownNameError, match=r"uvw\.zarr.* has no variable .v.; it holds w, u"):
        first.variable("v")
    with pytest.raises(UnknownNameError, match=r"uvw\.zarr'"):  # named by the store, not by u
        u.variable("v")
    assert verify(store)["variables checked"] == "w, u"  # every variable read back
    next(p for p in (store / "variables" / "u" / "data" / "c").rglob("*") if p.is_file()).unlink()
    with pytest.raises(StoreCorruptError, match="variables/u"):
        verify(store)
    one = ingest([src], tmp_path / "v.zarr", var="v")  # one variable: as before, named
    assert one.variables == ("v",) and one.variable("v") is one and "variables" not in one.meta


def test_render_variables_side_by_side(tmp_path, monkeypatch, capsys):
    from PIL import Image

    c = components()
    store = ingest([netcdf(tmp_path / "f.nc", c)], tmp_path / "s.zarr", variables="u,v").path
    png = tmp_path / "uv.png"
    args = ("render", store, "-o", png, "--variables", "u,v", "--engine", "numpy")
    code, err = run_cli(monkeypatch, capsys, *args, "--size", "64x48", "--window", "0:3")
    assert code == 0, err
    assert Image.open(png).size[0] == 2 * 64  # one panel per variable, side by side
    code, err = run_cli(monkeypatch, capsys, *args, "--variables", "q", "-o", tmp_path / "q.png")
    one_line_error(code, err, "no variable 'q'")
    assert not (tmp_path / "q.png").exists()
