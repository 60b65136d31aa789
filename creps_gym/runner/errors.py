"""The run directory's error and warning classes (a module of their own: every runner module uses them)."""

from __future__ import annotations

__all__ = ["RunDirError", "RunDirWarning"]


class RunDirError(ValueError):
    """A run directory that cannot be used as it is: a damaged, foreign or locked file (CLI exit code 3)."""


class RunDirWarning(UserWarning):
    """Something in a run directory was repaired or recovered (what and how is in the message)."""
