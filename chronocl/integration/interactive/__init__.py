"""Interactive integration: a session scrubs a window through time and keeps its chronovolume
up to date, sliding incrementally where it can (docs/architecture.md, "How a slide flows").

- `session`: `Session`, one level of a series; it owns a window manager (the resident steps)
  and a `Slider`; `SessionPool` and `auto_session` build the sessions of ``level="auto"``.
- `moves`: what both kinds of session share: the window or spec a move asks for, and the
  spec shown with its value range fixed.
- `slider`: `Slider`, the incremental state of one window under one spec, built from the
  series, the engine and the spec; its `Leaves` and `Combine` feed the sliding aggregate.
- `sliding`: `SlidingAggregate`, a window's aggregate under an associative operation that
  has no inverse, in O(sqrt W) partials.
- `levels`: `AutoSession` and its `LatencyModel`: the level drawn next, for a latency target.
"""
