"""The scalability report (`chronocl bench`): integration throughput against window size,
strong and weak scaling over dask workers, per device (docs/scaling.md). It measures
(`scaling`), runs the cells and writes the folder (`scaling_run`) and draws the figures and
index.html (`scaling_report`), on top of the out-of-core runs (`chronocl.integration.runs`)."""
