"""Fit to window in the viewer: the data TF's value range fitted to a view's window and mode.

The range is the command line's and the API's (`chronocl.integration.fit_range.window_range`:
the median to the 99.9th percentile of what the mode shows over the selected steps), so a
viewer frame with a fitted TF is the picture `chronocl render` makes for the same window.

The viewer keeps the TF's curve as drawn (its points over u in [0, 1]) and fits by giving the
TF that range (`DataTF.value_range = (lo, hi)`): the TF editor draws the curve over the
series' range, where u = 0 and u = 1 of the curve land on lo and hi (tf_editor.js). Fitting
again, after the window or the mode changed, gives the same curve another range; nothing is
squeezed twice. A data set opens fitted to its first window and first view's mode, as the
command line fits its default curve (`fitted_default`; not where a page reconnecting reopens
it: the page sends back the state it had); the page fits again when the first view's mode
changes while the curve is still the default one, and on the Fit button.
"""

from __future__ import annotations

import dataclasses

from chronocl import modes
from chronocl.core.errors import InvalidParameterError
from chronocl.data.series import TimeSeries
from chronocl.integration.fit_range import window_range
from chronocl.viewer.view_state import ViewState


def fitted_range(
    series: TimeSeries, state: ViewState, view: int = 0, mode: str | None = None
) -> tuple[float, float]:
    """The value range fitted to `view`'s window in `state` for `mode` (default: the view's)."""
    if not 0 <= view < len(state.views):
        raise InvalidParameterError(
            f"view {view + 1} is not shown ({len(state.views)} views); fit a view on the page"
        )
    name = mode or state.views[view][0]
    return window_range(series, state.selection(series.n_steps, view), modes.get(name))


def fitted_default(series: TimeSeries, state: ViewState) -> ViewState:
    """`state` with its data TF's curve over the range fitted to its first view's window and
    mode (a data set's first picture, as `chronocl render` draws the default curve)."""
    tf = dataclasses.replace(state.data_tf, value_range=fitted_range(series, state))
    return dataclasses.replace(state, data_tf=tf)


def fit_reply(msg: dict, state: ViewState, series: TimeSeries) -> dict:
    """The answer to a `fit` message: the range for the view's window and the mode asked
    (default: the view's), with the window and mode it was fitted to."""
    view = msg.get("view", 0)
    mode = msg.get("mode") or (state.views[view][0] if view < len(state.views) else None)
    lo, hi = fitted_range(series, state, view, mode)
    t0, t1, stride = state.own_window(view) or state.window
    return {
        "type": "fit",
        "id": msg.get("id"),
        "view": view,
        "mode": mode,
        "window": [t0, t1, stride],
        "range": [lo, hi],
    }
