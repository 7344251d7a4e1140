"""A corpus of bad command lines: each is refused before any work, in one line, exit 2.

Every case runs the real CLI (`python -m chronocl ...`) in its own folder and checks: exit
code 2, exactly one line on stderr that starts with ``chronocl: error:`` and holds the
case's needle (the problem and its fix), no traceback, the case's folder byte-for-byte as
before (no output, no hidden ``.NAME.partial*``, no probe file), and the input store's every
file unchanged. Cases that could touch the store (outputs onto, inside or around it) work on
their own copy.

Start-up costs about 2 s of CPU per `python -m chronocl` (chronocl imports zarr, dask and
xarray), too slow for a hundred cases on two cores. So the cases run through the tests' CLI
server (tests/cli_process.py), which imports chronocl once and forks one child per case: the
real CLI in the case's folder with its own argv, stdout and stderr. Each case's assertions
are still its own test. CHRONOCL_CLI_SUBPROCESS=1 runs every case as its own
`python -m chronocl` instead; the cases that must succeed (paths with spaces and non-ASCII
characters) always do.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import chronocl

from . import cli_process

ROOT = Path(__file__).resolve().parents[1]


def _read_only_folder() -> str | None:
    """A folder that refuses new files even for root (sysfs), or None where there is none."""
    for folder in ("/sys/kernel", "/sys"):
        if not os.path.isdir(folder):
            continue
        try:
            fd, probe = tempfile.mkstemp(dir=folder)
        except OSError:
            return folder
        os.close(fd)
        os.unlink(probe)
    return None


READ_ONLY = _read_only_folder()


@dataclass(frozen=True)
class Case:
    """argv templates: {s} the input store, {d} the case's folder, {ro} a read-only folder."""

    id: str
    args: tuple[str, ...]
    needle: str = ""  # the error line must hold it; "" for a case that must succeed
    setup: Callable[[Path, Path], None] | None = None  # (case folder, store)
    own_store: bool = False  # {s} is a copy of the store inside the case's folder
    read_only: bool = False  # needs READ_ONLY
    creates: str = ""  # a positive case: this path (a template) must exist afterwards

    @property
    def ok(self) -> bool:
        return not self.needle


def write(name: str, text: str) -> Callable[[Path, Path], None]:
    def setup(d: Path, s: Path) -> None:
        (d / name).write_text(text)

    return setup


def tf(case_id: str, content: str | dict, needle: str) -> Case:
    """integrate with --tf holding `content` (a dict is written as JSON)."""
    text = content if isinstance(content, str) else json.dumps(content)
    return Case(
        f"tf-{case_id}",
        ("integrate", "{s}", "{d}/o.zarr", "--tf", "{d}/tf.json"),
        needle,
        write("tf.json", text),
    )


def integrate(case_id: str, args: tuple[str, ...], needle: str, **kw) -> Case:
    return Case(case_id, ("integrate", "{s}", "{d}/o.zarr", *args), needle, **kw)


def render(case_id: str, args: tuple[str, ...], needle: str, **kw) -> Case:
    return Case(case_id, ("render", "{s}", "-o", "{d}/o.png", *args), needle, **kw)


def export(case_id: str, args: tuple[str, ...], needle: str, **kw) -> Case:
    return Case(case_id, ("export", "{s}", "-o", "{d}/out", *args), needle, **kw)


def symlink_loop(name: str) -> Callable[[Path, Path], None]:
    def setup(d: Path, s: Path) -> None:
        (d / f"{name}-a").symlink_to(d / f"{name}-b")
        (d / f"{name}-b").symlink_to(d / f"{name}-a")

    return setup


def mkdir(name: str) -> Callable[[Path, Path], None]:
    def setup(d: Path, s: Path) -> None:
        (d / name).mkdir(parents=True)

    return setup


