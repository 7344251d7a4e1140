"""Integration modes: one module per way of integrating through time, and their registry."""
