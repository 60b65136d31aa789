"""Registry-driven checks of every registered ``creps_gym/`` id (functions, reacher, kick, wrapper examples).

Each check runs one or two episodes, so that the slower MuJoCo envs stay cheap. An id whose optional
dependency is not installed is skipped with the reason.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence
from helpers import make_or_skip

import creps_gym
from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv
from creps_gym.envs.evaluation import evaluate_policy, test_contexts

IDS = creps_gym.registered_ids()
NATIVE_VECTOR_IDS = [env_id for env_id in IDS if gym.spec(env_id).vector_entry_point is not None]

pytestmark = pytest.mark.filterwarnings("ignore:.*(symmetric and normalized|different from the unwrapped)")


def _make(env_id: str) -> gym.Env:
    return make_or_skip(env_id)


def _model(env: gym.Env) -> ContextualEpisodicEnv:
    model = env.unwrapped
    assert isinstance(model, ContextualEpisodicEnv)
    return model


def _two_contexts(model: ContextualEpisodicEnv) -> np.ndarray:
    return model.sample_contexts(np.random.default_rng(123), 2)


def _fixed_action(env: gym.Env) -> np.ndarray:
    env.action_space.seed(7)
    return env.action_space.sample()


def test_the_function_suite_is_registered():
    assert len([env_id for env_id in IDS if env_id.endswith("-v0")]) >= 15
    assert "creps_gym/Rosenbrock-v0" in NATIVE_VECTOR_IDS


@pytest.mark.parametrize("env_id", IDS)
def test_check_env(env_id):
    env = _make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.spec.max_episode_steps is None  # a TimeLimit of 1 would truncate the single step
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_gives_identical_episodes(env_id):
    runs = []
    for _ in range(2):
        env = _make(env_id)
        obs, reset_info = env.reset(seed=42)
        step = env.step(_fixed_action(env))
        runs.append((obs, reset_info, *step))
        env.close()
    assert data_equivalence(runs[0], runs[1], exact=True)
    _, _, _, _, terminated, truncated, _ = runs[0]
    assert terminated is True and truncated is False


def _candidate_actions(env: gym.Env, model: ContextualEpisodicEnv) -> list[np.ndarray]:
    """Parameters to probe the context with: the env's reference parameters, if it ships some (a random kick
    just falls over, with the same penalty in every context), else its declared start's mean (a
    low-dimensional kick's u = 0 is the reference kick), then seeded samples of the parameter box."""
    if callable(getattr(model, "reference_params", None)):
        candidates = [np.asarray(model.reference_params())]
    else:
        candidates = [np.asarray(model.initial_distribution()[0])]
    candidates.append(_fixed_action(env))
    candidates += [env.action_space.sample() for _ in range(2)]
    return candidates


@pytest.mark.parametrize("env_id", IDS)
def test_context_option_sets_the_context_and_changes_the_outcome(env_id):
    env = _make(env_id)
    model = _model(env)
    contexts = _two_contexts(model)
    for action in _candidate_actions(env, model):
        returns = []
        for context in contexts:
            obs, info = env.reset(seed=0, options={"context": context})
            np.testing.assert_array_equal(obs, context)
            np.testing.assert_array_equal(info["context"], context)
            np.testing.assert_array_equal(model.context, context)
            obs, reward, _, _, info = env.step(action)
            np.testing.assert_array_equal(info["context"], context)
            returns.append(reward)
        if returns[0] != returns[1]:
            break
    assert returns[0] != returns[1], f"{env_id}: the same parameters gave the same return in two contexts"
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_info_context_is_the_observation(env_id):
    env = _make(env_id)
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    np.testing.assert_array_equal(info["context"], obs)
    obs_step, _, _, _, info = env.step(_fixed_action(env))
    np.testing.assert_array_equal(info["context"], obs_step)
    np.testing.assert_array_equal(obs_step, obs)
    env.close()


@pytest.mark.parametrize("env_id", NATIVE_VECTOR_IDS)
def test_native_vector_env_matches_the_scalar_env(env_id):
    vector = make_or_skip(env_id, vector=True, num_envs=2)
    assert isinstance(vector, ContextualEpisodicVectorEnv)
    env = _make(env_id)
    contexts = _two_contexts(_model(env))
    actions = np.stack([_fixed_action(env), env.action_space.sample()])
    obs, info = vector.reset(seed=0, options={"context": contexts})
    np.testing.assert_array_equal(obs, contexts)
    np.testing.assert_array_equal(info["context"], contexts)
    _, rewards, terminated, truncated, info = vector.step(actions)
    assert terminated.all() and not truncated.any()
    np.testing.assert_array_equal(info["final_info"]["context"], contexts)
    for k in range(2):
        env.reset(options={"context": contexts[k]})
        _, reward, _, _, _ = env.step(actions[k])
        assert reward == rewards[k]
    vector.close()
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_evaluation_helper_uses_the_env_model(env_id):
    env = _make(env_id)
    model = _model(env)
    contexts = test_contexts(env, 2, seed=11)
    np.testing.assert_array_equal(contexts, test_contexts(env, 2, seed=11))
    assert all(model.observation_space.contains(context) for context in contexts)
    action = _fixed_action(env)
    result = evaluate_policy(env, action, contexts)
    rewards = []
    for context in contexts:
        env.reset(options={"context": context})
        rewards.append(env.step(action)[1])
    np.testing.assert_array_equal(result.returns, rewards)
    assert result.metric in ("regret", "return")
    if result.metric == "regret":
        np.testing.assert_array_equal(
            result.regrets, model.regret(contexts, np.tile(action, (len(contexts), 1)))
        )
        assert (result.regrets >= 0).all() and result.value == pytest.approx(result.regrets.mean())
    else:
        assert result.value == pytest.approx(np.mean(rewards))
    env.close()
