"""Context wrappers for the one-step contextual envs (:class:`~creps_gym.envs.base.ContextualEpisodicEnv`).

Each wrapper works on any creps_gym env, including the episodic conversions of step-based tasks
(:class:`~creps_gym.wrappers.episodic.EpisodicEnv`). Their native-vector counterparts are in
:mod:`creps_gym.wrappers.vector`.

Wrappers
--------
FixedContexts
    Contexts taken from a given set, in a cycle or at random (seeded), e.g. a named train or test split;
    the reset ``info`` gains ``"context_index"``.
SampleContexts
    Contexts drawn from a :class:`~creps_gym.wrappers.samplers.ContextSampler` (uniform, Gaussian or any
    callable) with the env's ``np_random`` at every reset.
HideContext
    The observation becomes an empty vector, shape (0,); the context stays in ``info["context"]``
    (blind baselines).
NormalizeParams
    The parameter (action) box becomes ``[-1, 1]^p`` and is mapped linearly onto the env's bounds.

Seeding: ``reset(seed=k)`` re-seeds the env's ``np_random`` (``seeding.np_random(k)``, as ``Env.reset``
does) before the wrapper draws, and restarts a cycle at the first context. ``reset(options={"context": s})``
still sets the context explicitly and bypasses the wrapper. The wrappers record their constructor
arguments (``gymnasium.utils.RecordConstructorArgs``), so ``gymnasium.make(wrapped.spec)`` rebuilds a
wrapped env.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from numpy.typing import NDArray

from creps_gym._validation import as_float_array
from creps_gym.envs.base import initial_distribution
from creps_gym.envs.evaluation import contextual_model
from creps_gym.wrappers.sources import FixedSet, checked_samples, param_bounds, unchanged_on_error

__all__ = ["FixedContexts", "HideContext", "NormalizeParams", "SampleContexts"]

Array = NDArray[np.float64]


class _ContextChoice(gym.Wrapper):
    """Base of the wrappers that choose the context of every reset."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.model = contextual_model(env, ("env",), user=type(self).__name__)

    def _choose(self) -> tuple[Array, dict[str, Any]]:
        raise NotImplementedError

    def _restart(self) -> None:
        """Called on a seeded reset."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        """Reset with a context chosen by the wrapper (unless ``options["context"]`` is given); a reset that
        raises leaves the wrapper's generator and cycle as they were."""
        with unchanged_on_error(self):
            return self._reset(seed, {} if options is None else dict(options))

    def _reset(self, seed: int | None, options: dict[str, Any]) -> tuple[Any, dict]:
        if seed is not None:
            self._restart()
        if "context" in options:
            return self.env.reset(seed=seed, options=options)
        if seed is not None:  # seed the env's generator as Env.reset(seed=seed) would, then draw from it
            self.np_random, _ = seeding.np_random(seed)
        context, extra = self._choose()
        obs, info = self.env.reset(options={**options, "context": context})
        info.update(extra)
        return obs, info


