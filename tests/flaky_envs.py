"""Envs that fail at random or return odd rewards, shared by the failure tests (and the Ray tests).

Imported as ``from flaky_envs import ...``; :func:`flaky` registers ``test/Flaky-v0`` (with a native vector
env) so that vector backends can make copies.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv

FLAKY_ID = "test/Flaky-v0"
_INSTANCES = {"made": 0}  # every copy draws its own failures (a rebuilt env does not replay them)


class Flaky(ContextualEpisodicEnv):
    """theta*(s) = (s, -s), return -|theta - theta*(s)|^2, with failures drawn from a seeded generator.

    Each ``reset`` raises with probability ``reset_rate`` and each ``evaluate`` call (a ``step``, or a
    whole batch of the native vector env) with probability ``step_rate``; ``fail_above`` makes every
    evaluation with a first parameter above it raise. The failures come from
    ``numpy.random.default_rng([flake_seed, instance number])``, never from the env's own ``np_random``,
    so they change no context and no return.
    """

    def __init__(
        self,
        step_rate: float = 0.0,
        reset_rate: float = 0.0,
        flake_seed: int = 0,
        fail_above: float | None = None,
    ) -> None:
        super().__init__([0.0], [1.0], [-2.0, -2.0], [2.0, 2.0])
        self.step_rate, self.reset_rate, self.fail_above = step_rate, reset_rate, fail_above
        _INSTANCES["made"] += 1
        self.flakes = np.random.default_rng([flake_seed, _INSTANCES["made"]])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple:
        if self.flakes.random() < self.reset_rate:
            raise RuntimeError("simulated reset failure")
        return super().reset(seed=seed, options=options)

    def evaluate(self, contexts, params):
        if self.flakes.random() < self.step_rate:
            raise RuntimeError("simulated step failure")
        if self.fail_above is not None and (params[:, 0] > self.fail_above).any():
            raise RuntimeError("simulated crash")
        best = np.concatenate([contexts, -contexts], axis=1)
        return -np.sum((params - best) ** 2, axis=1), {}


class FlakyVector(ContextualEpisodicVectorEnv):
    """The native vector env of :class:`Flaky` (one ``evaluate`` call per batch)."""

    single_env_class = Flaky


class OddReward(gym.Env):
    """A one-step env (not a creps_gym model) whose reward is ``reward`` as given, of any type."""

    observation_space = gym.spaces.Box(0.0, 1.0, (1,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float64)

    def __init__(self, reward: Any = 0.5) -> None:
        self.reward = reward

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple:
        super().reset(seed=seed)
        return self.np_random.uniform(0.0, 1.0, size=1), {}

    def step(self, action: Any) -> tuple:
        return np.zeros(1), self.reward, True, False, {}


def register() -> None:
    """Register ``test/Flaky-v0`` and ``test/OddReward-v0`` (idempotent)."""
    if FLAKY_ID not in gym.registry:
        gym.register(FLAKY_ID, entry_point=Flaky, vector_entry_point=FlakyVector)
    if "test/OddReward-v0" not in gym.registry:
        gym.register("test/OddReward-v0", entry_point=OddReward)


def flaky(**kwargs: Any) -> gym.Env:
    """A :class:`Flaky` made by ``gymnasium.make`` (so that it has a spec vector backends can copy)."""
    register()
    return gym.make(FLAKY_ID, disable_env_checker=True, **kwargs)
