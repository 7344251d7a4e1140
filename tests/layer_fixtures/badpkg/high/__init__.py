"""Layer high: above low."""
