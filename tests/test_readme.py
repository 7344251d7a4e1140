"""The README's "Your own data in five commands", run as a reader would run it.

The section between `<!-- five-commands -->` and `<!-- /five-commands -->` is read in order:
its Python block is executed in a fresh folder (it writes a raw series and the meta.json a
simulation would write), every line of its `sh` blocks is run through the command line there
(`python -m chronocl`, split as a shell splits it, so a quoted glob reaches chronocl whole),
each must exit 0, and what each wrote is checked: the store holds exactly the simulated
steps, with the spacing and times of meta.json; a PNG opens and is not black; an exported
.pvd lists .vti files that VTK reads back as the store's steps. A `text` block after a command
is what the command prints: every line shown must be printed (timings and sizes on disk
aside). A picture `docs/readme/NAME.png` after a command is what its output NAME made (the
PNG itself, or for an exported folder the middle z slice of each step as VTK reads it): it
must have the size shown and differ from it by little (the README's copies are reduced to
256 colours; other drivers draw slightly differently).

`CHRONOCL_WRITE_README_PICTURES=1 pytest -s tests/test_readme.py` writes the pictures into
docs/readme/ instead of comparing them, and prints what each command printed.
"""

from __future__ import annotations

import os
import re
import shlex
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from PIL import Image

import chronocl
from chronocl.data.run_meta import read_run_meta

from . import cli_process
from .test_export_vti import read_vti

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PICTURES = ROOT / "docs" / "readme"
WRITE = os.environ.get("CHRONOCL_WRITE_README_PICTURES") == "1"
START, END = "<!-- five-commands -->", "<!-- /five-commands -->"
# a fenced block, or a picture: in the order they come
ITEM = re.compile(r"^```(\w+)\n(.*?)^```$|!\[[^\]]*\]\(([^)\s]+)\)", re.S | re.M)
# what changes from run to run in what a command prints
VOLATILE = [
    (re.compile(r" in [0-9.]+ s$"), " in N s"),
    (re.compile(r"^(size on disk\s+).*$"), r"\1N"),
]
MAX_MEAN_DIFFERENCE = 6.0  # of 255, per channel: 256 colours and another driver's rounding


def section() -> str:
    text = README.read_text()
    assert text.count(START) == 1 and text.count(END) == 1, f"README.md needs {START} .. {END}"
    return text[text.index(START) + len(START) : text.index(END)]


def items(text: str) -> list[tuple[str, str]]:
    """(kind, body) in the order they come: ('python'|'sh'|'text'|..., code) or ('image', link)."""
    found = []
    for m in ITEM.finditer(text):
        found.append(("image", m.group(3)) if m.group(3) else (m.group(1), m.group(2)))
    return found


def commands(body: str) -> list[list[str]]:
    """The commands of an sh block, one a line, split as a shell splits them."""
    lines = [shlex.split(line, comments=True) for line in body.splitlines()]
    return [argv for argv in lines if argv]


def option(argv: list[str], *names: str) -> str:
    for i, arg in enumerate(argv):
        if arg in names:
            return argv[i + 1]
        for name in names:
            if name.startswith("--") and arg.startswith(name + "="):
                return arg.split("=", 1)[1]
    raise AssertionError(f"no {'/'.join(names)} in {shlex.join(argv)}")


def normalised(line: str) -> str:
    line = line.rstrip()
    for pattern, replacement in VOLATILE:
        line = pattern.sub(replacement, line)
    return line


