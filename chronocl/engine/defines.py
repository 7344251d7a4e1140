"""The build defines of the integration kernels that follow from a brick and an order: the
device type of the data (DATA_T, DATA_V lanes), float16 bricks, the enhancement code, and whether
the order steps through the brick in turn or reversed (common.h).
"""

from __future__ import annotations

import numpy as np

DEVICE_TYPES = {"uint8": "uchar", "uint16": "ushort", "int16": "short", "float32": "float"}
# float16 bricks (device format float16): DATA_T half, loaded with vload_half into float lanes.
HALF_DEFINES = {"DATA_T": "half", "HALF_DATA": True}
ENHANCE_CODES = {"none": 0, "edge": 1, "silhouette": 2}
VEC = 16  # voxels per work-item along x in the vectorised kernels
# common.h's x86 paths a build may take (its CPU_PATHS): "native", those the CPU has; "avx2",
# AVX2 as on a CPU without AVX-512; "generic", the portable gathers. All give the same bits,
# and the suite builds and compares each variant the CPU it runs on can run.
CPU_PATHS = {"native": None, "avx2": 1, "generic": 0}


def order_defines(order, w: int) -> dict[str, bool]:
    """ORDER_FORWARD / ORDER_BACKWARD where the integration order is the brick's steps in turn
    or reversed: the kernels then step through the brick without an index table (common.h)."""
    order = np.asarray(order)
    forward = np.array_equal(order, np.arange(w))
    return {
        "ORDER_FORWARD": forward,
        "ORDER_BACKWARD": not forward and np.array_equal(order, np.arange(w)[::-1]),
    }


def lane_type(dt: np.dtype, lanes: int) -> str:
    """The kernels' DATA_V: the device type with `lanes` lanes (float lanes for float16 data)."""
    base = "float" if dt == np.float16 else DEVICE_TYPES[dt.name]
    return base + (str(lanes) if lanes > 1 else "")
