"""How the runner draws an iteration's episodes (reset seeds and contexts) from its env stream.

Every iteration first draws one reset seed per episode, ``rng.integers(0, 2**63 - 1, size=n)``; then the
contexts, in one of two ways (``RunConfig.context_draws``):

* ``"batch"`` (the default): one call ``layer.sample_contexts(rng, n)`` on the layer that chooses the
  contexts: the outermost :class:`~creps_gym.wrappers.FixedContexts` or
  :class:`~creps_gym.wrappers.SampleContexts`, else the creps_gym model itself. This needs an env whose
  observation *is* the context and whose layers pass ``reset(options={"context": s})`` through to the
  model: a creps_gym model under the wrappers of :data:`PASS_THROUGH_WRAPPERS`, action wrappers and
  reward wrappers. Episodes then run with ``reset(seed=seed, options={"context": context})``.
* ``"reset"``, and the fallback for every other env (a plain Gymnasium env, an observation wrapper such as
  :class:`~creps_gym.wrappers.HideContext`): each context is the observation of ``env.reset(seed=seed)``
  (retried like an episode), and episodes run with ``reset(seed=seed)``. It is the stream of run
  directories of format ``creps_gym.run/2``, which resume with it.

The stream is the same on every backend, so every backend gives the same history bit for bit.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.base import ContextualEpisodicEnv
from creps_gym.runner.backends import reset_context
from creps_gym.runner.config import CONTEXT_DRAWS
from creps_gym.wrappers import FixedContexts, SampleContexts

__all__ = ["PASS_THROUGH_WRAPPERS", "ContextDraws", "batch_layer"]

Array = NDArray[np.float64]
SEED_HIGH = 2**63 - 1
#: Wrappers that leave the observation and ``reset(options={"context": s})`` as they are.
PASS_THROUGH_WRAPPERS: tuple[type, ...] = (
    gym.wrappers.OrderEnforcing,
    gym.wrappers.PassiveEnvChecker,
    gym.wrappers.TimeLimit,
)


def batch_layer(env: gym.Env) -> Any:
    """The layer of ``env`` whose ``sample_contexts(rng, n)`` draws its contexts, or None (see above)."""
    layer = env
    while True:
        if isinstance(layer, (FixedContexts, SampleContexts, ContextualEpisodicEnv)):
            return layer
        passes = isinstance(layer, (*PASS_THROUGH_WRAPPERS, gym.ActionWrapper, gym.RewardWrapper))
        if not passes:
            return None
        layer = layer.env


class ContextDraws:
    """Draws the reset seeds and contexts of an iteration's episodes (see the module docstring).

    Parameters
    ----------
    env : gymnasium.Env
        The run's env (contexts are its observations).
    mode : {"batch", "reset"}
    retries : int
        Re-tries of a failed reset (``"reset"`` draws).
    """

    def __init__(self, env: gym.Env, mode: str, retries: int) -> None:
        if mode not in CONTEXT_DRAWS:
            raise ValueError(f"context_draws: expected one of {list(CONTEXT_DRAWS)}, got {mode!r}")
        self.env, self.retries = env, retries
        self.n_context_dims = int(np.prod(env.observation_space.shape))
        layer = batch_layer(env) if mode == "batch" else None
        self.batched = layer is not None
        self._sample = None if layer is None else layer.sample_contexts

    def draw(self, rng: np.random.Generator, n: int, label: str) -> tuple[NDArray[np.int64], Array]:
        """Reset seeds (n,) and contexts (n, z) of ``n`` episodes; ``label`` names them in errors."""
        seeds = rng.integers(0, SEED_HIGH, size=n)
        if self._sample is None:
            return seeds, self.reset_contexts(seeds, label)
        contexts = np.asarray(self._sample(rng, n), dtype=np.float64)
        if contexts.shape != (n, self.n_context_dims):
            raise ValueError(
                f"sample_contexts: expected shape ({n}, {self.n_context_dims}), got {contexts.shape}"
            )
        return seeds, contexts

    def reset_contexts(self, seeds: NDArray[np.int64], label: str) -> Array:
        """The contexts of ``env.reset(seed=s)``, shape (n, z); each reset retried like an episode."""
        rows = [
            np.asarray(
                reset_context(self.env, int(s), self.retries, f"{label}, episode {k}"), np.float64
            ).ravel()
            for k, s in enumerate(seeds)
        ]
        return np.array(rows).reshape(len(seeds), self.n_context_dims)
