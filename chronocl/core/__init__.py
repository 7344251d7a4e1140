"""Core: errors, selections, transfer functions, enhancement, budgets, safe writes, progress."""
