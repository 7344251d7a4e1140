"""Every environment variable chronocl reads, in one place: its name and what it sets.

The code each one configures parses its value, next to the numbers it sizes; reading goes
through `get`, which knows only the names below (tests/test_suite_rules.py refuses
`os.environ` anywhere else in the package), so this list is the whole story.
"""

from __future__ import annotations

import os

VARIABLES = {
    "CHRONOCL_DEVICE": "the OpenCL device (an index 0:1 or a name part), as --device",
    "PYOPENCL_CTX": "pyopencl's own device choice, read after CHRONOCL_DEVICE",
    "CHRONOCL_DEVICE_MEMORY": "device memory resident steps may take (e.g. 6GB)",
    "CHRONOCL_DEVICE_KIND": "gpu: a CPU device taken as a GPU (bricks copied to it and kept "
    "there, GPU launch shapes): the suite's GPU paths on PoCL",
    "CHRONOCL_MAX_ALLOC": "a lower largest device buffer (e.g. 1MB: the suite's large paths)",
    "CHRONOCL_THREADS": "host threads (default: one per core)",
    "CHRONOCL_VERBOSE": "kernel build logs shown (set by the CLI's --verbose)",
    "CHRONOCL_SLAB_UPLOAD": "a refine's slabs uploaded as they integrate: 1 or 0 (default: "
    "where the engine writes the display format off the host's cores)",
    "CHRONOCL_VIEWER_TOKEN": "the viewer's token instead of a random one",
    "CHRONOCL_REMOTE_RETRIES": "retries of a remote read after the first try",
    "CHRONOCL_REMOTE_BACKOFF_S": "the first wait before a retry, in seconds",
    "CHRONOCL_TMPDIR": "where remote outputs are written before they are published",
    "POCL_MAX_PTHREAD_COUNT": "PoCL's threads (an out-of-core run counts them)",
    "POCL_CPU_MAX_CU_COUNT": "PoCL's compute units (the same, where the first is unset)",
}


def get(name: str) -> str:
    """The variable's value, stripped ("" where unset)."""
    if name not in VARIABLES:
        raise KeyError(f"{name} is not one of chronocl's variables (chronocl/core/env.py)")
    return os.environ.get(name, "").strip()


def set_value(name: str, value: str) -> None:
    """Set a variable for this process and the processes it starts (the CLI's --verbose)."""
    if name not in VARIABLES:
        raise KeyError(f"{name} is not one of chronocl's variables (chronocl/core/env.py)")
    os.environ[name] = value
