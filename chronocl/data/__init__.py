"""Data: time series over zarr, ingest, z-slab bricks, built-in synthetic data."""