def raw_steps(folder: str) -> Callable[[Path, Path], None]:
    """Two 2x2x2 uint8 raw steps in `folder`."""

    def setup(d: Path, s: Path) -> None:
        (d / folder).mkdir(parents=True, exist_ok=True)
        for t in range(2):
            np.full(8, t, np.uint8).tofile(d / folder / f"v{t}.raw")

    return setup


def smooth_raw(folder: str) -> Callable[[Path, Path], None]:
    """Two float32 little-endian raw steps of a Gray-Scott front (NX NY NZ = 28 24 20)."""

    def setup(d: Path, s: Path) -> None:
        from chronocl.data.simulations import simulate

        (d / folder).mkdir(parents=True, exist_ok=True)
        for t, step in enumerate(simulate("gray-scott", (20, 24, 28), 4)[-2:]):
            step.astype("<f4").tofile(d / folder / f"v{t}.raw")

    return setup


def link_to_store(name: str) -> Callable[[Path, Path], None]:
    def setup(d: Path, s: Path) -> None:
        (d / name).symlink_to(s)

    return setup


def nested_store(d: Path, s: Path) -> None:
    """outer.zarr/S.zarr: a folder named like an output that holds the input store."""
    (d / "outer.zarr").mkdir()
    shutil.copytree(s, d / "outer.zarr" / "S.zarr")


ING = ("--dims", "2", "2", "2", "--dtype", "uint8")


def ingest_around(name: str, flag: str, file: str, text: str, key: str = "") -> Case:
    """ingest -o runA --overwrite, `flag` naming runA/`file` (holding `text`; `key`: a JSON
    key after it): the output would replace the folder holding a file it reads."""
    return Case(
        f"ingest-around-its-{name}",
        (
            "ingest",
            "{d}/raw/v*.raw",
            "-o",
            "{d}/runA",
            "--overwrite",
            *ING,
            flag,
            f"{{d}}/runA/{file}{key}",
        ),
        "contains the input",
        lambda d, s: (
            raw_steps("raw")(d, s),
            mkdir("runA")(d, s),
            write(f"runA/{file}", text)(d, s),
        ),
    )


def edited_events(edit: Callable[[dict], None]) -> Callable[[Path, Path], None]:
    """events.json: the store's events at threshold 0.5, a record then edited by `edit`."""

    def setup(d: Path, s: Path) -> None:
        found = chronocl.events(str(s), threshold=0.5).to_dict()
        edit(found)
        (d / "events.json").write_text(json.dumps(found))

    return setup


def state_and_tf(d: Path, s: Path) -> None:
    """s.json: a viewer's saved state of the store; t.json: a TF file."""
    from chronocl.data.series import open_series
    from chronocl.viewer.snapshot import snapshot_of
    from chronocl.viewer.view_state import default_state

    series = open_series(s)
    state = snapshot_of(default_state(0, series), "S", series, str(s))
    (d / "s.json").write_text(json.dumps(state))
    (d / "t.json").write_text(json.dumps({"points": [[0, 1, 1, 1, 0], [1, 1, 1, 1, 1]]}))


TRACKS = ("render", "{s}", "-o", "{d}/o.png", "--mode", "max", "--colour", "track")

