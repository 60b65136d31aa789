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

With a context selector (:mod:`creps_gym.selectors`; ``RunConfig.context_selector`` or an object), the
contexts come from ``selector.select(selector_rng, n)`` instead, ``selector_rng`` being the run's
``SeedSequence`` child :attr:`~creps_gym.runner.seeds.SeedPlan.SELECTOR` (no other stream uses it, so
runs without a selector draw what they drew before), and the reset seeds still from the env stream. It
needs ``"batch"`` draws on an env that accepts ``reset(options={"context": s})`` as above; any other env
is refused.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.base import ContextualEpisodicEnv
from creps_gym.errors import ConfigError
from creps_gym.runner.backends import reset_context
from creps_gym.runner.config import CONTEXT_DRAWS, RunConfig
from creps_gym.runner.selection import Selection
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
    selection : Selection, optional
        The run's context selector, if any: it chooses the contexts instead of the env (bound here to the
        env's context box) with its own stream, and is told every iteration's outcome (:meth:`tell`).
    """

    def __init__(self, env: gym.Env, mode: str, retries: int, selection: Selection | None = None) -> None:
        if mode not in CONTEXT_DRAWS:
            raise ValueError(f"context_draws: expected one of {list(CONTEXT_DRAWS)}, got {mode!r}")
        self.selection = selection if selection is not None else Selection(None)
        self.env, self.retries, self.selector = env, retries, self.selection.selector
        self.n_context_dims = int(np.prod(env.observation_space.shape))
        layer = batch_layer(env) if mode == "batch" else None
        self.batched = layer is not None
        self._sample = None if layer is None else layer.sample_contexts
        if self.selector is not None:
            if layer is None:
                raise ConfigError(
                    "context_selector",
                    "expected an env whose contexts the runner sets (a creps_gym model, possibly under "
                    "FixedContexts, SampleContexts, TimeLimit, action or reward wrappers) and "
                    f"context_draws='batch', got {env} with context_draws={mode!r}; where the world picks "
                    "the context, no selector can choose it",
                )
            space = env.observation_space
            self.low, self.high = space.low.astype(np.float64), space.high.astype(np.float64)
            self.selector.bind(self.low.copy(), self.high.copy(), layer.sample_contexts)

    @classmethod
    def for_run(cls, env: gym.Env, config: RunConfig, selector: Any = None) -> ContextDraws:
        """The draws of a run of ``config`` on ``env`` (``selector``: a selector object, if any)."""
        return cls(env, config.context_draws, config.retries, Selection(config, selector))

    def tell(self, contexts: Array, returns: Array, optimizer: Any) -> None:
        """Tell the selector (if any) an iteration's contexts, returns and the optimiser's diagnostics."""
        self.selection.tell(contexts, returns, optimizer)

    def draw(
        self, rng: np.random.Generator, n: int, label: str, optimizer: Any = None
    ) -> tuple[NDArray[np.int64], Array]:
        """Reset seeds (n,) and contexts (n, z) of ``n`` episodes; ``label`` names them in errors.

        A selector's contexts are drawn from its own stream and checked against the context box (a
        selector that asks for it gets ``optimizer``'s ``context_utility``: :meth:`Selection.select`).
        """
        seeds = rng.integers(0, SEED_HIGH, size=n)
        if self._sample is None:
            return seeds, self.reset_contexts(seeds, label)
        if self.selector is None:
            contexts, name = np.asarray(self._sample(rng, n), dtype=np.float64), "sample_contexts"
        else:
            contexts, name = np.asarray(self.selection.select(n, optimizer), np.float64), "selector"
        if contexts.shape != (n, self.n_context_dims):
            raise ValueError(f"{name}: expected shape ({n}, {self.n_context_dims}), got {contexts.shape}")
        if self.selector is not None and not (
            np.isfinite(contexts).all() and (contexts >= self.low).all() and (contexts <= self.high).all()
        ):
            raise ValueError(
                f"{label}: context_selector {self.selector!r} chose contexts outside the context box "
                f"[{self.low.tolist()}, {self.high.tolist()}]"
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
