"""`python -m chronocl.cli` runs the command line, as `python -m chronocl` does."""

from chronocl.cli import main

main()
