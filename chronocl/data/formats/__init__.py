"""The file formats chronocl reads and writes, one module each (OME-Zarr two: images read in
`omezarr`, chronovolumes written in `omezarr_chronovolume`), listed in `registry`."""
