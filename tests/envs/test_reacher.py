"""The DMP-driven planar reacher: kinematics, the return, batching, contexts, rendering, errors, learning."""

from __future__ import annotations

import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from helpers import EXTRAS

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.reacher import PlanarReacherEnv, PlanarReacherVectorEnv, end_effector, forward_kinematics
from creps_gym.envs.reacher.planar import GOAL, START_ANGLES, VIA_STEP
from creps_gym.envs.reacher.rendering import posture_shades
from creps_gym.optimizers import CREPSCMA

ENV_ID = "creps_gym/PlanarReacher-v0"


def test_forward_kinematics_hand_checked():
    half = np.pi / 2
    cases = {
        (0.0, 0.0, 0.0, 0.0, 0.0): (5.0, 0.0),
        (half, 0.0, 0.0, 0.0, 0.0): (0.0, 5.0),
        (0.0, half, 0.0, 0.0, 0.0): (1.0, 4.0),
        (half, -half, 0.0, 0.0, 0.0): (4.0, 1.0),
        (0.0, 0.0, np.pi, 0.0, 0.0): (-1.0, 0.0),  # two links out, three back
        (half, half, half, half, 0.0): (1.0, 0.0),  # up, left, down, right, right
    }
    for angles, hand in cases.items():
        np.testing.assert_allclose(end_effector(angles), hand, atol=1e-12)
    joints = forward_kinematics([0.0, half, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(joints, [[0, 0], [1, 0], [1, 1], [1, 2], [1, 3], [1, 4]], atol=1e-12)
    assert forward_kinematics(np.zeros((3, 7, 5))).shape == (3, 7, 6, 2)
    np.testing.assert_allclose(
        end_effector([0.3, 0.3], link_length=2.0),
        [2 * np.cos(0.3) + 2 * np.cos(0.6), 2 * np.sin(0.3) + 2 * np.sin(0.6)],
    )


def test_plain_dmp_swings_along_the_circle_from_straight_up_to_the_goal():
    env = PlanarReacherEnv()
    traj = env.joint_trajectories(np.zeros((1, 25)))
    np.testing.assert_array_equal(traj.positions[0, 0], START_ANGLES)
    np.testing.assert_array_equal(traj.positions[0, :, 1:], 0.0)  # only the first joint has a distance to go
    hands = end_effector(traj.positions[0])
    np.testing.assert_allclose(np.linalg.norm(hands, axis=1), 5.0)
    np.testing.assert_allclose(hands[-1], GOAL, atol=5e-3)


def test_return_decomposes_into_distances_and_acceleration_cost():
    rng = np.random.default_rng(0)
    env = PlanarReacherEnv(position_weight=2.0, acceleration_weight=3e-5)
    contexts = rng.uniform(0, 2, size=(6, 2))
    params = rng.normal(size=(6, 25))
    returns, info = env.evaluate(contexts, params)
    angles = env.joint_trajectories(params)
    via = end_effector(angles.positions[:, VIA_STEP])
    final = end_effector(angles.positions[:, -1])
    np.testing.assert_allclose(info["via_position"], via)
    np.testing.assert_allclose(info["via_distance"], np.hypot(*(via - contexts).T))
    np.testing.assert_allclose(info["goal_distance"], np.hypot(*(final - GOAL).T))
    accel = angles.accelerations
    np.testing.assert_allclose(info["acceleration_cost"], 3e-5 * 0.01 * np.einsum("ntj,ntj->n", accel, accel))
    expected = -2.0 * (info["via_distance"] ** 2 + info["goal_distance"] ** 2) - info["acceleration_cost"]
    np.testing.assert_allclose(returns, expected, rtol=1e-13)
    assert np.all(info["acceleration_cost"] > 0)


def test_batch_equals_loop_exactly_for_evaluate_step_and_vector_env():
    rng = np.random.default_rng(1)
    contexts = rng.uniform(0, 2, size=(100, 2))
    params = rng.normal(scale=3.0, size=(100, 25))
    env = PlanarReacherEnv()
    returns, info = env.evaluate(contexts, params)
    for i in range(100):
        one, one_info = env.evaluate(contexts[i : i + 1], params[i : i + 1])
        assert one[0] == returns[i]
        for key, value in info.items():
            np.testing.assert_array_equal(one_info[key][0], value[i])
    vec = gym.make_vec(ENV_ID, num_envs=100)
    assert isinstance(vec.unwrapped, PlanarReacherVectorEnv)
    vec.reset(seed=0, options={"context": contexts})
    _, vec_returns, terminated, truncated, _ = vec.step(params)
    np.testing.assert_array_equal(vec_returns, returns)
    assert terminated.all() and not truncated.any()
    single = gym.make(ENV_ID)
    for i in (0, 50, 99):
        single.reset(options={"context": contexts[i]})
        assert single.step(params[i])[1] == returns[i]


def test_context_changes_the_outcome_but_not_the_motion():
    env = gym.make(ENV_ID)
    theta = np.random.default_rng(2).normal(size=25)
    outcomes = []
    for context in ([0.0, 0.0], [2.0, 2.0]):
        obs, info = env.reset(options={"context": context})
        np.testing.assert_array_equal(obs, context)
        np.testing.assert_array_equal(info["context"], context)
        outcomes.append(env.step(theta))
    (_, r0, *_, i0), (_, r1, *_, i1) = outcomes
    assert r0 != r1 and i0["via_distance"] != i1["via_distance"]
    np.testing.assert_array_equal(i0["via_position"], i1["via_position"])
    np.testing.assert_allclose(i0["via_distance"], np.linalg.norm(i0["via_position"]))


def test_same_seed_gives_the_same_contexts():
    a, b = gym.make(ENV_ID), gym.make(ENV_ID)
    obs_a = [a.reset(seed=5)[0] for _ in range(1)] + [a.reset()[0] for _ in range(3)]
    obs_b = [b.reset(seed=5)[0] for _ in range(1)] + [b.reset()[0] for _ in range(3)]
    np.testing.assert_array_equal(obs_a, obs_b)
    assert all(np.all((o >= 0) & (o <= 2)) for o in obs_a)


@EXTRAS
def test_rgb_array_render_shows_the_motion():
    env = gym.make(ENV_ID, render_mode="rgb_array")
    assert "human" not in env.metadata["render_modes"]
    env.reset(options={"context": [1.0, 1.0]})
    start = env.render()
    assert start.shape == (480, 480, 3) and start.dtype == np.uint8
    env.step(np.zeros(25))
    plain = env.render()
    env.reset(options={"context": [1.0, 1.0]})
    env.step(np.full(25, 0.7))
    bent = env.render()
    assert (plain != start).any() and (bent != plain).mean() > 0.01
    red = (bent[..., 0] > 200) & (bent[..., 1] < 60) & (bent[..., 2] < 60)
    assert red.sum() > 20  # the via-point cross


@EXTRAS
@pytest.mark.filterwarnings("ignore:.*symmetric and normalized")
def test_check_env_passes_including_the_render_check():
    check_env(gym.make(ENV_ID, render_mode="rgb_array").unwrapped)


def test_posture_shades_are_darkest_at_the_via_point():
    indices, grey = posture_shades(101, 50)
    assert indices[0] == 0 and indices[-1] == 100
    assert grey[indices == 50][0] == 0.0 and np.all(grey >= 0.0) and np.all(grey < 0.85)
    assert np.all(np.diff(grey[indices <= 50]) < 0) and np.all(np.diff(grey[indices >= 50]) > 0)


def test_render_without_matplotlib_says_which_extra_to_install(monkeypatch):
    env = PlanarReacherEnv(render_mode="rgb_array")
    env.reset(seed=0)
    monkeypatch.setitem(sys.modules, "matplotlib.backends.backend_agg", None)
    with pytest.raises(ImportError, match=r"creps-gym\[plot\]"):
        env.render()


def test_render_without_mode_or_before_reset():
    assert PlanarReacherEnv().render() is None
    with pytest.raises(RuntimeError, match="before reset"):
        PlanarReacherEnv(render_mode="rgb_array").render()
    with pytest.raises(ValueError, match="render_mode"):
        PlanarReacherEnv(render_mode="human")


def test_errors_name_the_argument():
    env = PlanarReacherEnv()
    with pytest.raises(ValueError, match="contexts: expected as many rows as params"):
        env.evaluate(np.zeros((2, 2)), np.zeros((3, 25)))
    with pytest.raises(ValueError, match=r"params: expected shape \(n, 25\)"):
        env.evaluate(np.zeros((1, 2)), np.zeros((1, 24)))
    with pytest.raises(ValueError, match="params: expected finite"):
        env.evaluate(np.zeros((1, 2)), np.full((1, 25), np.inf))
    with pytest.raises(ValueError, match="context box"):
        env.reset(options={"context": [2.5, 0.0]})
    with pytest.raises(ValueError, match="acceleration_weight: expected a finite value >= 0"):
        PlanarReacherEnv(acceleration_weight=-1.0)
    with pytest.raises(TypeError, match="position_weight"):
        PlanarReacherEnv(position_weight="1")
    with pytest.raises(ValueError, match="n_basis: expected an integer >= 1"):
        PlanarReacherEnv(n_basis=0)
    with pytest.raises(ValueError, match="angles: expected shape"):
        forward_kinematics(0.5)


def test_basis_count_sets_the_parameter_count():
    env = PlanarReacherEnv(n_basis=3)
    assert env.action_space.shape == (15,)
    traj = env.joint_trajectories(np.ones((1, 15)))
    # Joint 2 gets weights 1 on all its basis functions: a set-point shift of exactly the phase.
    np.testing.assert_allclose(traj.forcing[0, :, 1], 25.0 * 6.25 * traj.phase)


def test_registration_is_json_serialisable_without_time_limit():
    spec = gym.spec(ENV_ID)
    assert spec.max_episode_steps is None and spec.vector_entry_point is not None
    assert gym.make(ENV_ID).spec.to_json()


@pytest.mark.slow
def test_creps_cma_old_learns_to_pass_the_via_points():
    env = PlanarReacherEnv()
    test_contexts = np.random.default_rng(123).uniform(0, 2, size=(50, 2))
    rng = np.random.default_rng(4)
    opt = CREPSCMA(25, 2, variant="old", initial_mean=0.0, initial_cov=1.0, seed=4)
    start, _ = env.evaluate(test_contexts, opt.recommend(test_contexts))
    for _ in range(150):
        contexts = rng.uniform(0, 2, size=(100, 2))
        params = opt.ask(contexts)
        opt.tell(contexts, params, env.evaluate(contexts, params)[0])
    final, info = env.evaluate(test_contexts, opt.recommend(test_contexts))
    assert start.mean() < -10.0  # the plain DMP misses every via-point by metres
    assert final.mean() > 0.02 * start.mean()  # the cost falls by more than 98 %
    assert np.median(info["via_distance"]) < 0.2 and np.median(info["goal_distance"]) < 0.1
