"""Figs 1-2 of the paper: the contextual test-function study (see README.md)."""
