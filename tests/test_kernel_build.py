"""Kernel builds are silent: every kernel file builds without a warning with the options the
engine uses, on a cold cache, and a CLI run prints nothing of the compiler's.

The options are those of OpenCLEngine.accumulate / _elementwise and bench/integrate.py, and
every one of the host recolouring's (chronocl/engine/gather.py, chronocl/render/recolour/bricks.py).
Options a file never mentions cannot change its preprocessed source, so they are held
fixed; of the rest, a set of combinations holding every pair of values (all-pairs) is
built, in the test process with pyopencl's CompilerWarning an error.
CHRONOCL_KERNEL_MATRIX=full builds every combination instead, in a fresh process (about
400 000 builds now, days on PoCL: a release check on many cores, not a CI run).
"""

from __future__ import annotations

import itertools
import json
import os
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import chronocl
from chronocl import modes
from chronocl.engine import opencl, program
from chronocl.engine.defines import CPU_PATHS, HALF_DEFINES
from chronocl.engine.gather import CL_TYPES, gather_defines
from chronocl.engine.opencl import DEVICE_TYPES, OpenCLEngine
from chronocl.modes.base import KernelInput
from chronocl.modes.spec import IntegrationSpec
from chronocl.render.recolour.bricks import RECOLOUR_H, bricks_defines

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INTEGRATION_KEYS = set(
    "DATA_T DATA_V VEC KEY_RAW IDX_T CHANGE_BYTES QUANT LUT_N CONST_COLOR TF_SEGS SEG_ALPHA "
    "ENHANCE EARLY_EXIT SKIP_EMPTY IS_MIN NORM_TIME RAW_PARTIAL TIME_ORDER ALIGNED "
    "ORDER_FORWARD ORDER_BACKWARD TIME_TABLE SLOTS RGBA8 CPU_PATHS WINNERS".split()
)
STEP_ORDERS = ("table", "forward", "backward")  # order[i], or the steps in turn / reversed
BOOLS = (False, True)


def byte_lane_define(mode) -> str | None:
    """The define a mode sets for byte data compared in byte lanes (None: it has none)."""
    spec = IntegrationSpec(mode=mode.name, order="forward")
    on, _ = mode.kernel_options(
        spec, np.zeros(2), False, KernelInput(np.dtype(np.uint8), 2, (0, 255))
    )
    off, _ = mode.kernel_options(
        spec, np.zeros(2), False, KernelInput(np.dtype(np.float32), 2, (0, 255))
    )
    keys = [k for k in on if on[k] is True and off.get(k) is False]
    assert len(keys) <= 1, keys
    return keys[0] if keys else None


def integration_combinations(name: str):
    """Every define combination OpenCLEngine.accumulate can pass for mode `name`."""
    mode = modes.get(name)
    byte_path = byte_lane_define(mode)
    data = []  # (DATA_T, QUANT, raw lanes): quantised paths are uint8 only; max/min compare
    for t in DEVICE_TYPES.values():  # raw values in the lanes of every integer type
        data.append((t, False, False))
        if t == "uchar":
            data.append((t, False, True) if byte_path else (t, True, False))
        elif t != "float" and byte_path == "KEY_RAW":
            data.append((t, False, True))
    lanes = ((0, 16), (0, 1), (1, 1), (2, 1))  # (ENHANCE, VEC): enhancement is VEC=1 only
    norm = BOOLS if name == "additive" else (False,)
    partial = BOOLS if mode.slides == "invert" else (False,)
    time_order = (0, 1, 2) if name == "change" else (False,)
    # a winner's time tables in registers: rows kernels (VEC 16) of the modes with t_index
    time_table = BOOLS if mode.has_t_index and mode.rows_kernel else (False,)
    winners = BOOLS if mode.writes_winners else (False,)  # each voxel's winner written too
    # (CONST_COLOR, TF_SEGS, SEG_ALPHA) as the engine passes them: pieces of colour, opacity
    # or both; their opacity is the value (1) or, in the threshold modes, decides lanes (2).
    # TF_SEGS: one piece, some with a middle one, the most (2..7 compile as 3 does).
    seg_alpha = 2 if mode.opacity_threshold else 1
    colour = [(True, 0, 0), (False, 0, 0), (False, 3, 0), (False, 1, seg_alpha)]
    colour += [(False, 3, seg_alpha), (False, 8, seg_alpha), (True, 3, seg_alpha)]
    colour += [(True, 8, seg_alpha)]  # (False, 3, 2): count's own ramp, coloured and in pieces
    for combo in itertools.product(
        data,
        lanes,
        colour,
        BOOLS,
        BOOLS,
        BOOLS,
        norm,
        partial,
        time_order,
        (256, 65536),
        STEP_ORDERS,
        time_table,
        winners,
    ):
        (t, quant, raw), (enh, vec), (const, segs, pieces_alpha), early, skip, aligned = combo[:6]
        norm_time, raw_partial, order, lut_n, steps, table, won = combo[6:]
        if table and vec != 16:
            continue
        if quant and (lut_n != 256 or mode.lut_by_value):  # one LUT entry per byte value
            continue
        if enh and pieces_alpha == 2:  # enhanced opacity is not bounded by the pieces'
            continue
        yield {
            "DATA_T": t,
            "DATA_V": t + (str(vec) if vec > 1 else ""),
            "VEC": vec,
            "KEY_RAW": False,
            "CHANGE_BYTES": False,
            **({byte_path: raw} if byte_path else {}),
            "IDX_T": ("uchar" if t == "uchar" else "ushort")
            if raw and byte_path == "KEY_RAW"
            else False,
            "QUANT": quant,
            "LUT_N": lut_n,
            "CONST_COLOR": const,
            "TF_SEGS": segs,
            "SEG_ALPHA": pieces_alpha,
            "ENHANCE": enh,
            "EARLY_EXIT": early,
            "SKIP_EMPTY": skip,
            "IS_MIN": name == "min",
            "NORM_TIME": norm_time,
            "RAW_PARTIAL": raw_partial,
            "TIME_ORDER": order,
            "ALIGNED": aligned,
            "ORDER_FORWARD": steps == "forward",
            "ORDER_BACKWARD": steps == "backward",
            "TIME_TABLE": table,
            "WINNERS": won,
        }


