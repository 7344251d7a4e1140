"""Layer low: the bottom of the fixture."""
