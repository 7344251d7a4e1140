"""`chronocl devices`: list the OpenCL platforms and devices, marking the default one."""

from __future__ import annotations

from chronocl.cli.options import err, out


def devices() -> None:
    """List the OpenCL platforms and devices, marking the default one.

    Select one with --device 0:1 (platform:device), a part of its name, or CHRONOCL_DEVICE.

    Example: chronocl devices
    """
    from chronocl.engine.device import NO_PLATFORM, list_devices, pick_device

    found = list_devices()
    if not found:
        err.print(f"chronocl: {NO_PLATFORM}", highlight=False, markup=False)
        return
    default = pick_device(None)[0].index
    for d in found:
        mark = "*" if d.index == default else " "
        out.print(
            f"{mark} {d.index}  {d.kind:<4} {d.label}  ({d.version}; driver {d.driver}; "
            f"{d.compute_units} compute units, {d.global_mem / 2**30:.1f} GiB)",
            highlight=False,
        )
