"""Pictures that cannot show what was selected say so: a step whose values all fall where the
transfer functions are transparent, or a chronovolume with nothing opaque, gets one warning
naming the steps and the option that fixes it (a plume whose early steps are faint)."""

from __future__ import annotations

import sys
import warnings

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import ChronoclWarning
from chronocl.data import synthetic


@pytest.fixture(scope="module")
def plume():
    """A plume growing from faint to strong: step 0 peaks at 13 % of the series' maximum."""
    data = np.stack(list(synthetic.steps("jet", 12, (24, 24, 32), 0))).astype(np.float32)
    scale = np.linspace(0.13, 1.0, 12, dtype=np.float32)[:, None, None, None]
    return chronocl.TimeSeries.from_array(data * scale / data.max(), source="plume")


# The data TF that was the default until it was fitted to the window: transparent below 35 %
# of the series' range (a TF drawn by hand is read against the series' range).
HIDES_LOW = chronocl.DataTF(
    points=[(0, 1, 1, 1, 0), (0.35, 1, 1, 1, 0), (0.6, 1, 1, 1, 0.5), (1, 1, 1, 1, 0.9)]
)


def _warned(fn) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn()
    return [str(w.message) for w in caught if issubclass(w.category, ChronoclWarning)]


@pytest.mark.parametrize("mode", ["alpha", "additive", "max", "first_hit", "mean"])
def test_faint_early_steps_are_named_in_one_warning(plume, mode):
    got = _warned(
        lambda: chronocl.integrate(plume, "0:10", mode, engine="numpy", data_tf=HIDES_LOW)
    )
    assert len(got) == 1, got
    assert got[0].startswith("steps 0, 1, 2 (3 of the 10 selected) are invisible")
    assert "(0.00 .. 0.28 of the value range) lie where the data TF's opacity is under" in got[0]
    assert "--tf FILE with a data_tf" in got[0]
    # Each named step really is transparent; the next is not.
    stats = plume.stats
    top = [(stats.step_max[s] - plume.vmin) / (plume.vmax - plume.vmin) for s in range(4)]
    assert max(top[:3]) < 0.35 <= top[3]


def test_the_defaults_show_the_faint_steps(plume):
    for mode in ("alpha", "additive", "max", "first_hit", "mean", "min"):
        assert _warned(lambda m=mode: chronocl.integrate(plume, "0:10", m, engine="numpy")) == []


def test_visible_windows_and_opaque_tfs_are_quiet(plume):
    late = _warned(
        lambda: chronocl.integrate(plume, "5:12", "alpha", engine="numpy", data_tf=HIDES_LOW)
    )
    assert late == []
    opaque = chronocl.DataTF(points=[(0, 1, 1, 1, 0.4), (1, 1, 1, 1, 0.9)])
    every = _warned(lambda: chronocl.integrate(plume, "0:10", data_tf=opaque, engine="numpy"))
    assert every == []
    # count and change colour a derived quantity, not each step's values
    for mode in ("count", "change"):
        assert not any(
            "invisible" in m
            for m in _warned(lambda m=mode: chronocl.integrate(plume, "0:10", m, engine="numpy"))
        )


def test_an_enhanced_picture_and_a_tf_opaque_only_low_are_judged_right(plume):
    """Edge enhancement can raise faint voxels above the TF's opacity: no step is condemned on
    the TF alone then. A TF opaque only at low values hides the high steps, said so."""
    edge = _warned(lambda: chronocl.integrate(plume, "0:10", enhance="edge", engine="numpy"))
    assert not any("invisible" in m for m in edge), edge
    low = chronocl.DataTF(points=[(0, 1, 1, 1, 0.8), (0.2, 1, 1, 1, 0.8), (0.25, 1, 1, 1, 0)])
    got = _warned(lambda: chronocl.integrate(plume, "0:12", data_tf=low, engine="numpy"))
    assert got == [] or all("lie where the data TF's opacity is under" in m for m in got), got


def test_a_chronovolume_with_nothing_opaque_says_so(plume):
    got = _warned(
        lambda: chronocl.integrate(plume, "0:12", "min", engine="numpy", data_tf=HIDES_LOW)
    )
    assert len(got) == 1 and got[0].startswith("the min chronovolume shows nothing"), got
    assert "opaque where the min values lie" in got[0]


def test_the_cli_prints_one_warning_line_and_renders(plume, tmp_path, monkeypatch, capsys):
    from chronocl.cli import main

    store = tmp_path / "plume.zarr"
    plume.save(store)
    tf = tmp_path / "tf.json"
    chronocl.TFSetting(data_tf=HIDES_LOW).save(tf)
    out = tmp_path / "p.png"
    argv = ["chronocl", "render", str(store), "-o", str(out), "--window", "0:10", "--tf", str(tf)]
    monkeypatch.setattr(sys, "argv", [*argv, "--engine", "numpy", "--size", "96x64"])
    with pytest.raises(SystemExit) as info:
        main()
    assert (info.value.code or 0) == 0 and out.exists()
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "warning" in ln]
    assert len(lines) == 1 and lines[0].startswith("chronocl: warning: steps 0, 1, 2"), lines