CASES = [
    # ---------------------------------------------------------------- windows
    integrate("window-past-end", ("--window", "0:9"), "outside the series"),
    integrate("window-stride-0", ("--window", "0:5:0"), "stride must be at least 1"),
    integrate("window-empty", ("--window", ""), "cannot read time window"),
    integrate("window-empty-list", ("--window", ","), "cannot read time window"),
    integrate("window-repeats", ("--window", "1,1,3"), "without repeats"),
    integrate("window-negative", ("--window", "-1:3"), "outside the series"),
    integrate("window-step-past-end", ("--window", "1,7"), "outside [0, 5)"),
    integrate("window-garbage", ("--window", "a:b"), "cannot read time window"),
    integrate("window-same-ends", ("--window", "3:3"), "is empty: it ends where it starts"),
    integrate("window-reversed", ("--window", "4:2"), "is reversed: write 2:4"),
    integrate("window-of-times", ("--window", "1.0:3.0"), "write --window 1:3"),
    integrate("window-of-no-times", ("--window", "7.5:9.5"), "no step's time lies in"),
    render("render-window-past-end", ("--window", "2:99"), "outside the series"),
    # ---------------------------------------------------------------- modes and orders
    integrate("mode-unknown", ("--mode", "sum"), "unknown mode 'sum'; choose one of"),
    render("render-mode-unknown", ("--mode", "alpha,sum"), "unknown mode 'sum'"),
    render("render-mode-empty", ("--mode", ","), "names no mode"),
    render("render-mode-twice", ("--mode", "max,max"), "given twice"),
    integrate("order-unknown", ("--order", "sideways"), "unknown order"),
    integrate("order-not-permutation", ("--order", "0,1"), "must be a permutation"),
    integrate("order-repeats", ("--order", "0,0,1,2,3"), "must be a permutation"),
    integrate(
        "order-outside-window", ("--window", "0:3", "--order", "2,1,4"), "must be a permutation"
    ),
    integrate("enhance-unknown", ("--enhance", "glow"), "unknown enhancement 'glow'"),
    integrate("normalize-unknown", ("--normalize", "sum"), "unknown additive normalisation"),
    integrate("value-range-word", ("--value-range", "wide"), "is not window, series or LO,HI"),
    integrate("value-range-reversed-flag", ("--value-range", "2,1"), "LO < HI"),
    integrate("value-range-one-number", ("--value-range", "0,"), "2 comma-separated numbers"),
    render("render-value-range-nan", ("--value-range", "nan,1"), "two finite numbers"),
    integrate("value-range-float32-same", ("--value-range", "1,1.00000001"), "distinct in float32"),
    integrate("engine-unknown", ("--engine", "cuda"), "unknown engine 'cuda'"),
    integrate("threshold-out-of-range", ("--threshold", "1.5"), "must lie in [0, 1)"),
    integrate("time-tf-unknown", ("--time-tf", "rainbow"), "unknown time TF preset"),
    integrate("workers-zero", ("--workers", "0"), "at least 1 worker"),
    integrate("scheduler-malformed", ("--scheduler", "foo"), "write it like tcp://host:8786"),
    integrate(
        "scheduler-and-workers",
        ("--scheduler", "tcp://localhost:8786", "--workers", "2"),
        "not both",
    ),
    # ---------------------------------------------------------------- transfer-function JSON
    tf("value-range-string", {"data_tf": {"value_range": "01"}}, "value_range must be a list"),
    tf("value-range-number", {"data_tf": {"value_range": 5}}, "value_range must be a list"),
    tf("value-range-reversed", {"data_tf": {"value_range": [2, 1]}}, "min < max"),
    tf("value-range-huge", {"data_tf": {"value_range": [0, 1e300]}}, "outside float32"),
    tf(
        "width-string",
        {"time_tf": {"alpha": {"shape": "hat", "width": "0.5"}}},
        "width must be a number",
    ),
    tf(
        "falloff-null",
        {"time_tf": {"color": {"preset": "luminance", "falloff": None}}},
        "falloff must be a number, got null",
    ),
    tf("point-string", {"data_tf": {"points": [[0, 1, 1, 1, "0"], [1, 1, 1, 1, 1]]}}, "number"),
    tf("point-outside", {"data_tf": {"points": [[0, 1, 1, 1, 0], [1, 1, 1, 2, 1]]}}, "[0, 1]"),
    tf("size-float", {"data_tf": {"size": 256.5}}, "size must be an integer"),
    tf("nan", '{"data_tf": {"points": [[0, 1, 1, 1, NaN], [1, 1, 1, 1, 1]]}}', "NaN"),
    tf("unknown-key", {"time_tf": {"colour": {}}}, "unknown key 'colour'"),
    tf("not-object", "[1, 2]", "JSON object"),
    tf("null-section", {"data_tf": None}, "data_tf must be a JSON object"),
    tf("deep-nesting", "[" * 100_000 + "]" * 100_000, "too deeply"),
    tf("not-json", "{not json", "not valid JSON"),
    Case(
        "tf-folder",
        ("integrate", "{s}", "{d}/o.zarr", "--tf", "{d}/tf.json"),
        "is a folder, not a file",
        mkdir("tf.json"),
    ),
    Case(
        "tf-symlink-loop",
        ("integrate", "{s}", "{d}/o.zarr", "--tf", "{d}/tf-a"),
        "symlink loop",
        symlink_loop("tf"),
    ),
    Case(
        "tf-missing",
        ("render", "{s}", "-o", "{d}/o.png", "--tf", "{d}/none.json"),
        "does not exist; check the --tf path",
    ),
    # ---------------------------------------------------------------- render and camera
    render("size-too-small", ("--size", "8x8"), "outside 16..8192"),
    render("size-too-large", ("--size", "9000x100"), "outside 16..8192"),
    render("size-malformed", ("--size", "big"), "WxH"),
    render("background-unknown", ("--background", "no-such-colour"), "unknown colour"),
    render("clip-offset-outside", ("--clip", "1,0,0,5"), "clip offset is 5; use -1"),
    render("clip-zero-normal", ("--clip", "0,0,0,0.5"), "normal is (0, 0, 0)"),
    render("clip-not-finite", ("--clip", "inf,0,0,0"), "four finite numbers"),
    render("clip-too-few", ("--clip", "1,2"), "must be 4 comma-separated numbers"),
    render("azimuth-nan", ("--azimuth", "nan"), "camera azimuth"),
    render("zoom-zero", ("--zoom", "0"), "camera zoom is 0; use"),
    render("zoom-huge", ("--zoom", "1e9"), "camera zoom"),
    render("projection-unknown", ("--projection", "fisheye"), "unknown projection 'fisheye'"),
    render("frames-one", ("--turntable", "{d}/t.gif", "--frames", "1"), "use 2 to 3600"),
    render("turntable-suffix", ("--turntable", "{d}/t.txt"), "video suffix"),
    render("render-enhance-unknown", ("--enhance", "glow"), "unknown enhancement"),
    render("render-normalize-unknown", ("--normalize", "sum"), "unknown additive"),
    render("render-engine-unknown", ("--engine", "cuda"), "unknown engine"),
    render("render-order-not-permutation", ("--order", "3,1"), "must be a permutation"),
    render(
        "save-chronovolume-suffix",
        ("--save-chronovolume", "{d}/cv.png"),
        "cannot tell the chronovolume format",
    ),
    # ---------------------------------------------------------------- outputs
    Case(
        "integrate-read-only",
        ("integrate", "{s}", "{ro}/o.zarr"),
        "does not take new files",
        read_only=True,
    ),
    Case(
        "render-read-only",
        ("render", "{s}", "-o", "{ro}/o.png"),
        "does not take new files",
        read_only=True,
    ),
    Case(
        "export-read-only",
        ("export", "{s}", "-o", "{ro}/out", "--format", "raw"),
        "does not take new files",
        read_only=True,
    ),
    Case(
        "ingest-read-only",
        ("ingest", "{d}/raw/v*.raw", "-o", "{ro}/o.zarr", *ING),
        "does not take new files",
        raw_steps("raw"),
        read_only=True,
    ),
    Case(
        "integrate-file-as-folder",
        ("integrate", "{s}", "{d}/notes.txt/o.zarr"),
        "is a file, not a folder",
        write("notes.txt", "not a folder"),
    ),
    Case(
        "ingest-file-as-folder",
        ("ingest", "{d}/raw/v*.raw", "-o", "{d}/notes.txt/o.zarr", *ING),
        "is a file, not a folder",
        lambda d, s: (raw_steps("raw")(d, s), write("notes.txt", "not a folder")(d, s)),
    ),
    Case(
        "integrate-onto-input",
        ("integrate", "{s}", "{s}", "--overwrite"),
        "is the input",
        own_store=True,
    ),
    Case(
        "export-onto-input",
        ("export", "{s}", "-o", "{s}", "--format", "npy", "--overwrite"),
        "is the input",
        own_store=True,
    ),
    Case(
        "integrate-onto-symlinked-input",
        ("integrate", "{s}", "{d}/link.zarr", "--overwrite"),
        "is the input",
        link_to_store("link.zarr"),
        own_store=True,
    ),
    Case(
        "integrate-inside-input",
        ("integrate", "{s}", "{s}/cv.zarr"),
        "lies inside the input",
        own_store=True,
    ),
    Case(
        "export-inside-input",
        ("export", "{s}", "-o", "{s}/steps", "--format", "vti"),
        "lies inside the input",
        own_store=True,
    ),
    Case(
        "render-inside-input",
        ("render", "{s}", "-o", "{s}/view.png"),
        "lies inside the input",
        own_store=True,
    ),
    Case(
        "render-save-onto-input",
        ("render", "{s}", "-o", "{d}/o.png", "--save-chronovolume", "{s}", "--overwrite"),
        "is the input",
        own_store=True,
    ),
    Case(
        "render-turntable-inside-input",
        ("render", "{s}", "-o", "{d}/o.png", "--turntable", "{s}/turn.gif"),
        "lies inside the input",
        own_store=True,
    ),
    Case(
        "integrate-containing-input",
        ("integrate", "{d}/outer.zarr/S.zarr", "{d}/outer.zarr", "--overwrite"),
        "contains the input",
        nested_store,
    ),
    Case(
        "ingest-containing-input",
        ("ingest", "{d}/raw.zarr/v*.raw", "-o", "{d}/raw.zarr", "--overwrite", *ING),
        "contains the input",
        raw_steps("raw.zarr"),
    ),
    Case(
        "ingest-onto-input-file",
        ("ingest", "{d}/raw/v0.raw", "-o", "{d}/raw/v0.raw", "--overwrite", *ING),
        "is the input",
        raw_steps("raw"),
    ),
    ingest_around("times-file", "--times", "t.txt", "0\n1"),
    ingest_around("times-json", "--times", "m.json", "{}", key=":t"),
    ingest_around("meta", "--meta", "m.json", "{}"),
    Case(
        "ingest-onto-its-times-from-meta",
        (
            "ingest",
            "{d}/raw/v*.raw",
            "-o",
            "{d}/m.json",
            "--overwrite",
            *ING,
            "--times-from-meta",
            "{d}/m.json",
        ),
        "is the input",
        lambda d, s: (raw_steps("raw")(d, s), write("m.json", '{"times": [0, 1]}')(d, s)),
    ),
    Case(
        "render-around-its-events",
        (
            "render",
            "{s}",
            "-o",
            "{d}/o.png",
            "--save-chronovolume",
            "{d}/cv.zarr",
            "--overwrite",
            "--events",
            "{d}/cv.zarr/events.json",
        ),
        "contains the input",
        lambda d, s: (mkdir("cv.zarr")(d, s), write("cv.zarr/events.json", "{}")(d, s)),
    ),
    Case(
        "integrate-onto-a-link-to-nothing",
        ("integrate", "{s}", "{d}/dl.zarr"),
        "already exists; pass --overwrite",
        lambda d, s: (d / "dl.zarr").symlink_to(d / "nowhere.zarr"),
    ),
    Case(
        "render-tracks-of-events-without-tracks",
        (*TRACKS, "--events", "{d}/events.json"),
        "cannot colour by track",
        edited_events(lambda e: [f.pop("track") for f in e["features"]]),
    ),
    Case(
        "render-tracks-of-events-without-a-range",
        (*TRACKS, "--events", "{d}/events.json"),
        "cannot colour by track",
        edited_events(lambda e: e["meta"].update(mask={"kind": "opacity", "opacity": 0.1})),
    ),
    Case(
        "render-state-onto-its-tf",
        (
            "render",
            "--state",
            "{d}/s.json",
            "--tf",
            "{d}/t.json",
            "-o",
            "{d}/t.json",
            "--overwrite",
        ),
        "is the input",
        state_and_tf,
    ),
    Case(
        "render-tracks-of-events-with-a-mask-not-an-object",
        (*TRACKS, "--events", "{d}/events.json"),
        "does not say what a step showed",
        edited_events(lambda e: e["meta"].update(mask="threshold")),
    ),
    Case(
        "render-tracks-of-events-with-steps-not-a-list",
        (*TRACKS, "--events", "{d}/events.json"),
        "cannot colour by track",
        edited_events(lambda e: e["meta"].update(steps=5)),
    ),
    Case(
        "generate-onto-working-folder",
        ("generate", "vortex", ".", "--overwrite"),
        "contains the current folder",
    ),
    Case(
        "integrate-exists",
        ("integrate", "{s}", "{d}/o.zarr"),
        "already exists; pass --overwrite",
        mkdir("o.zarr"),
    ),
    Case(
        "render-exists",
        ("render", "{s}", "-o", "{d}/o.png"),
        "already exists; pass --overwrite",
        write("o.png", "an image"),
    ),
    Case(
        "render-save-exists",
        ("render", "{s}", "-o", "{d}/o.png", "--save-chronovolume", "{d}/cv.zarr"),
        "already exists; pass --overwrite",
        mkdir("cv.zarr"),
    ),
    Case(
        "export-exists",
        ("export", "{s}", "-o", "{d}/out.npy", "--format", "npy"),
        "already exists; pass --overwrite",
        write("out.npy", "an array"),
    ),
    Case(
        "generate-exists",
        ("generate", "jet", "{d}/g.zarr", "--shape", "8x8x8", "--steps", "2"),
        "already exists; pass --overwrite",
        mkdir("g.zarr"),
    ),
    # ---------------------------------------------------------------- generate
    Case("generate-unknown", ("generate", "tornado", "{d}/g.zarr"), "tornado"),
    Case("generate-shape-2d", ("generate", "jet", "{d}/g.zarr", "--shape", "8x8"), "NXxNYxNZ"),
    Case(
        "generate-shape-huge",
        ("generate", "jet", "{d}/g.zarr", "--shape", "100000x100000x100000"),
        "too large to generate",
    ),
    Case("generate-steps-zero", ("generate", "jet", "{d}/g.zarr", "--steps", "0"), "1 to 100000"),
    Case(
        "generate-steps-huge",
        ("generate", "jet", "{d}/g.zarr", "--steps", "100000000000"),
        "--steps",
    ),
    Case("generate-seed-negative", ("generate", "jet", "{d}/g.zarr", "--seed", "-1"), "seed"),
    # ---------------------------------------------------------------- memory budgets
    integrate("memory-infinite", ("--memory", "1e999"), "more than 1.00 PiB"),
    integrate("memory-absurd", ("--memory", "2000TB"), "more than 1.00 PiB"),
    integrate("memory-not-a-size", ("--memory", "lots"), "is not a size"),
    integrate("memory-zero", ("--memory", "0"), "must be positive"),
    # ---------------------------------------------------------------- export options
    export("export-format-unknown", ("--format", "tiff"), "unknown export format 'tiff'"),
    export("export-z-reversed", ("--z", "2:1"), "z slab 2:1 is outside"),
    export("export-z-garbage", ("--z", "abc"), "cannot read z slab"),
    export("export-window-past-end", ("--window", "3:99"), "outside the series"),
    # ---------------------------------------------------------------- stores and inputs
    Case("store-missing", ("integrate", "{d}/none.zarr", "{d}/o.zarr"), "does not exist"),
    Case(
        "store-symlink-loop",
        ("render", "{d}/store-a", "-o", "{d}/o.png"),
        "symlink loop",
        symlink_loop("store"),
    ),
    Case("info-missing", ("info", "{d}/none.zarr"), "does not exist"),
    Case("ingest-missing", ("ingest", "{d}/none.raw", "-o", "{d}/o.zarr", *ING), "does not exist"),
    Case("ingest-no-match", ("ingest", "{d}/*.none", "-o", "{d}/o.zarr", *ING), "no files match"),
    Case(
        "ingest-format-unknown",
        ("ingest", "{d}/raw/v0.raw", "-o", "{d}/o.zarr", "--format", "gif"),
        "unknown format 'gif'",
        raw_steps("raw"),
    ),
    Case(
        "ingest-wrong-endian",
        (
            "ingest",
            "{d}/raw/v*.raw",
            "-o",
            "{d}/o.zarr",
            "--dims",
            "28",
            "24",
            "20",
            "--endian",
            "big",
        ),
        "pass --endian little",
        smooth_raw("raw"),
    ),
    Case(
        "ingest-wrong-endian-nan-fill",
        (
            "ingest",
            "{d}/raw/v*.raw",
            "-o",
            "{d}/o.zarr",
            "--dims",
            "28",
            "24",
            "20",
            "--endian",
            "big",
            "--nan-fill",
            "0",
        ),
        "pass --endian little",
        smooth_raw("raw"),
    ),
    Case(
        "ingest-wrong-dtype",
        (
            "ingest",
            "{d}/raw/v*.raw",
            "-o",
            "{d}/o.zarr",
            "--dims",
            "28",
            "24",
            "40",
            "--dtype",
            "uint16",
        ),
        "pass --dtype float32 --dims 28 24 20",
        smooth_raw("raw"),
    ),
    # ---------------------------------------------------------------- must succeed
    Case(
        "ok-generate-unicode",
        ("generate", "jet", "{d}/out dir/gé nérée.zarr", "--shape", "8x6x4", "--steps", "2"),
        creates="{d}/out dir/gé nérée.zarr",
    ),
    Case(
        "ok-integrate-unicode",
        ("integrate", "{s}", "{d}/out dir/chronö volume.zarr", "--engine", "numpy"),
        creates="{d}/out dir/chronö volume.zarr",
    ),
    Case(
        "ok-export-unicode",
        ("export", "{s}", "-o", "{d}/out dir/schritte ü", "--format", "vti", "--window", "0:2"),
        creates="{d}/out dir/schritte ü/schritte ü.pvd",
    ),
    Case(
        "ok-ingest-unicode",
        ("ingest", "{d}/rå data/v*.raw", "-o", "{d}/out dir/ïngest.zarr", *ING),
        setup=raw_steps("rå data"),
        creates="{d}/out dir/ïngest.zarr",
    ),
    Case(
        "ok-render-unicode",
        (
            "render",
            "{s}",
            "-o",
            "{d}/out dir/bild ö.png",
            "--engine",
            "numpy",
            "--size",
            "32x32",
            "--save-chronovolume",
            "{d}/out dir/chronö volume.zarr",
        ),
        creates="{d}/out dir/bild ö.png",
    ),
]