class FixedContexts(FixedSet, _ContextChoice, gym.utils.RecordConstructorArgs):
    """Draw every episode's context from a fixed set: in a cycle, or at random with the env's ``np_random``.

    Parameters
    ----------
    env : gymnasium.Env
        A creps_gym contextual env (possibly wrapped).
    contexts : array_like, shape (m, z)
        The set; every context must lie in the env's context box.
    order : {"cycle", "random"}
        ``"cycle"`` visits the set in order (restarting on every seeded reset); ``"random"`` draws an
        index uniformly at each reset.
    name : str, optional
        A label for the set (``"train"``, ``"test"``), kept in :attr:`name`.

    Notes
    -----
    The reset ``info`` gains ``"context_index"``, the index of the context in the set.
    """

    def __init__(self, env: gym.Env, contexts: Any, order: str = "cycle", name: str | None = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, contexts=contexts, order=order, name=name)
        _ContextChoice.__init__(self, env)
        self._hold(contexts, order, name)

    def _choose(self) -> tuple[Array, dict[str, Any]]:
        contexts, index = self.source.draw(self.np_random, 1)
        return contexts[0], {"context_index": int(index[0])}

    def sample_contexts(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` contexts (n, z) as ``n`` resets after a seeded one choose them, drawn with ``rng``.

        A cycle starts at the first context; ``"random"`` draws the indices from ``rng``. The wrapper's
        own state is untouched (the runner draws an iteration's contexts with one call).
        """
        m = self.source.contexts.shape[0]
        index = rng.integers(0, m, size=n) if self.source.order == "random" else np.arange(n) % m
        return self.source.contexts[index]


class SampleContexts(_ContextChoice, gym.utils.RecordConstructorArgs):
    """Draw every episode's context from ``sampler(env.np_random, 1)``.

    Parameters
    ----------
    env : gymnasium.Env
        A creps_gym contextual env (possibly wrapped).
    sampler : ContextSampler
        :class:`~creps_gym.wrappers.samplers.UniformContexts`, :class:`GaussianContexts` or any callable
        ``(rng, n) -> (n, z)``; its samples must lie in the env's context box.
    """

    def __init__(self, env: gym.Env, sampler: Any) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, sampler=sampler)
        _ContextChoice.__init__(self, env)
        if not callable(sampler):
            raise TypeError(f"sampler: expected a callable (rng, n) -> (n, z), got {type(sampler).__name__}")
        self.sampler = sampler

    def _choose(self) -> tuple[Array, dict[str, Any]]:
        return checked_samples(self.sampler, self.np_random, 1, self.model)[0], {}

    def sample_contexts(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` contexts (n, z) from ``sampler(rng, n)``, checked against the env's context box."""
        return checked_samples(self.sampler, rng, n, self.model)


class HideContext(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Blind the agent: the observation is an empty float64 vector, shape (0,); ``info["context"]`` stays."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        contextual_model(env, ("env",), user="HideContext")
        self.observation_space = spaces.Box(np.zeros(0), np.zeros(0), dtype=np.float64)

    def observation(self, observation: Any) -> Array:
        """Return ``np.zeros(0)``."""
        return np.zeros(0)


class NormalizeParams(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Search in ``[-1, 1]^p``: ``theta = low + (u + 1) (high - low) / 2`` maps ``u`` onto the env's box.

    The map is affine and applied as is (values outside ``[-1, 1]`` map outside the box, as the base env
    evaluates out-of-box parameters as given).

    Parameters
    ----------
    env : gymnasium.Env
        An env with a 1-D Box action space with finite bounds.
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        self.low, self.high = param_bounds(env.action_space, "NormalizeParams")
        dim = self.low.shape[0]
        self.action_space = spaces.Box(-np.ones(dim), np.ones(dim), dtype=np.float64)

    def action(self, action: Any) -> Array:
        """Map normalised parameters ``u`` (p,) to the env's parameters (p,)."""
        u = as_float_array(action, "action", (self.low.shape[0],))
        return self.low + 0.5 * (u + 1.0) * (self.high - self.low)

    def normalize(self, params: Any) -> Array:
        """Inverse map: physical parameters (..., p) to normalised ones (..., p)."""
        params = as_float_array(params, "params")
        if params.shape[-1:] != self.low.shape:
            raise ValueError(f"params: expected shape (..., {self.low.shape[0]}), got {params.shape}")
        return 2.0 * (params - self.low) / (self.high - self.low) - 1.0

    def initial_distribution(self) -> tuple[Array, Array]:
        """The wrapped env's declared initial distribution in normalised units (mean, std), shape (p,):
        N(mean, std²) becomes N(normalize(mean), (2 std / (high − low))²)."""
        mean, std = initial_distribution(self.env)
        return self.normalize(mean), 2.0 * std / (self.high - self.low)
