"""The known-bad package's face (its top layer): one case per layer rule, each in its own module
under `low/` (layer low) or `high/` (layer high). tests/test_layers.py names the expected lines."""
