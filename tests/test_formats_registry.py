"""The format registry: every reader takes the options it declares; outputs and exports by name."""

from __future__ import annotations

import inspect

import pytest

from chronocl.data.formats.contract import COMMON_OPTIONS
from chronocl.data.formats.registry import EXPORTERS, OUTPUTS, READERS, output_for, recognise
from chronocl.data.ingest import FORMATS


def test_the_readers_exporters_and_outputs_are_listed_in_message_order():
    assert FORMATS == ("auto", "raw", "npy", "netcdf", "tiff", "omezarr")
    assert tuple(EXPORTERS) == ("vti", "npy", "raw")
    assert [o.suffix for o in OUTPUTS] == [".zarr", ".ome.zarr", ".vti"]


@pytest.mark.parametrize("name", READERS)
def test_every_reader_takes_the_options_it_declares(name):
    reader = READERS[name]
    params = inspect.signature(reader.read).parameters
    assert set(reader.common) <= set(COMMON_OPTIONS)
    for key, unset in {**reader.options, **dict.fromkeys(reader.common)}.items():
        assert key in params, f"{name} reader does not take {key}"
        if key in reader.options:
            assert params[key].default == unset, f"{name}: {key} defaults to another value"


def test_the_longest_suffix_decides_the_output(tmp_path):
    assert output_for(tmp_path / "a.ome.zarr").suffix == ".ome.zarr"
    assert output_for(str(tmp_path / "A.ZARR") + "/").suffix == ".zarr"
    assert output_for(tmp_path / "a.vti").suffix == ".vti"
    assert output_for(tmp_path / "a.png") is None


def test_files_are_recognised_by_suffix_and_raw_takes_the_rest(tmp_path):
    names = {"a.npy": "npy", "a.nc": "netcdf", "a.H5": "netcdf", "a.ome.tif": "tiff"}
    for file, reader in {**names, "a.raw": "raw", "a.bin": "raw"}.items():
        assert recognise(tmp_path / file).name == reader
    (tmp_path / "folder.npy").mkdir()
    assert recognise(tmp_path / "folder.npy") is None  # a folder but no OME-Zarr image
