"""chronocl: chronovolumes of time-varying volume data (Woodring & Shen 2003) on OpenCL.

A window of time steps is integrated along time, through a temporal transfer
function, into one RGBA volume that can be raycast from any view.

    import chronocl
    series = chronocl.open("vortex.zarr")
    cv = chronocl.integrate(series, "0:30:10", mode="alpha", time_tf="rgb")
    cv.save("vortex-alpha.zarr")

    session = chronocl.Session(series, memory="2GB", mode="max", time_tf="rgb")
    cv = session.set_window(0, 16)
    cv = session.slide(+1)          # incremental with absolute time positions

    graph = chronocl.events(series, "0:20", threshold=0.3)  # features, events, tracks

    image = chronocl.render_slice(cv, "z=40")  # a plane: colours and the winning step
    w = chronocl.show(series)       # the viewer in a notebook cell (the `notebook` extra)
"""

from chronocl.core.enhance import Enhance
from chronocl.core.errors import ChronoclError
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF, TFSetting, TimeAlpha, TimeColor, TimeTF
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.probe import TimeCurve, probe
from chronocl.data.series import TimeSeries, open_series
from chronocl.data.window import WindowManager
from chronocl.events import EventGraph, events, load_events
from chronocl.integration.inmemory import integrate, make_spec
from chronocl.integration.interactive.session import Session
from chronocl.modes.spec import IntegrationSpec
from chronocl.notebook import show
from chronocl.render import Camera, render, render_views
from chronocl.render.slices import render_slice, slice_value

open = open_series

__version__ = "0.1.0"
__all__ = [
    "Camera",
    "ChronoclError",
    "Chronovolume",
    "DataTF",
    "Enhance",
    "EventGraph",
    "IntegrationSpec",
    "Selection",
    "Session",
    "TFSetting",
    "TimeAlpha",
    "TimeColor",
    "TimeCurve",
    "TimeSeries",
    "TimeTF",
    "WindowManager",
    "__version__",
    "events",
    "integrate",
    "load_events",
    "make_spec",
    "open",
    "open_series",
    "probe",
    "render",
    "render_slice",
    "render_views",
    "show",
    "slice_value",
]
