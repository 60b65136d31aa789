"""How a batch of episodes runs, shared by every backend: the env source, the retry policy, the episode
checks and the :class:`Backend` base class.

The failure policy is described in :mod:`creps_gym.runner.backends`, which builds the backends
(:func:`~creps_gym.runner.backends.make_backend`) and re-exports these names; the concrete backends
(:mod:`creps_gym.runner.backends`' serial one, :mod:`.vector`, :mod:`.ray`) import them from here, so that
no backend module imports the module that builds it.
"""

from __future__ import annotations

import importlib
import math
import numbers
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.errors import EpisodeError

__all__ = [
    "Array",
    "Backend",
    "EnvSource",
    "check_context",
    "episode_return",
    "reset_context",
    "retry",
    "run_episodes",
]

Array = NDArray[np.float64]


@dataclass
class EnvSource:
    """How a worker builds its env: a registered id with kwargs, or an env object (copied to workers)."""

    env_id: str | None = None
    kwargs: dict[str, Any] = field(default_factory=dict)
    env: Any = None
    #: Episodes reset with ``options={"context": ...}`` as well as their seed (batched context draws).
    set_context: bool = False

    def make(self) -> gym.Env:
        """A fresh env (the object itself for object sources)."""
        return gym.make(self.env_id, **self.kwargs) if self.env_id is not None else self.env

    def registered_spec(self) -> Any:
        """The registry's ``EnvSpec`` of the id; a ``module:Env-v0``'s module is imported first, as
        ``gymnasium.make`` does."""
        module, _, name = str(self.env_id).rpartition(":")
        if module:
            importlib.import_module(module)
        return gym.spec(name)

    def spec(self) -> Any:
        """What ``gymnasium.make_vec`` takes: the id, or the object's spec (TypeError if it has none)."""
        if self.env_id is not None:
            return self.env_id
        if getattr(self.env, "spec", None) is None:
            raise TypeError(
                "env: the vector backend expected a registered env id or an env made by gymnasium.make "
                f"(with a spec), got {type(self.env).__name__} without a spec"
            )
        return self.env.spec


def _episode_text(label: str, index: int, seed: int, context: Array) -> str:
    return f"{label}, episode {index} (reset seed {seed}, context {np.asarray(context).tolist()})"


def check_context(obs: Any, context: Array, where: str) -> None:
    """Raise :class:`EpisodeError` unless a reset's observation ``obs`` is the recorded ``context``."""
    got = np.asarray(obs, dtype=np.float64).reshape(-1)
    if not np.array_equal(got, np.asarray(context).reshape(-1)):
        raise EpisodeError(
            f"{where}: reset(seed=...) gave context {got.tolist()}, expected the recorded "
            f"{np.asarray(context).tolist()}; the env must be deterministic under reset(seed=...)"
        )


def retry(
    call: Callable[[], Any],
    attempts: int,
    *,
    on_failure: Callable[[], None] | None = None,
    reraise: tuple[type[Exception], ...] = (EpisodeError,),
) -> tuple[bool, Any, Exception | None]:
    """Call ``call()`` up to ``attempts`` times: ``(True, value, None)``, or ``(False, None, last error)``.

    Exceptions in ``reraise`` (by default ``EpisodeError``: an episode already named) propagate at once;
    ``on_failure`` runs after each other failure (e.g. to rebuild a broken vector env).
    """
    last: Exception | None = None
    for _ in range(attempts):
        try:
            return True, call(), None
        except reraise:
            raise
        except Exception as exc:  # any failure of user env code is retried, then reported by the caller
            last = exc
            if on_failure is not None:
                on_failure()
    return False, None, last


def episode_return(reward: Any) -> float:
    """An episode's reward as a float: a finite real number (a Python or numpy int or float, or a
    one-element real array). A str, bool, None or complex reward raises TypeError (never 1.0 or a parsed
    string), a NaN or infinite one ValueError."""
    if isinstance(reward, np.ndarray) and reward.size == 1 and reward.dtype.kind in "fiu":
        reward = reward.reshape(())[()]
    if isinstance(reward, (bool, np.bool_)) or not isinstance(reward, numbers.Real):
        raise TypeError(f"reward: expected a real number, got {type(reward).__name__} {reward!r}")
    try:
        value = float(reward)
    except OverflowError:  # a Python int beyond the float range
        raise ValueError(
            f"reward: expected a finite return, got an integer of {len(str(abs(int(reward))))} digits"
        ) from None
    if not math.isfinite(value):
        raise ValueError(f"expected a finite return, got {value}")
    return value


def reset_context(env: gym.Env, seed: int, retries: int, where: str) -> Any:
    """``env.reset(seed=seed)``'s observation, the reset retried like an episode (EpisodeError at the end).

    ``where`` names the episode in the error (e.g. ``"iteration 3, episode 2"``).
    """
    ok, obs, last = retry(lambda: env.reset(seed=int(seed))[0], retries + 1)
    if not ok:
        raise EpisodeError(
            f"{where} (reset seed {seed}): reset failed {retries + 1} time(s); "
            f"last error: {type(last).__name__}: {last}"
        ) from last
    return obs


def _one_episode(env: gym.Env, seed: int, context: Array, params: Array, set_context: bool) -> float:
    obs, _ = env.reset(seed=int(seed), options={"context": context} if set_context else None)
    check_context(obs, context, "reset")
    _, reward, terminated, truncated, _ = env.step(params)
    if not (terminated or truncated):
        raise RuntimeError("expected a one-step episode (terminated or truncated after the first step)")
    return episode_return(reward)


def run_episodes(
    env: gym.Env,
    seeds: Any,
    contexts: Array,
    params: Array,
    *,
    first: int,
    label: str,
    retries: int,
    set_context: bool = False,
) -> Array:
    """Run episodes one by one with the retry policy of :mod:`creps_gym.runner.backends`.

    Parameters
    ----------
    env : gymnasium.Env
    seeds : array_like of int, shape (n,)
    contexts : ndarray, shape (n, z)
        The recorded contexts (checked against each reset).
    params : ndarray, shape (n, p)
    first : int
        Index of the first episode within the iteration (for error messages).
    label : str
        E.g. ``"iteration 3"``.
    retries : int
    set_context : bool
        Reset with ``options={"context": ...}`` too (the contexts came from a batched draw).

    Returns
    -------
    ndarray, shape (n,)
    """
    returns = np.empty(len(seeds))
    for k, seed in enumerate(seeds):
        where = _episode_text(label, first + k, int(seed), contexts[k])
        try:
            ok, value, last = retry(
                lambda k=k, seed=seed: _one_episode(env, int(seed), contexts[k], params[k], set_context),
                retries + 1,
            )
        except EpisodeError as exc:
            raise EpisodeError(f"{where}: {exc}") from None
        if not ok:
            raise EpisodeError(
                f"{where} failed {retries + 1} time(s); last error: {type(last).__name__}: {last}"
            ) from last
        returns[k] = value
    return returns


class Backend(ABC):
    """Runs a batch of episodes and returns their returns, in order."""

    name: str = "base"

    def __init__(self, source: EnvSource, retries: int) -> None:
        self.source = source
        self.retries = retries

    @abstractmethod
    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        """Returns (n,) of the episodes ``(seeds (n,), contexts (n, z), params (n, p))``."""

    def close(self) -> None:  # noqa: B027 (most backends hold nothing to release)
        """Release workers (idempotent)."""

    def log_entry(self) -> dict[str, Any] | None:
        """An event for the run directory's log about where the episodes run (None: nothing to add)."""
        return None
