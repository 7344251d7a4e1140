"""Integration runs: in memory, interactive sessions with sliding windows, out of core, on dask."""
