"""The run directory's error and warning classes, re-exported from :mod:`creps_gym.errors`, their home."""

from __future__ import annotations

from creps_gym.errors import RunDirError, RunDirWarning

__all__ = ["RunDirError", "RunDirWarning"]
