"""`chronocl devices`: list the OpenCL platforms and devices, marking the default one."""

from __future__ import annotations

from chronocl.cli.options import err, out


def devices() -> None:
    """List the OpenCL platforms and devices, marking the default one.

    Select one with --device 0:1 (platform:device), a part of its name, or CHRONOCL_DEVICE.

    Example: chronocl devices
    """
    from chronocl.engine.device import (
        NO_PLATFORM,
        build_problem,
        list_devices,
        pick_device,
        usable_devices,
    )

    found = list_devices()
    if not found:
        err.print(f"chronocl: {NO_PLATFORM}", highlight=False, markup=False)
        return
    usable = {d.index for d in usable_devices()}
    default = pick_device(None)[0].index if usable else None
    for d in found:
        mark = "*" if d.index == default else " "
        problem = "" if d.index in usable else f"  cannot build kernels: {build_problem(d.index)}"
        out.print(
            f"{mark} {d.index}  {d.kind:<4} {d.label}  ({d.version}; driver {d.driver}; "
            f"{d.compute_units} compute units, {d.global_mem / 2**30:.1f} GiB){problem}",
            highlight=False,
        )
