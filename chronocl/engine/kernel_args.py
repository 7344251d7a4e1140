"""The integration kernels' arguments, declared once as C text and set by name.

Every integrate kernel of kernels/opencl/MODE.cl takes, in this order: KERNEL_ARGS (the
macro in common.h, declared here as `INTEGRATE`), its mode's extras (the names and values
`Mode.kernel_options` returns), its outputs (`OUTPUTS`: `out`, `t_index` in the modes that
have one, and `won_u`, `won_k` in those that write winners: `Mode.writes_winners`), and in a
`_rows` kernel `ROWS` (the macro ROWS_ARGS). As pyopencl's reduction.py does, the host parses
the C text for the names and the scalars' dtypes; the host sets arguments by name, and
tests/test_kernel_args.py checks every kernel's signature against these declarations name by
name and type by type.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

# The C text of common.h's KERNEL_ARGS, argument by argument.
INTEGRATE_C = """
    __global const DATA_T *data, __global const float *lut, __global const float4 *tc,
    __global const int *order, __global const int *steps, __global const long *step_base,
    const long zstride, const int x0, const int nx,
    const int ny, const int nzb, const int w, const int zcrop, const int nz_out,
    const float vmin, const float scale, const float cut, const float4 enh, const float4 view
"""
# out_t: float4, or uchar4 (RGBA8); a mode that `writes_winners` also takes won_u and won_k
OUTPUTS_C = (
    "__global out_t *out, __global int *t_index, __global float *won_u, __global uchar *won_k"
)
ROWS_C = "const int rows, const int nvec, __local T *st"  # ROWS_ARGS(T)

# Host dtypes of the scalar C types (lanes: a float4 is four float32).
SCALARS = {
    "int": (np.int32, 1),
    "long": (np.int64, 1),
    "float": (np.float32, 1),
    "float4": (np.float32, 4),
}


@dataclass(frozen=True)
class Arg:
    """One kernel argument: its name and C type ("__global const float *", "const int")."""

    name: str
    ctype: str

    @property
    def pointer(self) -> bool:
        return self.ctype.endswith("*")

    def value(self, v):
        """`v` as the kernel takes it: scalars in their dtype, buffers and None as given."""
        if self.pointer or v is None:
            return v
        dtype, lanes = SCALARS[self.ctype.removeprefix("const ")]
        if lanes == 1:
            return dtype(v)
        a = np.asarray(v, dtype=dtype)
        if a.shape != (lanes,):
            raise ValueError(f"kernel argument {self.name} takes {lanes} values, got {a.shape}")
        return a


def parse(c_text: str) -> tuple[Arg, ...]:
    """The arguments of a C parameter list ("const int nx, __global float *out")."""
    args = []
    for part in c_text.split(","):
        decl = " ".join(part.replace("*", " * ").split())
        m = re.fullmatch(r"(.+?)\s*\b([A-Za-z_]\w*)", decl)
        if m is None:
            raise ValueError(f"not a C parameter: {part.strip()!r}")
        args.append(Arg(m.group(2), m.group(1).strip()))
    return tuple(args)


class ArgList:
    """A declared argument list: `bind` makes a list in the declared order from names."""

    def __init__(self, c_text: str) -> None:
        self.args = parse(c_text)
        self.positions = {a.name: i for i, a in enumerate(self.args)}

    def bind(self, **values) -> BoundArgs:
        """The values of every argument, by name (None: set later with `BoundArgs.set`)."""
        missing = [a.name for a in self.args if a.name not in values]
        unknown = sorted(set(values) - set(self.positions))
        if missing or unknown:
            raise TypeError(f"kernel arguments: missing {missing}, unknown {unknown}")
        bound = BoundArgs(self, [None] * len(self.args))
        bound.set(**values)
        return bound


@dataclass
class BoundArgs:
    """Values for an `ArgList`, in its order (`values`), changed by name between launches."""

    decl: ArgList
    values: list

    def set(self, **values) -> None:
        for name, v in values.items():
            i = self.decl.positions[name]
            self.values[i] = self.decl.args[i].value(v)


INTEGRATE = ArgList(INTEGRATE_C)
OUTPUTS = parse(OUTPUTS_C)
ROWS = ArgList(ROWS_C)
