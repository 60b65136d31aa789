"""OffsetParams: parameters relative to a centre in scaled units, and the declared start mapped through it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.base import initial_distribution
from creps_gym.wrappers import NormalizeParams, OffsetParams


def _sphere():
    return gym.make("creps_gym/Sphere-v0", dim=3)


def test_wrapped_step_equals_the_unwrapped_step_at_centre_plus_scale_theta():
    centre, scale = np.array([0.5, -1.0, 2.0]), np.array([0.1, 2.0, 0.5])
    wrapped, plain = OffsetParams(_sphere(), centre, scale), _sphere()
    theta = np.array([0.3, -1.2, 2.5])
    wrapped.reset(seed=4)
    plain.reset(seed=4)
    got, want = wrapped.step(theta), plain.step(centre + scale * theta)
    assert got[1] == want[1] and got[2:4] == want[2:4]
    np.testing.assert_allclose(wrapped.to_agent(centre + scale * theta), theta, rtol=1e-14)


def test_the_declared_distribution_maps_through_the_wrapper():
    env = _sphere()
    mean, std = initial_distribution(env)
    default = OffsetParams(env)  # centre and scale: the declared start, so the start is N(0, 1)
    got_mean, got_std = initial_distribution(default)
    np.testing.assert_array_equal(got_mean, np.zeros(3))
    np.testing.assert_array_equal(got_std, np.ones(3))
    shifted = OffsetParams(env, centre=1.0, scale=0.5)
    got_mean, got_std = initial_distribution(shifted)
    np.testing.assert_allclose(1.0 + 0.5 * got_mean, mean)  # maps back onto the env's declaration
    np.testing.assert_allclose(0.5 * got_std, std)
    low, high = env.action_space.low, env.action_space.high
    np.testing.assert_allclose(shifted.action_space.low, (low - 1.0) / 0.5)
    np.testing.assert_allclose(shifted.action_space.high, (high - 1.0) / 0.5)


def test_a_wrapper_that_does_not_map_the_distribution_falls_back_to_its_box():
    env = NormalizeParams(gym.make("creps_gym/Sphere-v0", dim=3))
    mean, std = initial_distribution(env)  # the inner declaration is in other units: not reused
    np.testing.assert_array_equal(mean, np.zeros(3))
    np.testing.assert_array_equal(std, np.full(3, 0.5))


def test_the_kick_offsets_start_at_the_reference_kick():
    pytest.importorskip("mujoco")
    env = OffsetParams(gym.make("creps_gym/KickPrecision-v0", num_threads=1))
    np.testing.assert_array_equal(env.action(np.zeros(25)), env.unwrapped.reference_params())
    np.testing.assert_array_equal(initial_distribution(env)[1], np.ones(25))
    env.close()


def test_records_its_constructor_arguments():
    env = OffsetParams(_sphere(), centre=0.5, scale=2.0)
    kwargs = env.spec.additional_wrappers[-1].kwargs if env.spec else env._saved_kwargs
    np.testing.assert_array_equal(kwargs["centre"], np.full(3, 0.5))
    np.testing.assert_array_equal(kwargs["scale"], np.full(3, 2.0))


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"scale": 0.0}, ValueError, "scale > 0"),
        ({"scale": [1.0, -1.0, 1.0]}, ValueError, "scale > 0"),
        ({"centre": [1.0, 2.0]}, ValueError, "centre"),
        ({"centre": np.nan}, ValueError, "centre"),
        ({"scale": 1e-320}, ValueError, "scale: expected values that keep the declared distribution"),
    ],
)
def test_bad_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        OffsetParams(_sphere(), **kwargs)


def test_bad_action_is_rejected():
    env = OffsetParams(_sphere())
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.zeros(2))


def test_unit_scale_batches_are_exactly_centre_plus_offsets():
    """benchmarks/kick/run.py relies on this: its committed numbers came from ``reference + offsets``."""
    env = OffsetParams(_sphere(), centre=[0.1, 0.2, 0.3], scale=1.0)
    offsets = np.random.default_rng(0).normal(0.0, 0.02, (50, 3))
    np.testing.assert_array_equal(env.to_env(offsets), np.array([0.1, 0.2, 0.3]) + offsets)
    with pytest.raises(ValueError, match="offsets"):
        env.to_env(np.zeros((2, 4)))
