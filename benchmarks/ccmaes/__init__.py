"""Issue 12: the C-CMA-ES target study (see README.md)."""
