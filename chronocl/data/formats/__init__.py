"""The file formats chronocl reads and writes, one module each, listed in `registry`."""
