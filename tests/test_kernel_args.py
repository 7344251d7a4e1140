"""The integration kernels' arguments: one declaration (chronocl/engine/kernel_args.py) that
common.h's KERNEL_ARGS and ROWS_ARGS and every mode's integrate kernels follow, name by name
and type by type, with each mode's extras named as `Mode.kernel_options` returns them.

No device: the kernel sources are read as text. A kernel whose arguments drift from the
declaration would be handed values in the wrong places, silently; this catches it first.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from chronocl import modes
from chronocl.engine.kernel_args import INTEGRATE, OUTPUTS, ROWS, SCALARS, Arg, parse
from chronocl.engine.program import kernel_dir
from chronocl.modes.base import KernelInput
from chronocl.modes.spec import IntegrationSpec


def c_source(name: str) -> str:
    """kernels/opencl/NAME without comments, macro lines joined."""
    text = (kernel_dir() / name).read_text()
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    text = re.sub(r"//[^\n]*", " ", text)
    return text.replace("\\\n", " ")


def macro(text: str, name: str) -> str:
    """The body of `#define NAME ...` (for a macro with parameters, after them)."""
    m = re.search(rf"^\s*#define {name}\b(\([^)]*\))?(.*)$", text, flags=re.M)
    assert m is not None, f"common.h defines no {name}"
    return m.group(2).strip()


def signature(text: str, function: str) -> list[str]:
    """The parameters of `__kernel void FUNCTION(...)`, as written."""
    m = re.search(rf"__kernel\s+void\s+{function}\s*\(", text)
    assert m is not None, f"no kernel {function}"
    depth, i = 1, m.end()
    while depth:
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        i += 1
    params, depth, start = [], 0, m.end()
    for j in range(m.end(), i - 1):
        depth += {"(": 1, ")": -1}.get(text[j], 0)
        if text[j] == "," and depth == 0:
            params.append(text[start:j].strip())
            start = j + 1
    params.append(text[start : i - 1].strip())
    return [" ".join(p.split()) for p in params]


def test_common_h_follows_the_declaration():
    common = c_source("common.h")
    assert parse(macro(common, "KERNEL_ARGS")) == INTEGRATE.args
    assert parse(macro(common, "ROWS_ARGS")) == ROWS.args


def test_the_check_sees_a_swap_or_a_retype():
    """Two arguments swapped, or one retyped, no longer match the declaration."""
    text = macro(c_source("common.h"), "KERNEL_ARGS")
    swapped = text.replace("const int nx", "const int TMP").replace("const int ny", "const int nx")
    assert parse(swapped.replace("const int TMP", "const int ny")) != INTEGRATE.args
    assert parse(text.replace("const float cut", "const int cut")) != INTEGRATE.args


def extras_of(mode) -> list[dict]:
    """The mode's extras, by name, for a few inputs (names and types may not depend on them)."""
    spec = IntegrationSpec(mode=mode.name, threshold=0.25)
    positions = np.linspace(0.0, 1.0, 4)
    given = [
        KernelInput(np.dtype(np.uint8), 4, (0.0, 255.0)),
        KernelInput(np.dtype(np.float32), 4, (-1.0, 2.5)),
        KernelInput(np.dtype(np.uint16), 300, (3.0, 3.0)),
    ]
    return [mode.kernel_options(spec, positions, raw, g)[1] for g in given for raw in (0, 1)]


def is_of(arg: Arg, value) -> bool:
    """Whether `value` is what the kernel takes for `arg` (its dtype, and lanes)."""
    dtype, lanes = SCALARS[arg.ctype.removeprefix("const ")]
    if lanes == 1:
        return type(value) is dtype
    return isinstance(value, np.ndarray) and value.dtype == dtype and value.shape == (lanes,)


@pytest.mark.parametrize("name", modes.names())
def test_each_modes_kernels_take_the_declared_arguments(name):
    """KERNEL_ARGS, the mode's extras by name and type, its outputs, and in a rows kernel
    ROWS_ARGS: the order the engine sets them in (`OpenCLEngine.accumulate`)."""
    mode = modes.get(name)
    text = c_source(f"{mode.kernel}.cl")
    outputs = OUTPUTS[: 4 if mode.writes_winners else 2 if mode.has_t_index else 1]
    for function in (mode.kernel_function, mode.rows_kernel):
        if function is None:
            continue
        params = signature(text, function)
        assert params[0] == "KERNEL_ARGS", function
        rest = params[1:]
        if function == mode.rows_kernel:
            assert re.fullmatch(r"ROWS_ARGS\(\w+\)", rest[-1]), function
            rest = rest[:-1]
        declared = parse(", ".join(rest)) if rest else ()
        n = len(declared) - len(outputs)
        assert declared[n:] == outputs, function
        extras = declared[:n]
        for given in extras_of(mode):
            assert list(given) == [a.name for a in extras], function
            assert all(is_of(a, given[a.name]) for a in extras), (function, given)


def test_bound_arguments_follow_the_declaration():
    names = [a.name for a in INTEGRATE.args]
    values = {
        a.name: (None if a.pointer else [1, 2, 3, 4] if "float4" in a.ctype else 3)
        for a in INTEGRATE.args
    }
    bound = INTEGRATE.bind(**values)
    for a, v in zip(INTEGRATE.args, bound.values, strict=True):
        assert v is None if a.pointer else is_of(a, v), a
    bound.set(x0=48, data="brick")
    assert bound.values[names.index("x0")] == np.int32(48)
    assert bound.values[names.index("data")] == "brick"
    with pytest.raises(TypeError, match="missing \\['view'\\]"):
        INTEGRATE.bind(**{k: v for k, v in values.items() if k != "view"})
    with pytest.raises(TypeError, match="unknown \\['zoom'\\]"):
        INTEGRATE.bind(**values, zoom=1)
    with pytest.raises(ValueError, match="enh takes 4 values"):
        INTEGRATE.bind(**{**values, "enh": [1.0, 2.0, 3.0]})
