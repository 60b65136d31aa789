"""The env-declared initial search distribution: the hook, its fallback, and the runner and CLI using it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from helpers import EXTRAS

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.base import box_initial_distribution, initial_distribution
from creps_gym.listing import initial_hint
from creps_gym.runner.config import RunConfig
from creps_gym.runner.loop import Runner


class _DeclaringSphere(gym.Wrapper):
    """A creps_gym sphere whose start is declared by a wrapper (mean 0.5, std 0.1 per parameter)."""

    def initial_distribution(self):
        p = self.action_space.shape[0]
        return np.full(p, 0.5), np.full(p, 0.1)


class _Foreign(gym.Env):
    """An env outside creps_gym: a Box of parameters and no declaration."""

    observation_space = gym.spaces.Box(0.0, 1.0, (1,), np.float64)
    action_space = gym.spaces.Box(np.array([-1.0, 0.0]), np.array([3.0, 8.0]), dtype=np.float64)


def test_functions_declare_the_box_rule():
    env = gym.make("creps_gym/Sphere-v0", dim=3)
    mean, std = initial_distribution(env)
    box_mean, box_std = box_initial_distribution(env.action_space)
    assert np.array_equal(mean, box_mean) and np.array_equal(std, box_std)


def test_the_reacher_declares_its_own_start():
    mean, std = initial_distribution(gym.make("creps_gym/PlanarReacher-v0"))  # kept as it was
    assert np.array_equal(mean, np.zeros(25)) and np.array_equal(std, np.full(25, 15.0))


def test_reacher_v1_declares_the_papers_start_and_behaves_like_v0():
    """v1 (issue 31): σ = 1, where CREPS-CMA-old ends 300x better than from v0's σ = 15 (docstring)."""
    v0, v1 = gym.make("creps_gym/PlanarReacher-v0"), gym.make("creps_gym/PlanarReacher-v1")
    mean, std = initial_distribution(v1)
    assert np.array_equal(mean, np.zeros(25)) and np.array_equal(std, np.ones(25))
    contexts = np.random.default_rng(0).uniform(0, 2, (5, 2))
    params = np.random.default_rng(1).normal(0, 3, (5, 25))
    assert np.array_equal(
        v0.unwrapped.evaluate(contexts, params)[0], v1.unwrapped.evaluate(contexts, params)[0]
    )
    with pytest.raises(ValueError, match="initial_std: expected a finite value > 0, got 0"):
        gym.make("creps_gym/PlanarReacher-v1", initial_std=0)


def test_the_kick_declares_the_reference_kick():
    pytest.importorskip("mujoco")
    env = gym.make("creps_gym/KickPrecision-v0", num_threads=1)
    mean, std = initial_distribution(env)  # through gymnasium's wrappers (order enforcing, checker)
    assert np.array_equal(mean, env.unwrapped.reference_params())
    assert np.array_equal(std, np.full(25, 0.02))
    assert initial_hint(env) == "N(env-declared mean, 0.02^2)"
    env.close()


def test_foreign_envs_fall_back_to_the_box_rule():
    mean, std = initial_distribution(_Foreign())
    assert np.array_equal(mean, [1.0, 4.0]) and np.array_equal(std, [1.0, 2.0])


def test_a_declaration_in_other_parameter_units_falls_back_to_the_box_rule():
    """A wrapper between the declaring env and the caller changed the action space without mapping."""

    class Rescale(gym.ActionWrapper):
        def __init__(self, env):
            super().__init__(env)
            self.action_space = gym.spaces.Box(-1.0, 1.0, env.action_space.shape, np.float64)

        def action(self, action):
            return action

    env = Rescale(_DeclaringSphere(gym.make("creps_gym/Sphere-v0", dim=3)))
    mean, std = initial_distribution(env)
    assert np.array_equal(mean, np.zeros(3)) and np.array_equal(std, np.full(3, 0.5))


@pytest.mark.parametrize(
    ("declared", "error", "match"),
    [
        ((np.zeros(5), np.ones(5)), ValueError, r"Wrong.initial_distribution\(\) mean: expected shape \(2,"),
        ((np.zeros(2), -np.ones(2)), ValueError, r"Wrong.initial_distribution\(\) std: expected values > 0"),
        ((np.zeros(2), np.array([1.0, np.nan])), ValueError, r"std: expected finite values, got nan"),
        ((np.zeros(2), np.ones(2) + 1j), TypeError, r"std: expected an array of real numbers, got a complex"),
        ([np.zeros(2), np.ones(2)], TypeError, r"expected a tuple \(mean, std\), got list"),
    ],
)
def test_a_broken_declaration_raises_naming_the_declaring_class(declared, error, match):
    class Wrong(gym.Wrapper):
        def initial_distribution(self):
            return declared

    with pytest.raises(error, match=match):
        initial_distribution(Wrong(_Foreign()))


def test_a_wrapper_declaration_wins_over_the_inner_env():
    env = _DeclaringSphere(gym.make("creps_gym/Sphere-v0", dim=3))
    mean, std = initial_distribution(env)
    assert np.array_equal(mean, np.full(3, 0.5)) and np.array_equal(std, np.full(3, 0.1))
    assert initial_hint(env) == "N(0.5, 0.1^2)"


@EXTRAS
@pytest.mark.parametrize("name", ["cma", "nevergrad", "optuna"])
def test_the_runner_starts_every_adapter_at_the_declared_distribution(name):
    env = _DeclaringSphere(gym.make("creps_gym/Sphere-v0", dim=3))
    optimizer = Runner(RunConfig(None, name, 2, 4, 0), env=env).optimizer
    assert np.array_equal(optimizer.initial_mean, np.full(3, 0.5))
    assert np.allclose(optimizer.initial_std, 0.1)
    given = Runner(RunConfig(None, name, 2, 4, 0, initial_mean=0.2, initial_std=1.0), env=env).optimizer
    assert np.array_equal(given.initial_mean, np.full(3, 0.2))  # the user's values win
    assert np.allclose(given.initial_std, 1.0)