def snapshot(folder: Path) -> dict[str, str]:
    """Every entry under `folder` (hidden ones too), links not followed: files by sha256."""
    entries: dict[str, str] = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            p = Path(root) / name
            rel = str(p.relative_to(folder))
            if p.is_symlink():
                entries[rel] = "link -> " + os.readlink(p)
            elif p.is_dir():
                entries[rel] = "folder"
            else:
                entries[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return entries


@dataclass
class Run:
    case: Case
    argv: list[str]
    result: subprocess.CompletedProcess | None
    folder: Path
    store: Path
    folder_before: dict[str, str]
    store_before: dict[str, str]
    folder_after: dict[str, str] | None = None
    store_after: dict[str, str] | None = None


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    """The shared input: 5 steps of 3x4x5 (Z, Y, X) random values."""
    path = tmp_path_factory.mktemp("input") / "S.zarr"
    chronocl.TimeSeries.from_array(np.random.default_rng(0).random((5, 3, 4, 5))).save(path)
    return path


def _prepare(case: Case, root: Path, shared: Path) -> Run:
    d = root / case.id
    d.mkdir()
    s = shared
    if case.own_store:
        s = d / "S.zarr"
        shutil.copytree(shared, s)
    if case.setup is not None:
        case.setup(d, s)
    fill = {"s": str(s), "d": str(d), "ro": str(READ_ONLY)}
    argv = [a.format(**fill) for a in case.args]
    return Run(case, argv, None, d, s, snapshot(d), snapshot(s))


def _execute(run: Run) -> Run:
    """The case as its own `python -m chronocl`."""
    run.result = cli_process.run(run.argv, cwd=run.folder, own_process=True)
    run.folder_after = snapshot(run.folder)
    run.store_after = snapshot(run.store)
    return run


def _execute_forked(runs: list[Run]) -> list[Run]:
    """The cases one after another through the CLI server (a fork each)."""
    for run in runs:
        run.result = cli_process.run(run.argv, cwd=run.folder)
        run.folder_after = snapshot(run.folder)
        run.store_after = snapshot(run.store)
    return runs


@pytest.fixture(scope="module")
def runs(request, store, tmp_path_factory) -> dict[str, Run]:
    """The selected cases: grouped (the bad ones), or each in its own `python -m chronocl`."""
    wanted = {
        item.callspec.params["case"].id
        for item in request.session.items
        if item.module is request.module and hasattr(item, "callspec")
        if "case" in item.callspec.params
    }
    root = tmp_path_factory.mktemp("cases")
    todo = [
        _prepare(c, root, store)
        for c in CASES
        if c.id in wanted and not (c.read_only and READ_ONLY is None)
    ]
    alone = [r for r in todo if r.case.ok]
    forked = [r for r in todo if r not in alone]
    with ThreadPoolExecutor(2) as pool:  # the forks beside the processes of their own
        done = [pool.submit(_execute_forked, forked)]
        done += [pool.submit(_execute, r) for r in alone]
        for future in done:
            future.result()
    return {r.case.id: r for r in todo}


def test_case_ids_are_unique():
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids))


