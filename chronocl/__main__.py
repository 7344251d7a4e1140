"""`python -m chronocl` runs the command line."""

from .cli import main

main()
