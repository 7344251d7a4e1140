"""The `chronocl` command line: a thin layer over the public API.

`app` (chronocl.cli.app) holds the help and the global options; each command is one module
here that parses its options, calls the API and prints; `options` holds what they share.
`main` is the console entry point (`chronocl`, `python -m chronocl`).
"""

from chronocl.cli.app import app, main

__all__ = ["app", "main"]