@pytest.mark.parametrize("case", [c for c in CASES if not c.ok], ids=lambda c: c.id)
def test_bad_input_is_refused_cleanly(case: Case, runs: dict[str, Run]):
    if case.read_only and READ_ONLY is None:
        pytest.skip("no folder here refuses new files to this user")
    run = runs[case.id]
    result = run.result
    assert result is not None
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode == 2, (run.argv, result.stderr)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("chronocl: error: "), lines[0]
    assert case.needle in lines[0], lines[0]
    assert result.stdout == ""
    # Nothing written, nothing half-written, nothing removed: the folder is as it was.
    assert run.folder_after == run.folder_before
    assert run.store_after == run.store_before, "the input store changed"
    if case.read_only:
        leftovers = [p for p in os.listdir(READ_ONLY) if "partial" in p or "chronocl" in p]
        assert leftovers == [] and not any(
            os.path.lexists(a) for a in run.argv if a.startswith(str(READ_ONLY))
        )


@pytest.mark.parametrize("case", [c for c in CASES if c.ok], ids=lambda c: c.id)
def test_awkward_but_valid_paths_succeed(case: Case, runs: dict[str, Run]):
    run = runs[case.id]
    result = run.result
    assert result is not None
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    target = Path(case.creates.format(d=run.folder, s=run.store))
    assert target.exists(), sorted(run.folder_after or {})
    assert not [k for k in run.folder_after or {} if ".partial" in k or "chronocl-probe" in k]
    assert run.store_after == run.store_before