def slices_picture(folder: Path) -> Image.Image:
    """The middle z slice of every step of an exported .pvd, as VTK reads the .vti files."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    pvd = folder / f"{folder.name}.pvd"
    datasets = ET.parse(pvd).getroot().find("Collection").findall("DataSet")
    steps = [(d.get("timestep"), read_vti(folder / d.get("file"))[1]["value"]) for d in datasets]
    top = max(float(values.max()) for _, values in steps)
    fig = Figure(figsize=(1.3 * len(steps), 1.75), dpi=100)
    FigureCanvasAgg(fig)
    for i, (time, values) in enumerate(steps):
        ax = fig.add_subplot(1, len(steps), i + 1)
        ax.imshow(values[values.shape[0] // 2], origin="lower", cmap="viridis", vmin=0, vmax=top)
        ax.set_title(f"t = {time}", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{pvd.name}: the middle z slice of each .vti (x right, y up)", fontsize=9)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.02, top=0.72, wspace=0.06)
    fig.canvas.draw()
    return Image.fromarray(np.asarray(fig.canvas.buffer_rgba())).convert("RGB")


def picture_of(out: Path) -> Image.Image:
    if out.is_dir():
        return slices_picture(out)
    with Image.open(out) as image:
        return image.convert("RGB")


def check_picture(image: Image.Image, shown: Path) -> None:
    """Not black, and what the README shows (or, writing, the README's copy written)."""
    rgb = np.asarray(image, dtype=np.float64)
    assert (rgb.max(axis=2) > 40).mean() > 0.05, f"{shown.name}: nearly black"
    if WRITE:
        PICTURES.mkdir(parents=True, exist_ok=True)
        small = image.quantize(256, dither=Image.Dither.NONE)
        small.save(shown, optimize=True)
        return
    assert shown.exists(), f"README shows {shown}, which is missing"
    with Image.open(shown) as readme_picture:
        expected = np.asarray(readme_picture.convert("RGB"), dtype=np.float64)
    assert expected.shape == rgb.shape, (
        f"{shown.name}: the command made {rgb.shape[1]}x{rgb.shape[0]}, the README shows "
        f"{expected.shape[1]}x{expected.shape[0]}; if that change is meant, write the pictures "
        "again: CHRONOCL_WRITE_README_PICTURES=1 pytest -s tests/test_readme.py"
    )
    difference = np.abs(rgb - expected).mean()
    assert difference <= MAX_MEAN_DIFFERENCE, (
        f"{shown.name}: what the command made differs from the README's picture by "
        f"{difference:.1f}/255 on average; if that change is meant, write the pictures again: "
        "CHRONOCL_WRITE_README_PICTURES=1 pytest -s tests/test_readme.py"
    )


def check_output(argv: list[str], cwd: Path, namespace: dict) -> Path | None:
    """What the command wrote (its -o) is whole and holds what it should; that path."""
    if argv[1] in ("info", "verify", "devices"):
        return None
    out = cwd / option(argv, "-o", "--out")
    assert out.exists(), f"{shlex.join(argv)} wrote no {out.name}"
    if out.suffix == ".zarr" and argv[1] == "ingest":
        series = chronocl.open(str(out))
        run = namespace["run"]  # the README's simulated steps (T, Z, Y, X)
        assert series.shape == run.shape
        np.testing.assert_array_equal(series.read(range(run.shape[0])), run)
        meta = read_run_meta(cwd / option(argv, "--meta"))  # what --meta should have taken
        assert series.dims == meta.dims and series.spacing == meta.spacing
        assert len(series.times) == run.shape[0] and series.time_unit == meta.times.unit
    elif out.suffix == ".png":
        with Image.open(out) as image:
            image.verify()
    elif out.is_dir() and (out / f"{out.name}.pvd").exists():
        store = cwd / argv[2]
        series = chronocl.open(str(store))
        root = ET.parse(out / f"{out.name}.pvd").getroot()
        files = [d.get("file") for d in root.find("Collection").findall("DataSet")]
        assert files, f"{out.name}.pvd lists no steps"
        for name in files:
            step = int(re.search(r"_t(\d+)\.vti$", name).group(1))
            values = read_vti(out / name)[1]["value"]
            np.testing.assert_array_equal(values, series.read([step])[0])
    return out


def test_readme_five_commands(tmp_path, monkeypatch):
    found = items(section())
    kinds = [kind for kind, _ in found]
    assert "python" in kinds and "sh" in kinds, "the five commands section lost its blocks"
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "readme"}
    ran: list[list[str]] = []
    printed = ""
    out: Path | None = None
    for kind, body in found:
        if kind == "python":
            exec(compile(body, str(README), "exec"), namespace)
        elif kind == "sh":
            for argv in commands(body):
                assert argv[0] == "chronocl", f"not a chronocl command: {shlex.join(argv)}"
                result = cli_process.run(argv[1:], cwd=tmp_path, timeout=300)
                assert result.returncode == 0, f"{shlex.join(argv)}\n{result.stderr}"
                printed = result.stdout + result.stderr
                if WRITE:
                    print(f"$ {shlex.join(argv)}\n{printed}")
                out = check_output(argv, tmp_path, namespace)
                ran.append(argv)
        elif kind == "text":
            assert ran, "a text block before any command"
            lines = {normalised(line) for line in printed.splitlines()}
            missing = [ln for ln in body.splitlines() if ln.strip() and normalised(ln) not in lines]
            assert not missing, f"{shlex.join(ran[-1])} no longer prints {missing}:\n{printed}"
        elif kind == "image":
            shown = (ROOT / body).resolve()
            assert shown.parent == PICTURES, f"README pictures live in docs/readme/: {body}"
            assert out is not None, f"{body} follows no command that wrote something"
            assert shown.stem == out.stem, f"{body} should be named after {out.name}"
            check_picture(picture_of(out), shown)
    assert [argv[1] for argv in ran] == ["ingest", "info", "render", "probe", "export"]
    assert "--meta" in ran[0]
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")], "partials left"


def test_readme_pictures_are_small():
    """The README's pictures load fast: each under 150 KB, together under 1 MB."""
    sizes = {p.name: p.stat().st_size for p in PICTURES.glob("*.png")}
    assert sizes, "no pictures in docs/readme/"
    assert all(size < 150_000 for size in sizes.values()), sizes
    assert sum(sizes.values()) < 1_000_000, sizes
    linked = set(re.findall(r"\(docs/readme/([^)\s]+\.png)\)", README.read_text()))
    assert linked == set(sizes), f"README links {sorted(linked)}, docs/readme/ has {sorted(sizes)}"
