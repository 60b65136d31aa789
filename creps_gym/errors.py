"""The project's exceptions and warnings, one import address each (as Gymnasium's ``gymnasium.error``).

Imports nothing (no numpy, no Gymnasium), so every layer may use it: the optimisers, the envs, the runner
and the command line. Bad input elsewhere is a plain ``ValueError`` or ``TypeError`` naming the argument;
these classes mark what a caller may want to catch on its own:

* :class:`RunDirError`: a run directory (or a file in it) that cannot be used as it is (CLI exit code 3).
* :class:`RunDirWarning`: something in a run directory was repaired or recovered.
* :class:`EpisodeError`: an episode failed after all retries; the run cannot continue (CLI exit code 1).

The modules that defined them before re-export them (``creps_gym.runner``, ``creps_gym.runner.errors``,
``creps_gym.runner.session``, ``creps_gym.runner.rundir``, ``creps_gym.runner.episodes`` and
``creps_gym.runner.backends``): the same classes, so ``except`` clauses written against any of them match.
"""

from __future__ import annotations

__all__ = ["EpisodeError", "RunDirError", "RunDirWarning"]


class RunDirError(ValueError):
    """A run directory that cannot be used as it is: a damaged, foreign or locked file (CLI exit code 3)."""


class RunDirWarning(UserWarning):
    """Something in a run directory was repaired or recovered (what and how is in the message)."""


class EpisodeError(RuntimeError):
    """An episode failed after all retries (the message names it); the run cannot continue."""
