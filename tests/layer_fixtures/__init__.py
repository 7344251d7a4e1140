"""Known-bad fixtures that tests/test_layers.py must reject: `badpkg` (Python) and `badjs`
(the viewer's ES module rules). Read as source only, never imported."""
