"""Fit to window in the viewer, without a browser: a data set opens with its data TF fitted as
the command line fits it, and the `fit` message answers the range `fit_range.window_range`
gives for the same window and mode (a view's own window, a mode asked for, a bad view); a
reopen for a page's restore (`"fit": false`) is not fitted."""

from __future__ import annotations

import json
import urllib.request

import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")


from .viewer_helpers import (  # noqa: F401
    Client,
    connected_client,
    fitted,
    plume_steps,
    plume_store,
    serving,
)


@pytest.fixture(scope="module")
def plume(tmp_path_factory):
    return plume_store(tmp_path_factory, "viewer-fit")


@pytest.fixture(scope="module")
def server(plume):
    yield from serving([plume], gl_current=True)


def saved_session(server, client: Client) -> dict:
    rid = client.send({"type": "save", "what": "session"})
    _, msg = client.wait("download", rid)
    req = urllib.request.Request(
        server.base + msg["url"], headers={"X-Chronocl-Token": server.token}
    )
    with urllib.request.urlopen(req, timeout=30) as r:
        return json.loads(r.read())


def fit(client: Client, **msg) -> dict:
    rid = client.send({"type": "fit", **msg})
    return client.wait("fit", rid)[1]


def test_the_plume_is_faint_early():
    data = plume_steps()
    assert data[0].max() < 0.15 * data.max()


def test_a_data_set_opens_fitted_to_its_first_window_and_mode(client, plume):
    ds, (_, header, _) = client.open(0)
    state = ds["state"]
    mode = state["views"][0]["mode"]
    w = state["window"]
    assert (w["t0"], w["t1"]) == (0, 10)  # the whole run: step 0 is in the first picture
    want = fitted(plume, 0, 10, mode)
    assert state["data_tf"]["value_range"] == pytest.approx(want, rel=1e-12)
    assert ds["fitted"]["range"] == state["data_tf"]["value_range"]
    assert ds["fitted"]["window"] == [0, 10, 1] and ds["fitted"]["mode"] == mode
    # The fitted range lies inside the series' (the editor's axis) and well under its top.
    assert ds["vmin"] <= want[0] < want[1] < 0.7 * ds["vmax"]
    # Fitting again for the same window and mode gives the same range: nothing moves.
    assert fit(client, view=0)["range"] == state["data_tf"]["value_range"]
    assert header["quality"] in ("full", "preview")


def test_fit_answers_the_ranges_fit_range_gives(client, plume):
    client.open(0)
    # The shared window moved: the TF keeps its range until it is fitted again.
    rid = client.send({"type": "update", "window": {"t0": 0, "t1": 2}})
    client.frame_for(rid)
    got = fit(client, view=0)
    assert got["window"] == [0, 2, 1] and got["mode"] == "alpha" and got["view"] == 0
    assert got["range"] == pytest.approx(fitted(plume, 0, 2, "alpha"), rel=1e-12)
    # Another mode, asked for (the page's refit on a mode change, before it sends the mode).
    for mode in ("max", "min", "additive", "change"):
        want = fitted(plume, 0, 2, mode)
        assert fit(client, view=0, mode=mode)["range"] == pytest.approx(want, rel=1e-12)
    # A view with its own window, and a second view following the shared one.
    views = [{"mode": "max", "window": {"t0": 3, "t1": 9, "stride": 2}}, {"mode": "min"}]
    rid = client.send({"type": "update", "views": views})
    client.frame_for(rid)
    own = fit(client, view=0)
    assert own["window"] == [3, 9, 2] and own["mode"] == "max"
    assert own["range"] == pytest.approx(fitted(plume, 3, 9, "max", 2), rel=1e-12)
    shared = fit(client, view=1)
    assert shared["window"] == [0, 2, 1] and shared["mode"] == "min"
    assert shared["range"] == pytest.approx(fitted(plume, 0, 2, "min"), rel=1e-12)
    # A view not shown: one line naming it; the socket keeps serving.
    rid = client.send({"type": "fit", "view": 3})
    err = client.wait("error", rid)[1]
    assert "view 4 is not shown" in err["message"] and "\n" not in err["message"]
    assert fit(client, view=1)["range"] == shared["range"]


def test_a_fitted_range_renders_as_given_and_saves_with_the_session(server, client, plume):
    client.open(0)
    got = fit(client, view=0, mode="max")
    points = [[0, 1, 1, 1, 0], [0.05, 1, 1, 1, 0], [0.3, 1, 1, 1, 0.25], [1, 1, 1, 1, 0.9]]
    rid = client.send(
        {
            "type": "update",
            "views": [{"mode": "max"}],
            "data_tf": {"points": points, "value_range": got["range"]},
        }
    )
    _, header, _ = client.frame_for(rid)
    assert header["views"][0]["note"] in ("", None)  # not an empty picture
    assert saved_session(server, client)["data_tf"]["value_range"] == got["range"]
    # A TF sent without a range is over the series' range again.
    rid = client.send({"type": "update", "data_tf": {"points": points}})
    client.frame_for(rid)
    assert "value_range" not in saved_session(server, client)["data_tf"]


def test_a_reopen_for_a_restore_is_not_fitted(server, client):
    """`open` with "fit": false (a page reconnecting, which sends back the state it had next):
    the data set's defaults, the TF not fitted, no fit in the reply; a fit flag that is not a
    boolean is refused in one line."""
    fitted_open, _ = client.open(0)
    rid = client.send({"type": "open", "dataset": 0, "fit": False})
    _, ds = client.wait("dataset", rid)
    assert "fitted" not in ds and ds["state"]["data_tf"].get("value_range") is None
    assert ds["state"]["views"] == fitted_open["state"]["views"]
    assert "value_range" not in saved_session(server, client)["data_tf"]
    # The page's state sent back: the fitted range it had is the state's again.
    got = fitted_open["state"]["data_tf"]
    rid = client.send({"type": "update", "data_tf": got, "size": [128, 128]})
    client.frame_for(rid)
    assert saved_session(server, client)["data_tf"]["value_range"] == got["value_range"]
    rid = client.send({"type": "open", "dataset": 0, "fit": "no"})
    err = client.wait("error", rid)[1]
    assert "fit" in err["message"] and "\n" not in err["message"]
