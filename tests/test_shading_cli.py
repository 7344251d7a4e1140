"""`chronocl render --shading`: the image and its turntable are lit; bad strengths are refused
before any work (in this process: how the entry point turns a refusal into one line and exit 2
is tests/test_cli.py's)."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from chronocl.cli.app import app
from chronocl.core.errors import InvalidParameterError


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def vortex(tmp_path_factory):
    path = tmp_path_factory.mktemp("shading") / "v.zarr"
    result = invoke("generate", "vortex", path, "--shape", "20x20x20", "--steps", "4")
    assert result.exit_code == 0, result.output
    return path


def test_shading_lights_the_image_and_the_turntable(tmp_path, vortex):
    import imageio.v3 as iio
    from PIL import Image as PILImage

    common = ["--window", "0:4:3", "--size", "48x48", "--engine", "numpy"]
    flat = invoke("render", vortex, "-o", tmp_path / "flat.png", *common)
    lit = invoke(
        "render",
        vortex,
        "-o",
        tmp_path / "lit.png",
        *common,
        "--shading-params",
        "0.2,0.8,0.6,30",
        "--turntable",
        tmp_path / "lit.gif",
        "--frames",
        "2",
    )
    assert flat.exit_code == 0 and lit.exit_code == 0, flat.output + lit.output
    a, b = (
        np.asarray(PILImage.open(tmp_path / f"{n}.png").convert("RGB"))[:48].astype(int)
        for n in ("flat", "lit")
    )
    assert np.abs(a - b).max() > 40  # lighting changed the panel
    frame = iio.imread(tmp_path / "lit.gif", index=0)[:48, :, :3].astype(int)
    assert np.abs(frame - b).mean() < np.abs(frame - a).mean()  # the turntable is lit too


@pytest.mark.parametrize(
    ("params", "needle"),
    [
        ("0.3,0.7", "must be ambient,diffuse,specular[,shininess], e.g. 0.3,0.7,0.3"),
        ("0.3,0.7,9", "specular is 9.0; use a number from 0 to 2"),
        ("0.3,0.7,0.3,0", "shininess is 0.0; use 1 to 256"),
    ],
)
def test_bad_shading_options(tmp_path, vortex, params, needle):
    result = invoke("render", vortex, "-o", tmp_path / "o.png", "--shading-params", params)
    assert isinstance(result.exception, InvalidParameterError), result.output
    assert needle in str(result.exception) and "\n" not in str(result.exception)
    assert not list(tmp_path.iterdir())  # refused before any work: nothing written