def all_pairs(combinations: list[dict]) -> list[dict]:
    """A subset of `combinations` holding every pair of (key, value)s that any of them holds:
    greedily, the first holding the most pairs not yet held. Pairs are numbered in an array
    (a round is one gather; a set per combination took minutes for tens of thousands)."""
    keys = list(combinations[0])
    assert all(list(c) == keys for c in combinations)
    codes = [{} for _ in keys]  # a value's number for its key (a dict: False and 0 are one)
    items = np.array(
        [
            [code.setdefault(c[k], len(code)) for k, code in zip(keys, codes, strict=True)]
            for c in combinations
        ]
    )
    columns, base = [], 0
    for a, b in itertools.combinations(range(len(keys)), 2):
        columns.append(base + items[:, a] * len(codes[b]) + items[:, b])
        base += len(codes[a]) * len(codes[b])
    pairs = np.stack(columns, axis=1)
    todo = np.zeros(base, bool)
    todo[pairs] = True
    chosen = []
    while todo.any():
        best = int(np.argmax(todo[pairs].sum(axis=1)))  # the first of the best, as max() picks
        chosen.append(combinations[best])
        todo[pairs[best]] = False
    return chosen


def with_slots(combinations: list[dict], full: bool) -> list[dict]:
    """SLOTS (the steps read where they lie) changes only how a voxel's address is computed,
    RGBA8 (the display format written instead of float32) only how a result is stored, and
    CPU_PATHS (common.h's x86 paths lowered: `chronocl.engine.defines.CPU_PATHS`) only which
    of equal paths a build takes: in the full matrix every combination with each form;
    otherwise the builds take the forms in turn, so every form compiles beside every option
    (dimensions of their own in the product multiplied the all-pairs search for no build more)."""
    paths = list(CPU_PATHS.values())
    if full:
        return [
            {**c, "SLOTS": s, "RGBA8": r, "CPU_PATHS": p}
            for c in combinations
            for s in BOOLS
            for r in BOOLS
            for p in paths
        ]
    return [
        {
            **c,
            "SLOTS": i % 2 == 1,
            "RGBA8": i // 2 % 2 == 1,
            "CPU_PATHS": paths[i // 4 % len(paths)],
        }
        for i, c in enumerate(combinations)
    ]


def builds(full: bool) -> list[tuple[str, list[str], bool | str]]:
    """(kernel file, options, common) of every build the test makes."""
    out = []
    files = {}
    for name in modes.names():
        file = f"{modes.get(name).kernel}.cl"
        files.setdefault(file, []).extend(integration_combinations(name))
    files["read_roofline.cl"] = [
        {"DATA_T": t, "DATA_V": t + "16", "LUT_N": 256, "VEC": 16} for t in ("uchar", "float")
    ]
    for file, combinations in files.items():
        text = program.source(file)
        used = {k for k in combinations[0] if re.search(rf"\b{k}\b", text)}
        reduced = {}  # options the file never names are held at their first value
        for c in combinations:
            r = {k: (v if k in used else combinations[0][k]) for k, v in c.items()}
            reduced.setdefault(frozenset(r.items()), r)  # equal as dicts are (False == 0)
        reduced = list(reduced.values())
        if not full:
            reduced = all_pairs(reduced)
        if file != "read_roofline.cl":
            reduced = with_slots(reduced, full)
        out += [(file, list(program.build_options(c)), True) for c in reduced]
    sliding = []  # each mode's combine / finish kernels, and the fixed-point sums
    for name in modes.names():
        mode, spec = modes.get(name), IntegrationSpec(mode=name)
        if mode.state_bytes:  # partials it combines
            file, _, defines = mode.combine_kernel(spec)
            sliding.append((f"{file}.cl", defines))
        if mode.slides == "invert":
            acc = np.zeros((1, 1, 1, mode.sum_channels), np.int64)
            _, defines, _, _ = mode.finish_kernel(acc, np.linspace(0, 1, 3), spec)
            sliding.append((f"{mode.kernel}.cl", defines))
            sliding.append(("sums.cl", {"CHANNELS": mode.sum_channels}))
        if mode.compares_values:  # its leaves' values, from steps on the device (device_leaves)
            sliding += [("leaves.cl", {"DATA_T": t}) for t in DEVICE_TYPES.values()]
            sliding.append(("leaves.cl", dict(HALF_DEFINES)))
    sliding = [
        (f, {"SLIDING": True, **d}) for i, (f, d) in enumerate(sliding) if (f, d) not in sliding[:i]
    ]
    out += [(f, list(program.build_options(d)), True) for f, d in sliding]
    out.append(("probe.cl", [], False))  # the device check (chronocl.engine.device)
    for k in (np.uint8, np.uint16):  # the host recolouring's, after recolour.h or alone
        host = [("recolour_bricks.cl", bricks_defines(k), RECOLOUR_H)]
        host += [
            ("recolour_gather.cl", gather_defines(k, t, c), False) for t in CL_TYPES for c in BOOLS
        ]
        out += [(f, list(program.build_options(d)), common) for f, d, common in host]
    return out


# Said by NVIDIA's driver (550 and later) about every kernel, whatever its source.
DRIVER_NOISE = (
    r"\(\): Warning: Function \w+ is a kernel, so overriding noinline attribute\. "
    r"The function may be inlined when called\."
)

BUILD_ALL = r"""
import json, re, sys, warnings
import pyopencl as cl
from chronocl.engine.device import get_context
from chronocl.engine.program import source

NOISE = sys.argv[1]
dc = get_context()
said = []
for file, options, common in json.load(sys.stdin):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prg = cl.Program(dc.context, source(file, common)).build(options=options)
    log = "\n".join(
        (prg.get_build_info(d, cl.program_build_info.LOG) or "").strip() for d in prg.devices
    )
    log = "\n".join(
        line for line in log.splitlines() if line.strip() and not re.fullmatch(NOISE, line.strip())
    )
    caught = [w for w in caught if log or not issubclass(w.category, cl.CompilerWarning)]
    if caught or log:
        said.append([file, " ".join(options), log, [str(w.message) for w in caught]])
print(json.dumps({"device": dc.info.label, "said": said}))
"""


def cold_env(tmp_path) -> dict:
    """The environment of a process with empty pyopencl and PoCL caches."""
    env = {k: v for k, v in os.environ.items() if k != "CHRONOCL_VERBOSE"}
    env.update(
        XDG_CACHE_HOME=str(tmp_path / "xdg"),
        POCL_CACHE_DIR=str(tmp_path / "pocl"),
        PYOPENCL_NO_CACHE="1",
        PYOPENCL_COMPILER_OUTPUT="1",
    )
    return env


def test_the_builds_cover_the_engines_options(monkeypatch):
    """The options the engine passes are the ones enumerated above (a new one must be added)."""
    seen = []
    real = opencl.kernel

    def recording(dc, name, function, defines, common=True):
        seen.append((name, dict(defines)))
        return real(dc, name, function, defines, common=common)

    monkeypatch.setattr(opencl, "kernel", recording)
    series = chronocl.TimeSeries.from_array(np.random.default_rng(0).random((3, 2, 3, 20)))
    for mode in modes.names():
        chronocl.integrate(series, mode=mode, engine=OpenCLEngine())
    assert {n for n, _ in seen} == {f"{modes.get(m).kernel}.cl" for m in modes.names()}
    combinations = {m: list(integration_combinations(m)) for m in modes.names()}  # once each
    for name, defines in seen:
        assert set(defines) <= INTEGRATION_KEYS, name  # a mode passes only the options it has
        full = {**dict.fromkeys(INTEGRATION_KEYS, False), **defines}
        del full["SLOTS"], full["RGBA8"], full["CPU_PATHS"]  # every form builds (`with_slots`)
        if 1 < full["TF_SEGS"] < 8:
            full["TF_SEGS"] = 3
        names = [m for m in modes.names() if f"{modes.get(m).kernel}.cl" == name]
        assert any(full in combinations[m] for m in names), (name, defines)


def test_every_kernel_builds_without_warnings_on_a_cold_cache(tmp_path):
    """Every build (all-pairs; the full matrix with CHRONOCL_KERNEL_MATRIX=full) in fresh
    processes with empty caches, one per core (a build holds the GIL, so threads would not
    help): the compiler says nothing, and nothing reaches stderr."""
    full = os.environ.get("CHRONOCL_KERNEL_MATRIX") == "full"
    todo = builds(full)
    sources = [f for f in os.listdir(program.kernel_dir()) if f.endswith(".cl")]  # not headers
    assert len({f for f, _, _ in todo}) == len(sources)
    n = max(1, min(os.cpu_count() or 1, 4))
    procs = []
    for i in range(n):
        (tmp_path / str(i)).mkdir()
        (tmp_path / str(i) / "todo.json").write_text(json.dumps(todo[i::n]))
        with open(tmp_path / str(i) / "todo.json") as todo_file:  # all start at once
            proc = subprocess.Popen(
                [sys.executable, "-c", BUILD_ALL, DRIVER_NOISE],
                stdin=todo_file,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=cold_env(tmp_path / str(i)),
                cwd=tmp_path / str(i),
            )
        procs.append(proc)
    said = []
    for proc in procs:
        out, err = proc.communicate(timeout=3600 if full else 900)
        assert proc.returncode == 0, err[-4000:]
        said += json.loads(out)["said"]
        assert err == ""  # clang writes "N warnings generated." straight to fd 2
    assert not said, f"{len(said)} of {len(todo)} builds warned; the first: {said[0]}"


def test_a_cli_run_on_a_cold_cache_prints_only_its_own_line(tmp_path):
    store = tmp_path / "s.zarr"
    raw = np.random.default_rng(1).random((4, 3, 5, 21)).astype(np.float32)
    chronocl.TimeSeries.from_array(raw).save(store)
    out = tmp_path / "o.zarr"
    result = subprocess.run(
        [sys.executable, "-m", "chronocl", "integrate", str(store), str(out)],
        capture_output=True,
        text=True,
        env={**cold_env(tmp_path), "COLUMNS": "500"},  # no wrapped lines
        cwd=tmp_path,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stderr.splitlines()
    # the CLI's own lines: its progress bar and one "wrote OUT (alpha, ...) in T s"
    assert [line for line in lines if "━" not in line] == [lines[-1]], result.stderr
    assert lines[-1].startswith(f"wrote {out} ("), result.stderr


WARNS = '#warning "chronocl test: {}"\n__kernel void f(__global int *x) {{ x[0] = 1; }}\n'


def test_build_logs_are_captured_unless_verbose(monkeypatch, capsys, tmp_path):
    from chronocl.engine.device import get_context

    monkeypatch.delenv("CHRONOCL_VERBOSE", raising=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        program.build(get_context(), "quiet.cl", {"LUT_N": 7}, text=WARNS.format("quiet"))
    assert caught == []
    assert capsys.readouterr().err == ""  # clang's "1 warning generated." goes to fd 2

    # In a fresh process: PoCL 3.0 repeats the first warned build's log in later ones.
    code = (
        "import sys; from chronocl.engine.device import get_context; "
        "from chronocl.engine.program import build; "
        f"build(get_context(), 'loud.cl', {{'LUT_N': 7}}, text={WARNS.format('loud')!r})"
    )
    env = {**cold_env(tmp_path), "CHRONOCL_VERBOSE": "1"}
    result = subprocess.run(
        [sys.executable, "-W", "error", "-c", code],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert "chronocl: building loud.cl on " in result.stderr, result.stderr
    assert "-DLUT_N=7" in result.stderr and "chronocl test: loud" in result.stderr


@pytest.mark.parametrize("verbose", ["", "1"])
def test_build_failure_still_names_options_device_and_log(monkeypatch, verbose):
    from chronocl.core.errors import KernelBuildError
    from chronocl.engine.device import get_context

    monkeypatch.setenv("CHRONOCL_VERBOSE", verbose)
    dc = get_context()
    bad = f"__kernel void f() {{ not C {verbose}; }}"
    with pytest.raises(KernelBuildError) as info:
        program.build(dc, "bad.cl", {"VEC": 16}, text=bad)
    message = str(info.value)
    assert "bad.cl" in message and "-DVEC=16" in message and dc.info.label in message
    assert "error" in message.lower()
