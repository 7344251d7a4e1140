"""Readers for input formats (NetCDF, TIFF, OME-Zarr) that feed `chronocl ingest`."""
