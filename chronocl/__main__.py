"""`python -m chronocl` runs the command line."""

from chronocl.cli import main

main()
