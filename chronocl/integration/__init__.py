"""Integration: a window of a series into a chronovolume.

`inmemory` integrates a window at once (`integrate`), `interactive` keeps a moving window's
chronovolume up to date (`Session`), and `runs` integrates into a file larger than memory,
streamed or on dask.
"""
