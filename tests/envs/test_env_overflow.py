"""No silent ±inf: finite parameters whose objective overflows are refused, on every env (issue 15, item 7).

The policy (``ContextualEpisodicEnv.check_returns``): a return that is not finite raises a ValueError that
names the parameters; envs that saturate (the MuJoCo kick, the episodic wrappers) return a finite value.
"""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from helpers import SPHERE, make_or_skip

from creps_gym import registered_ids
from creps_gym.envs.evaluation import evaluate_policy
from creps_gym.errors import EpisodeError
from creps_gym.optimizers import CREPSCMA
from creps_gym.runner import run

HUGE = (1e200, -1e200, 1e300, -1e300)


@pytest.mark.parametrize("env_id", registered_ids())
def test_huge_finite_params_give_a_finite_return_or_a_clear_error(env_id):
    env = make_or_skip(env_id, disable_env_checker=True)
    p = env.action_space.shape[0]
    for value in HUGE:
        env.reset(seed=0)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # e.g. MuJoCo's own warning about unstable simulations
                _, reward, *_ = env.step(np.full(p, value))
        except ValueError as exc:
            assert f"action: expected a finite return, got {'-' if '-inf' in str(exc) else ''}" in str(exc)
            assert f"for params [{value!r}, " in str(exc)
            assert env.unwrapped._last_params is None  # a refused step leaves the episode unfinished
            continue
        assert isinstance(reward, float) and math.isfinite(reward), (env_id, value, reward)


def test_the_sphere_refuses_an_overflow_in_every_api():
    env = gym.make(SPHERE, dim=3)
    env.reset(seed=0)
    overflow = r"action: expected a finite return, got -inf for params \[1e\+200, 0"
    with pytest.raises(ValueError, match=overflow):
        env.step(np.array([1e200, 0.0, 0.0]))
    assert math.isfinite(env.step(np.zeros(3))[1])  # the refused step changed nothing: the episode goes on
    vector = gym.make_vec(SPHERE, 2, vectorization_mode="vector_entry_point", dim=3)
    vector.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions: expected a finite return, got -inf for .* \(row 1\)"):
        vector.step(np.array([[0.0, 0.0, 0.0], [0.0, -1e300, 0.0]]))
    with pytest.raises(ValueError, match=r"policy: expected a finite return, got -inf"):
        evaluate_policy(env, np.full(3, 1e200), np.zeros((2, 1)) + 1.0)


def test_a_run_that_asks_for_overflowing_params_stops_with_an_episode_error_naming_them():
    with pytest.raises(
        EpisodeError, match=r"failed 2 time\(s\); last error: ValueError: action: .*for params"
    ):
        run(CREPSCMA(3, 1, seed=0, initial_mean=1e200), SPHERE, 2, 10, 0, env_kwargs={"dim": 3}, retries=1)
