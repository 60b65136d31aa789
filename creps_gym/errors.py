"""The project's exceptions and warnings, one import address each (as Gymnasium's ``gymnasium.error``).

Imports nothing (no numpy, no Gymnasium), so every layer may use it: the optimisers, the envs, the runner
and the command line. Bad input elsewhere is a plain ``ValueError`` or ``TypeError`` naming the argument;
these classes mark what a caller may want to catch on its own:

* :class:`RunDirError`: a run directory (or a file in it) that cannot be used as it is (CLI exit code 3).
* :class:`RunDirWarning`: something in a run directory was repaired or recovered.
* :class:`EpisodeError`: an episode failed after all retries; the run cannot continue (CLI exit code 1).
* :class:`ConfigError` (:class:`ConfigTypeError`): a bad value of one field of a run's configuration,
  named by ``.field`` (the command line maps it to its flag; CLI exit code 2).
* :class:`UsageError`: a bad command line (CLI exit code 2).

This is their only address: no other module re-exports them (``tests/test_errors.py`` checks).
"""

from __future__ import annotations

from typing import Any

__all__ = ["ConfigError", "ConfigTypeError", "EpisodeError", "RunDirError", "RunDirWarning", "UsageError"]


class RunDirError(ValueError):
    """A run directory that cannot be used as it is: a damaged, foreign or locked file (CLI exit code 3)."""


class RunDirWarning(UserWarning):
    """Something in a run directory was repaired or recovered (what and how is in the message)."""


class EpisodeError(RuntimeError):
    """An episode failed after all retries (the message names it); the run cannot continue."""


class ConfigError(ValueError):
    """A bad value of one field of a configuration: a ``RunConfig`` field (e.g. ``samples``), or an option
    of an optimiser (e.g. ``epsilon``, raised by the optimiser itself when a batch shows it cannot work).

    ``field`` names the field (the command line names the flag that sets it), ``reason`` says what was
    expected and what was given; the message is ``"field: reason"`` unless given (a component's own error
    about the field, e.g. an optimiser's about one of ``optimizer_options``, keeps its message).
    """

    def __init__(self, field: str, reason: str, message: str | None = None) -> None:
        super().__init__(f"{field}: {reason}" if message is None else message)
        self.field, self.reason = field, reason

    def __reduce__(self) -> Any:  # pickled with its field (e.g. across processes)
        return type(self), (self.field, self.reason, str(self))


class ConfigTypeError(ConfigError, TypeError):
    """A :class:`ConfigError` about a value of the wrong type (also a ``TypeError``)."""


class UsageError(Exception):
    """A bad command line (exit code 2): every command module of :mod:`creps_gym.cli` raises this class."""
