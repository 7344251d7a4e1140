"""Interactive integration: a session scrubs a window through time and keeps its chronovolume
up to date, sliding incrementally where it can (docs/architecture.md, "How a slide flows").

- `session`: `Session`, what a viewer or notebook moves: a level policy (`FixedLevel`, or
  `LatencyModel`: the level drawn next, for a latency target) over the sessions of the levels
  it shows, and the moves, written once.
- `level_session`: `LevelSession`, one level of a series; it owns a window manager (the
  resident steps) and a `Slider`; `SessionPool` builds one per level and pooling shown.
- `moves`: the window or spec a move asks for, and the spec shown with its value range fixed.
- `costs`: `Costs`, the rates measured on the machine at hand (integrating, sliding, reading,
  displaying) that the level drawn, slide or integrate, and read ahead or not are chosen by.
- `slider`: `Slider`, the incremental state of one window under one spec, built from the
  series, the engine and the spec; its `Leaves` and `Combine` feed the sliding aggregate.
- `sliding`: `SlidingAggregate`, a window's aggregate under an associative operation that
  has no inverse, in O(sqrt W) partials.
"""
