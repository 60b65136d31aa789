"""Callbacks of the runner, and the tqdm progress bar.

A callback is a :class:`Callback` (with ``on_start``, ``on_iteration`` and ``on_end``) or a plain callable
``f(record, history) -> bool | None`` used as ``on_iteration``. Returning True from ``on_iteration`` stops
the run after the current iteration (stop reason ``"callback"``).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from typing import Any

from creps_gym.optimizers.adapters.base import import_optional
from creps_gym.runner.history import History, IterationRecord

__all__ = ["Callback", "ProgressBar", "as_callback"]


class Callback:
    """Base class: override the hooks you need."""

    def on_start(self, history: History, total_iterations: int) -> None:
        """Called once before the first iteration of this session (``history`` may hold resumed records)."""

    def on_iteration(self, record: IterationRecord, history: History) -> bool | None:
        """Called after each iteration (``record`` is already in ``history``); return True to stop."""
        return None

    def on_end(self, history: History) -> None:
        """Called once when the run stops (normally or with an error)."""


class _FunctionCallback(Callback):
    def __init__(self, function: Callable[[IterationRecord, History], Any]) -> None:
        self.function = function

    def on_iteration(self, record: IterationRecord, history: History) -> bool | None:
        return bool(self.function(record, history))


def as_callback(callback: Callback | Callable[[IterationRecord, History], Any]) -> Callback:
    """A :class:`Callback` from a callback or a plain callable (``TypeError`` otherwise)."""
    if isinstance(callback, Callback):
        return callback
    if callable(callback):
        return _FunctionCallback(callback)
    raise TypeError(f"callbacks: expected Callback instances or callables, got {type(callback).__name__}")


class ProgressBar(Callback):
    """A tqdm bar over iterations showing the latest evaluated regret (or return) and the sample return.

    Parameters
    ----------
    enabled : bool or None
        None (default): show the bar only when standard error is a terminal (and tqdm is installed);
        True: always (``ImportError`` without tqdm, ``pip install creps-gym[cli]``); False: never.
    stream : file-like, optional
        Where to draw (default ``sys.stderr``).
    """

    def __init__(self, enabled: bool | None = None, stream: Any = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = bool(isatty and isatty()) if enabled is None else bool(enabled)
        self._required = bool(enabled)
        self._bar: Any = None
        self._shown: dict[str, str] = {}

    def on_start(self, history: History, total_iterations: int) -> None:
        if not self.enabled:
            return
        try:
            tqdm = import_optional("tqdm", "cli").tqdm
        except ImportError:
            if self._required:
                raise
            self.enabled = False
            return
        self._bar = tqdm(
            total=total_iterations, initial=len(history), file=self.stream, unit="it", dynamic_ncols=True
        )

    def on_iteration(self, record: IterationRecord, history: History) -> bool | None:
        if self._bar is None:
            return None
        if not math.isnan(record.eval_regret):
            self._shown = {"regret": f"{record.eval_regret:.3g}"}
        elif not math.isnan(record.eval_return):
            self._shown = {"eval return": f"{record.eval_return:.4g}"}
        self._bar.set_postfix({**self._shown, "sample return": f"{record.mean_return:.4g}"}, refresh=False)
        self._bar.update(1)
        return None

    def on_end(self, history: History) -> None:
        """Close the bar; a finished run's bar ends at 100% with its stop reason (an early stop too)."""
        if self._bar is None:
            return
        if history.stop_reason is not None:
            self._bar.total = self._bar.n
            self._bar.set_postfix({**self._shown, "stop": history.stop_reason}, refresh=False)
        self._bar.close()
        self._bar = None
