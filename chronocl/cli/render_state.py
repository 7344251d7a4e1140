"""`chronocl render --state SESSION.json`: draw what the viewer showed when its state was
saved as a snapshot (Save session; chronocl/viewer/snapshot.py): the same data set, window,
views, camera, transfer functions, clip, box outline and size, as the viewer's Save PNG draws
it: each view with its own window, camera and TFs where it had them.
Options given on the command line override the snapshot's fields (a camera option every view's
camera, a TF option every view's TF; --colormap recolours each view's own curve, its opacity
kept); the axis triad is drawn only when --axes is given (the Save PNG has none)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from chronocl.cli.options import err, parse_floats, parse_order, parse_shading, parse_sizes
from chronocl.core.errors import InvalidParameterError

# Options that do not apply to a snapshot's render (its integration and draw are the viewer's).
NOT_WITH_STATE = (
    "turntable",
    "save_chronovolume",
    "level",
    "device_format",
    "frames",
    "variables",
    "events",
    "colour",
)


def given(ctx, params: dict) -> dict:
    """The options of `params` given on the command line (not left at their defaults)."""
    # By name: typer's ParameterSource is its own enum, not click's.
    source = ctx.get_parameter_source
    return {
        k: v
        for k, v in params.items()
        if k != "ctx" and getattr(source(k), "name", None) == "COMMANDLINE"
    }


def render_state(state_path: Path, options: dict) -> None:
    """Render the snapshot (session file) in `state_path`; `options` are those given on the
    command line."""
    from chronocl.core.paths import check_target
    from chronocl.core.tf import TFSetting, TimeTF
    from chronocl.core.time_labels import check_prefer
    from chronocl.data.series import open_series
    from chronocl.render.raycaster import check_clip, check_size
    from chronocl.render.views import parse_color
    from chronocl.viewer.snapshot import (
        dataset_path,
        read_snapshot,
        render_snapshot,
        snapshot_state,
    )

    for name in NOT_WITH_STATE:
        if name in options:
            flag = "--" + name.replace("_", "-")
            raise InvalidParameterError(f"{flag} does not combine with --state; leave it out")
    snapshot = read_snapshot(state_path)
    store = options.get("store") or dataset_path(snapshot, state_path.name)
    out = options.get("out_path") or state_path.with_suffix(".png")
    overwrite = bool(options.get("overwrite", False))
    check_target(out, overwrite, [store, state_path, options.get("tf")])
    fields = _snapshot_fields(snapshot, options)
    series = open_series(store)
    state = snapshot_state(snapshot | fields, series)
    replace: dict = {}
    if "size" in options:
        replace["size"] = check_size(parse_sizes(options["size"], 2, "WxH", "512x512"))
    if "clip" in options:
        replace["clip"] = check_clip(parse_floats(options["clip"], 4, "clip"))
    if "background" in options:
        parse_color(options["background"])
        replace["background"] = options["background"]
    if "shading" in options or "shading_params" in options:
        lit = parse_shading(options.get("shading", False), options.get("shading_params"))
        replace["shading"] = lit
    if "frame" in options:  # the shared camera and each view's own
        replace["camera"] = dataclasses.replace(state.camera, frame=options["frame"])
        replace["view_cameras"] = tuple(
            None if c is None else dataclasses.replace(c, frame=options["frame"])
            for c in state.view_cameras
        )
    state = dataclasses.replace(state, **replace)
    time_labels = options.get("time_labels", "labels")
    check_prefer(time_labels)
    setting = TFSetting.load(options["tf"]) if "tf" in options else None
    changes = []
    for view in range(len(state.views)):  # each view's own TFs where it has them
        time_tf = TimeTF.preset(options["time_tf"]) if "time_tf" in options else None
        data_tf = setting.data_tf if setting else None
        if "colormap" in options:  # the view's curve recoloured, its opacity kept
            data_tf = (data_tf or state.data_tf_of(view)).with_colormap(options["colormap"])
        time_tf = time_tf or (setting.time_tf if setting else None)
        if time_tf is None and data_tf is not None:
            time_tf = _following(state.time_tf_object(view), data_tf)
        spec = {"data_tf": data_tf, "time_tf": time_tf, "normalize": options.get("normalize")}
        changes.append({k: v for k, v in spec.items() if v is not None})
    t0 = time.perf_counter()
    image = render_snapshot(
        state,
        series,
        engine=options.get("engine", "opencl"),
        device=options.get("device"),
        time_labels=time_labels,
        axes=bool(options.get("axes", False)),
        name=snapshot["dataset"]["name"],
        changes=changes,
    )
    image.save(out, overwrite=overwrite)
    modes = ", ".join(m for m, _ in state.views)
    err.print(f"wrote {out} ({modes} from {state_path.name}; {time.perf_counter() - t0:.2f} s)")


def _following(time_tf, data_tf):
    """The snapshot's time TF with its colours following a new data TF as where none is chosen
    (`TimeTF.for_data`: lightness under a colour map, rgb under grey), if they are one of
    those two; None where the snapshot chose others (kept)."""
    from chronocl.core.tf import TimeTF

    if time_tf.color.preset not in ("rgb", "lightness"):
        return None
    return dataclasses.replace(time_tf, color=TimeTF.for_data(data_tf.points).color)


def _snapshot_fields(snapshot: dict, options: dict) -> dict:
    """The snapshot fields that command-line options replace (in the snapshot's terms)."""
    fields: dict = {}
    views = [dict(v) for v in snapshot["views"]]
    if "mode" in options:
        names = [m.strip() for item in options["mode"] for m in item.split(",") if m.strip()]
        order = views[0].get("order", "forward")
        # view i keeps its own window, camera and TFs; views beyond the snapshot's are linked
        views = [
            (views[i] if i < len(views) else {"order": order}) | {"mode": m}
            for i, m in enumerate(names)
        ]
    if "order" in options:
        order = parse_order(options["order"])
        if not isinstance(order, str):
            raise InvalidParameterError("with --state, --order is forward or backward")
        views = [v | {"order": order} for v in views]
    fields["views"] = views
    if "window" in options:
        parts = str(options["window"]).split(":")
        try:
            t0, t1, *rest = (int(p) for p in parts)
        except ValueError:
            t0 = t1 = -1
            rest = []
        if len(parts) not in (2, 3) or t0 < 0:
            raise InvalidParameterError(
                f"with --state, --window is t0:t1[:stride], e.g. 0:10:2; got {options['window']!r}"
            )
        fields["window"] = {"t0": t0, "t1": t1, "stride": rest[0] if rest else 1}
        for v in views:  # every view shows it (a view's own window is let go)
            v["window"] = None
    camera = dict(snapshot["camera"])
    if "up" in options:
        from chronocl.render.camera import Camera

        Camera(up=options["up"])  # an unknown axis is named as on the command line
    given_camera = {
        k: options[k] for k in ("azimuth", "elevation", "zoom", "projection", "up") if k in options
    }
    fields["camera"] = camera | given_camera
    if given_camera:  # a view's own camera takes them too
        for v in views:
            if v.get("camera") is not None:
                v["camera"] = dict(v["camera"]) | given_camera
    if "enhance" in options:
        fields["enhance"] = {"kind": options["enhance"]}
    fields |= {k: options[k] for k in ("threshold", "outline") if k in options}
    return fields
