"""Vector counterparts of the context wrappers, for the native vector envs with per-env contexts.

They wrap a :class:`~creps_gym.envs.base.ContextualEpisodicVectorEnv` (``gymnasium.make_vec(id,
num_envs=n)`` of a creps_gym id with a native vector entry point, or ``EpisodicVectorEnv``) and choose one
context per sub-env. For ``SyncVectorEnv``/``AsyncVectorEnv``, wrap each sub-env with the scalar wrappers
instead (``gymnasium.make_vec(id, n, wrappers=[...])``).

Wrappers
--------
FixedContextsVector
    Per-env contexts from a fixed set, in a cycle or at random (seeded); ``info["context_index"]`` (n,).
SampleContextsVector
    Per-env contexts from a sampler, drawn with the vector env's ``np_random``.
HideContextVector
    Observations become empty, shape (n, 0); the contexts stay in ``info["context"]``.
NormalizeParamsVector
    Actions in ``[-1, 1]^p`` per env, mapped onto the env's parameter box.

Resets follow the native env: ``options["reset_mask"]`` (bool, (n,)) resets only some envs and the wrapper
draws contexts for those only. In the ``SAME_STEP`` autoreset mode the wrapper replaces the contexts the env
drew after a step by its own (the terminal data stay in ``info["final_obs"]`` and ``info["final_info"]``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from numpy.typing import NDArray

from creps_gym._validation import as_float_array
from creps_gym.envs.evaluation import contextual_model
from creps_gym.wrappers.sources import FixedSet, checked_samples, param_bounds, unchanged_on_error

__all__ = ["FixedContextsVector", "HideContextVector", "NormalizeParamsVector", "SampleContextsVector"]

Array = NDArray[np.float64]


class _ContextChoiceVector(VectorWrapper):
    """Base of the vector wrappers that choose the contexts of every reset and autoreset."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        self.model = contextual_model(env, ("vector",), user=type(self).__name__)

    def _choose(self, n: int) -> tuple[Array, dict[str, Any]]:
        raise NotImplementedError

    def _restart(self) -> None:
        """Called on a seeded reset."""

    def _reset_with_choice(self, mask: NDArray[np.bool_], options: dict[str, Any]) -> tuple[Any, dict]:
        contexts, extra = self._choose(int(mask.sum()))
        obs, info = self.env.reset(options={**options, "context": contexts, "reset_mask": mask})
        for key, value in extra.items():
            full = np.zeros(self.num_envs, dtype=value.dtype)
            full[mask] = value
            info[key], info["_" + key] = full, mask.copy()
        return obs, info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        """Reset with per-env contexts chosen by the wrapper (unless ``options["context"]`` is given); a reset
        that raises leaves the wrapper's generator and cycle as they were."""
        with unchanged_on_error(self):
            return self._reset(seed, {} if options is None else dict(options))

    def _reset(self, seed: int | None, options: dict[str, Any]) -> tuple[Any, dict]:
        if "context" in options:
            if seed is not None:
                self._restart()
            return self.env.reset(seed=seed, options=options)
        if isinstance(seed, list):
            raise TypeError("seed: expected an int or None for a native vector env, got a list")
        mask = np.asarray(options.pop("reset_mask", np.ones(self.num_envs, dtype=bool)))
        if mask.dtype != np.bool_ or mask.shape != (self.num_envs,):
            raise ValueError(
                f"options['reset_mask']: expected a bool array of shape ({self.num_envs},), "
                f"got dtype {mask.dtype} and shape {mask.shape}"
            )
        if seed is not None:
            self._restart()
            self.np_random, _ = seeding.np_random(seed)
        return self._reset_with_choice(mask, options)

    def step(self, actions: Any) -> tuple[Any, Array, Any, Any, dict]:
        """Step all envs; in ``SAME_STEP`` mode the next contexts are the wrapper's."""
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        if self.env.metadata.get("autoreset_mode") == AutoresetMode.SAME_STEP:
            final = {key: info[key] for key in ("final_obs", "_final_obs", "final_info", "_final_info")}
            done = np.asarray(terminated) | np.asarray(truncated)
            obs, info = self._reset_with_choice(done, {})
            info.update(final)
        return obs, rewards, terminated, truncated, info


class FixedContextsVector(FixedSet, _ContextChoiceVector):
    """Per-env contexts from a fixed set (see :class:`~creps_gym.wrappers.contexts.FixedContexts`).

    Parameters
    ----------
    env : VectorEnv
        A native creps_gym vector env (possibly wrapped).
    contexts : array_like, shape (m, z)
    order : {"cycle", "random"}
        A cycle hands out consecutive contexts to the envs being reset, in env order.
    name : str, optional
        A label for the set.
    """

    def __init__(self, env: VectorEnv, contexts: Any, order: str = "cycle", name: str | None = None) -> None:
        super().__init__(env)
        self._hold(contexts, order, name)

    def _choose(self, n: int) -> tuple[Array, dict[str, Any]]:
        contexts, index = self.source.draw(self.np_random, n)
        return contexts, {"context_index": index}


class SampleContextsVector(_ContextChoiceVector):
    """Per-env contexts from ``sampler(env.np_random, n)`` (see :class:`SampleContexts`).

    Parameters
    ----------
    env : VectorEnv
        A native creps_gym vector env (possibly wrapped).
    sampler : ContextSampler
        Any callable ``(rng, n) -> (n, z)`` whose samples lie in the env's context box.
    """

    def __init__(self, env: VectorEnv, sampler: Any) -> None:
        super().__init__(env)
        if not callable(sampler):
            raise TypeError(f"sampler: expected a callable (rng, n) -> (n, z), got {type(sampler).__name__}")
        self.sampler = sampler

    def _choose(self, n: int) -> tuple[Array, dict[str, Any]]:
        return checked_samples(self.sampler, self.np_random, n, self.model), {}


class HideContextVector(VectorWrapper):
    """Observations become empty, shape (n, 0) (also ``info["final_obs"]``); ``info["context"]`` stays."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        contextual_model(env, ("vector",), user="HideContextVector")
        self.single_observation_space = spaces.Box(np.zeros(0), np.zeros(0), dtype=np.float64)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)

    def _empty(self) -> Array:
        return np.zeros((self.num_envs, 0))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Array, dict]:
        """Reset the env; the observation is ``np.zeros((n, 0))``."""
        _, info = self.env.reset(seed=seed, options=options)
        return self._empty(), info

    def step(self, actions: Any) -> tuple[Array, Array, Any, Any, dict]:
        """Step the env; the observation is ``np.zeros((n, 0))``."""
        _, rewards, terminated, truncated, info = self.env.step(actions)
        if "final_obs" in info:
            info = {**info, "final_obs": self._empty()}
        return self._empty(), rewards, terminated, truncated, info


class NormalizeParamsVector(gym.vector.VectorActionWrapper):
    """Actions (n, p) in ``[-1, 1]`` mapped onto the env's parameter box (see :class:`NormalizeParams`)."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        self.low, self.high = param_bounds(env.single_action_space, "NormalizeParamsVector")
        dim = self.low.shape[0]
        self.single_action_space = spaces.Box(-np.ones(dim), np.ones(dim), dtype=np.float64)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)

    def actions(self, actions: Any) -> Array:
        """Map normalised actions (n, p) to the env's parameters (n, p)."""
        u = as_float_array(actions, "actions", (self.num_envs, self.low.shape[0]))
        return self.low + 0.5 * (u + 1.0) * (self.high - self.low)
