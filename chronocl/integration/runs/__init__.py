"""Integration runs into a file, larger than memory: the slabs planned under a memory budget
(`plan`), integrated by an executor in this process (`local`) or on a dask cluster
(`distributed`), written to a resumable store (`runstore`, `streaming`); `auto` picks where a
run goes (in memory, streamed or on dask)."""
