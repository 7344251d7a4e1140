"""Events through time: the features of each step of a window (connected components of the
voxels it shows), matched by overlap into continuations, merges, splits, births, deaths and
exits, and into tracks.

    import chronocl
    graph = chronocl.events("vortex.zarr", "0:20", threshold=0.3)
    graph.events        # [{"kind": "merge", "step": 4, "next_step": 5, ...}, ...]
    graph.graph         # networkx.DiGraph: nodes (step, id), edges with overlap, similarity
    graph.save("events.json")
    chronocl.render(cv, colour="track", events=graph)   # cv: max, min, first_hit or change

Needs the ``events`` extra (``pip install 'chronocl[events]'``: connected-components-3d and
networkx), imported on first use. `features` labels one step, `tracking` matches steps and
classifies events, `graph` holds the result, `run` is the pipeline, `plot` draws it,
`colour` colours a chronovolume's voxels by the track that reached them (`track_colour`).
"""

from chronocl.events.colour import track_colour
from chronocl.events.graph import EventGraph, load_events
from chronocl.events.run import events

__all__ = ["EventGraph", "events", "load_events", "track_colour"]
