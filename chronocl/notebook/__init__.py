"""The viewer in a notebook: `show(data)` returns a widget (anywidget) with the browser
viewer's controls in the cell output, rendered in the kernel's process and streamed over the
widget's comm (docs/notebook.md). Needs the `notebook` extra: pip install 'chronocl[notebook]'.

    import chronocl
    w = chronocl.show("vortex.zarr")
    w.mode = "max"               # the picture follows; so do w.window, w.data_tf, ...
    w.observe(print, "window")   # the page's edits come back
    w.screenshot()               # a PNG of the views shown
    w.probe((x, y, z))           # v(t) there, as the page's probe plots it

Several widgets in one kernel share its memory limit and a series' resident steps
(`chronocl.notebook.kernel`).
"""

from __future__ import annotations

import os

from chronocl.core.errors import InvalidParameterError


def show(
    data: object,
    *,
    name: str | None = None,
    window: tuple | None = None,
    mode: str | None = None,
    engine: str = "opencl",
    device: str | None = None,
    memory: str | int | None = None,
    height: int = 620,
    storage_options: dict | None = None,
    **array_options,
):
    """The viewer of `data` in the notebook: a TimeSeries, a store's path or URL (http://,
    https:// or s3://, read in place with `storage_options` as `chronocl.open` takes them:
    s3fs's `anon`, `endpoint_url`, `key`, `secret`; HTTP's client arguments), or a numpy, dask
    or xarray array (T, Z, Y, X; `array_options`: spacing, times, time_unit, resample, as
    `TimeSeries.from_array` takes them). `name` names the data set; `window` ((t0, t1[,
    stride])) and `mode` are set before the first picture's page shows it; `height` is the
    widget's height in CSS pixels. The widget's attributes (window, mode, views, data_tf,
    time_tf, camera) follow the page and set it. `memory` is the kernel's memory limit for
    every widget's steps and frames (the newest given; docs/notebook.md). Nothing is drawn
    until a page shows the widget or the kernel asks for a picture. Raises ChronoclError
    subclasses, in one line: the extra missing; bad data (a Chronovolume: the call that shows
    the series it came from; a URL of another scheme or without a host, or storage options
    for anything but a URL, checked before anything is opened; a store missing, unreachable
    or refused, as `chronocl.open` says it); no OpenGL in the kernel."""
    try:
        import anywidget  # noqa: F401
    except ImportError:
        raise InvalidParameterError(
            "chronocl.show needs the notebook extra: pip install 'chronocl[notebook]'"
        ) from None
    from chronocl.notebook.data import as_dataset, check_store, store_key
    from chronocl.notebook.widget import ChronoclWidget
    from chronocl.viewer.server import check_options

    if isinstance(height, bool) or not isinstance(height, int) or not 200 <= height <= 4000:
        raise InvalidParameterError(f"height {height!r} must be an integer of 200..4000 pixels")
    # as `chronocl view` checks them, before any data is read (a bad engine made a widget
    # whose frames never came, the cause never said)
    check_options(engine=engine, device=device, memory=memory)
    data = check_store(data, storage_options)  # a URL it cannot read: one line, nothing opened
    storage_options = None if storage_options is None else dict(storage_options)
    dataset = as_dataset(data, name, storage_options, **array_options)
    store = store_key(data, storage_options) if isinstance(data, str | os.PathLike) else None
    widget = ChronoclWidget(
        dataset, engine=engine, device=device, memory=memory, height=height, store=store
    )
    try:
        if window is not None:
            widget.window = window
        if mode is not None:
            widget.mode = mode
    except Exception:
        widget.close()
        raise
    widget.warm()  # its window integrated while the page loads, the one asked for
    return widget


__all__ = ["show"]
