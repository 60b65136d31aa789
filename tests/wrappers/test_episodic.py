"""Episodic conversion of step-based tasks: controllers, context accessors, registered ecosystem examples."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from decimal import Decimal

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.utils.env_checker import check_env

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.movement import DiscreteDMP, DMPConfig
from creps_gym.optimizers import CREPSCMA
from creps_gym.wrappers import (
    DMPController,
    EpisodicEnv,
    EpisodicVectorEnv,
    FixedContextsVector,
    GoalContext,
    LinearFeedbackController,
    QposContext,
    TrackingDMPController,
    make_controller,
)
from creps_gym.wrappers.examples import REGISTRATIONS

pytestmark = pytest.mark.filterwarnings("ignore:.*symmetric and normalized")
needs_mujoco = pytest.mark.skipif(
    not all(importlib.util.find_spec(name) for name in ("mujoco", "gymnasium_robotics")),
    reason="the ecosystem examples need the mujoco extra (pip install creps-gym[mujoco])",
)

EXAMPLE_IDS = [entry["id"] for entry in REGISTRATIONS]
MAZE = "creps_gym/PointMazeGoal-v0"
REACHER = "creps_gym/ReacherTarget-v0"


class PointGoal(gym.Env):
    """Tiny goal-conditioned inner env: a damped point in the plane, reward -|x - g|, ends within 0.05."""

    metadata = {"render_modes": []}  # noqa: RUF012

    def __init__(self) -> None:
        box = spaces.Box(-5.0, 5.0, (2,), np.float64)
        self.observation_space = spaces.Dict(
            {"achieved_goal": box, "desired_goal": box, "observation": spaces.Box(-10, 10, (4,), np.float64)}
        )
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.goal = None

    def _obs(self):
        state = np.r_[self.pos, self.vel]
        return {"achieved_goal": self.pos.copy(), "desired_goal": self.goal.copy(), "observation": state}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos, self.vel = self.np_random.uniform(-0.1, 0.1, 2), np.zeros(2)
        self.goal = self.np_random.uniform(-1.0, 1.0, 2)
        return self._obs(), {}

    def step(self, action):
        self.vel = 0.8 * self.vel + 0.1 * np.asarray(action, dtype=np.float64)
        self.pos = self.pos + self.vel
        distance = float(np.linalg.norm(self.pos - self.goal))
        return self._obs(), -distance, distance < 0.05, False, {"distance": distance}


def point_env(controller=None, **kwargs):
    if controller is None:
        controller = {"type": "linear", "indices": [0, 1, 2, 3, 6, 7], "gain_bound": 5.0}
    context = GoalContext([-1.0, -1.0], [1.0, 1.0])
    return EpisodicEnv(PointGoal(), controller, context, max_inner_steps=40, **kwargs)


# -- the conversion on a tiny inner env -------------------------------------------------------------------
def test_return_equals_a_hand_rolled_loop_with_linear_feedback():
    env = point_env()
    theta = np.random.default_rng(0).uniform(-1, 1, env.param_dim)
    env.reset(options={"context": [0.4, -0.6]})
    _, reward, terminated, truncated, info = env.step(theta)
    inner = PointGoal()
    obs, _ = inner.reset(seed=0)
    inner.goal = np.array([0.4, -0.6])
    obs["desired_goal"] = inner.goal.copy()
    gains, total = theta.reshape(2, 7), 0.0
    for step in range(40):  # noqa: B007  (the step count is checked below)
        flat = np.r_[obs["achieved_goal"], obs["desired_goal"], obs["observation"]]
        action = np.clip(gains[:, :6] @ flat[[0, 1, 2, 3, 6, 7]] + gains[:, 6], -1, 1).astype(np.float32)
        obs, r, done, _, last = inner.step(action)
        total += r
        if done:
            break
    assert reward == total and terminated and not truncated
    assert info["inner_length"] == step + 1 and info["inner_terminated"] == done
    assert info["inner_truncated"] == (not done) and info["inner_info"] == last


def test_a_goal_seeking_policy_terminates_early_and_the_context_changes_the_return():
    env = point_env()
    theta = np.zeros((2, 7))
    theta[:, 0:2] = -5 * np.eye(2)  # - K x
    theta[:, 2:4] = 5 * np.eye(2)  # + K g
    theta[:, 4:6] = -3 * np.eye(2)  # - D v
    returns, info = env.evaluate(np.array([[0.5, 0.5], [-0.8, 0.3]]), np.tile(theta.ravel(), (2, 1)))
    assert info["inner_terminated"].all() and (info["inner_length"] < 40).all()
    lazy, lazy_info = env.evaluate(np.array([[0.5, 0.5], [-0.8, 0.3]]), np.zeros((2, 14)))
    assert returns[0] != returns[1] and lazy[0] != lazy[1]
    assert (returns > lazy).all() and lazy_info["inner_truncated"].all()


def test_contexts_are_taken_from_the_inner_env_and_seeded():
    env = point_env()
    context, _ = env.reset(seed=4)
    inner = PointGoal()
    obs, _ = inner.reset(seed=int(seeding.np_random(4)[0].integers(2**31)))
    np.testing.assert_array_equal(context, obs["desired_goal"])
    other = point_env()
    np.testing.assert_array_equal(other.reset(seed=4)[0], context)
    theta = np.linspace(-1, 1, 14)
    assert env.step(theta)[1] == other.step(theta)[1]


def test_custom_controller_protocol_and_check_env():
    class Constant:
        action_dim, observation_dim = 2, None
        param_low, param_high = -np.ones(2), np.ones(2)

        def start(self, params, observation):
            self.params = params

        def act(self, step, observation):
            return self.params

    env = point_env(Constant())
    check_env(env, skip_render_check=True)
    env.reset(options={"context": [0.0, 0.0]})
    _, still, *_ = env.step(np.zeros(2))
    env.reset(options={"context": [0.0, 0.0]})
    _, moving, *_ = env.step(np.ones(2))
    assert moving < still


class NoActDim:
    observation_dim, param_low, param_high = None, np.zeros(1), np.ones(1)


def _swapped_bounds(controller):
    controller.param_low, controller.param_high = controller.param_high, controller.param_low
    return controller


@pytest.mark.parametrize(
    ("build", "error", "message"),
    [
        (lambda: point_env(DMPController(3, 40)), ValueError, "controller: expected action_dim 2"),
        (lambda: point_env(LinearFeedbackController(5, 2)), ValueError, "observation_dim 8"),
        (lambda: point_env(NoActDim()), TypeError, "controller: expected a Controller"),
        (lambda: point_env({"type": "pid"}), ValueError, "controller\\['type'\\]"),
        (lambda: point_env({"kind": "dmp"}), TypeError, "'type' key"),
        (lambda: point_env({"type": "linear", "indices": [9]}), ValueError, "indices: expected values in"),
        (lambda: point_env({"type": "dmp"}, start_seed=-1), ValueError, "start_seed"),
        (
            lambda: EpisodicEnv(PointGoal(), {"type": "dmp"}, GoalContext([0.0], [1.0]), max_inner_steps=40),
            ValueError,
            "context low/high: expected shape \\(2,\\)",
        ),
        (
            lambda: EpisodicEnv("CartPole-v1", {"type": "dmp"}, GoalContext([0, 0], [1, 1])),
            TypeError,
            "Box action space",
        ),
        (
            lambda: EpisodicEnv("Pendulum-v1", {"type": "dmp"}, GoalContext([0, 0], [1, 1])),
            TypeError,
            "GoalContext expected a goal-conditioned env",
        ),
        (
            lambda: EpisodicEnv(
                PointGoal(), {"type": "dmp"}, QposContext([0, 1], [0, 0], [1, 1]), max_inner_steps=40
            ),
            TypeError,
            "QposContext expected a Gymnasium MuJoCo env",
        ),
        (
            lambda: EpisodicEnv(PointGoal(), {"type": "dmp"}, GoalContext([-1, -1], [1, 1])),
            ValueError,
            "no time limit",
        ),
        (
            lambda: EpisodicEnv(PointGoal(), {"type": "dmp"}, "goal", max_inner_steps=40),
            TypeError,
            "context: expected a ContextAccess",
        ),
        (lambda: DMPController(2, 8), ValueError, "horizon: expected at least 16 inner steps .* stable"),
        (
            lambda: EpisodicEnv(
                PointGoal(), {"type": "dmp"}, GoalContext([-1, -1], [1, 1]), max_inner_steps=5
            ),
            ValueError,
            "horizon: expected at least 16 inner steps .* max_inner_steps .* got 5",
        ),
        (
            lambda: EpisodicEnv(
                "Pendulum-v1", {"type": "dmp"}, GoalContext([0, 0], [1, 1]), max_inner_steps=0
            ),
            ValueError,
            "max_inner_steps: expected an integer >= 1, got 0",
        ),
        (
            lambda: EpisodicEnv(
                "Pendulum-v1", {"type": "dmp"}, GoalContext([0, 0], [1, 1]), max_inner_steps=2.5
            ),
            TypeError,
            "max_inner_steps: expected an integer >= 1, got float",
        ),
        (
            lambda: point_env(_swapped_bounds(DMPController(2, 40))),
            ValueError,
            r"controller.param_low, controller.param_high: expected param_low < param_high, got 1.0 and -1.0",
        ),
        (lambda: DMPController(2, 40, start=[0.0, 0.0, 1.0]), ValueError, "start: expected a scalar"),
        (
            lambda: TrackingDMPController(4, [0, 1], [2], 40, [0, 0], [1, 1]),
            ValueError,
            "velocity_indices: expected 2 indices",
        ),
        (lambda: EpisodicEnv(3, {"type": "dmp"}, GoalContext([0, 0], [1, 1])), TypeError, "env: expected"),
        (
            lambda: EpisodicEnv(PointGoal(), {"type": "dmp"}, GoalContext([0, 0], [1, 1]), env_kwargs={1: 1}),
            ValueError,
            "env_kwargs: expected none",
        ),
    ],
)
def test_bad_inputs_get_clear_errors(build, error, message):
    with pytest.raises(error, match=message):
        build()


def test_bad_params_and_broken_controllers():
    env = point_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action: expected shape \(14,\)"):
        env.step(np.zeros(13))

    class Broken(DMPController):
        def act(self, step, observation):
            return np.full(2, np.nan)

    broken = point_env(Broken(2, 40))
    broken.reset(seed=0)
    with pytest.raises(RuntimeError, match=r"controller\.act: expected a finite action"):
        broken.step(np.zeros(10))


# -- controllers -------------------------------------------------------------------------------------------
def test_dmp_controller_plays_the_dmp_and_holds_the_last_action():
    controller = DMPController(2, 20, n_basis=3, weight_bound=2.0, start=[0.5, 0.0])
    theta = np.array([1.0, -1.0, 0.5, 0.0, 2.0, -2.0])
    controller.start(theta, np.zeros(0))
    config = DMPConfig(n_basis=3, weight_scale=25.0 * 6.25)
    expected = DiscreteDMP(2, config).rollout(theta[None], [0.5, 0.0], [0.0, 0.0], 20, 0.05).positions[0]
    played = np.array([controller.act(t, None) for t in range(25)])
    np.testing.assert_array_equal(played[:21], expected)
    np.testing.assert_array_equal(played[21:], np.tile(expected[-1], (4, 1)))
    np.testing.assert_array_equal(controller.param_high, np.full(6, 2.0))


def test_tracking_dmp_reference_runs_from_the_observed_start_to_the_goal():
    controller = make_controller(
        {"type": "tracking_dmp", "position_indices": [0, 1], "velocity_indices": [2, 3], "goal_low": [-1, -1]}
        | {"goal_high": [1, 1], "kp": 2.0, "kd": 0.5},
        observation_dim=4,
        action_dim=2,
        horizon=60,
    )
    assert isinstance(controller, TrackingDMPController) and controller.param_low.shape == (8,)
    observation = np.array([0.3, -0.2, 0.1, 0.0])
    controller.start(np.r_[0.8, 0.6, np.zeros(6)], observation)
    reference = controller.reference(np.r_[0.8, 0.6, np.zeros(6)][None], [0.3, -0.2])[0]
    np.testing.assert_array_equal(reference[0], [0.3, -0.2])
    np.testing.assert_allclose(reference[-1], [0.8, 0.6], atol=1e-3)
    np.testing.assert_allclose(controller.act(0, observation), -0.5 * observation[2:])
    later = controller.act(30, observation)
    np.testing.assert_allclose(later, 2.0 * (reference[30] - observation[:2]) - 0.5 * observation[2:])


# -- native vector version and wrappers ---------------------------------------------------------------
def test_episodic_vector_env_matches_scalar_rollouts_with_per_env_contexts():
    kwargs = {"env": PointGoal(), "context": GoalContext([-1, -1], [1, 1]), "max_inner_steps": 40}
    vec = FixedContextsVector(
        EpisodicVectorEnv(2, controller={"type": "dmp", "n_basis": 3}, **kwargs), [[0.5, 0.5], [-0.5, 0.2]]
    )
    obs, _ = vec.reset(seed=0)
    theta = np.random.default_rng(1).uniform(-1, 1, (2, 6))
    _, rewards, _, _, info = vec.step(theta)
    single = point_env({"type": "dmp", "n_basis": 3})
    expected = [single.rollout(c, t)[0] for c, t in zip(obs, theta, strict=True)]
    np.testing.assert_array_equal(rewards, expected)
    assert rewards[0] != rewards[1]
    np.testing.assert_array_equal(info["final_info"]["inner_length"], [40, 40])
    vec.close()


# -- the registered ecosystem examples -------------------------------------------------------------------
def test_importing_the_examples_imports_neither_mujoco_nor_gymnasium_robotics():
    code = (
        "import sys, creps_gym.wrappers.examples; "
        "print('mujoco' in sys.modules, 'gymnasium_robotics' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


@needs_mujoco
@pytest.mark.parametrize("env_id", EXAMPLE_IDS)
def test_every_example_resets_passes_check_env_and_is_deterministic(env_id):
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    context, _ = env.reset(seed=3)
    assert env.observation_space.contains(context)
    theta = np.random.default_rng(0).uniform(env.action_space.low, env.action_space.high)
    first = env.step(theta)
    twin = gym.make(env_id)
    np.testing.assert_array_equal(twin.reset(seed=3)[0], context)
    assert twin.step(theta)[1] == first[1]
    low, high = env.observation_space.low, env.observation_space.high
    returns, _ = env.unwrapped.evaluate(np.vstack([0.7 * low, 0.7 * high]), np.tile(theta, (2, 1)))
    assert returns[0] != returns[1]


@needs_mujoco
def test_maze_return_equals_a_hand_rolled_loop_over_point_maze():
    env = gym.make(MAZE).unwrapped
    goal, theta = np.array([1.6, -0.9]), np.r_[1.5, -1.0, 0.3, -0.2, 0.1, 0.0, 0.4, -0.4]
    env.reset(options={"context": goal})
    _, reward, _, _, info = env.step(theta)
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    inner = gym.make(
        "PointMaze_OpenDense-v3", continuing_task=True, reset_target=False, max_episode_steps=100
    )
    obs, _ = inner.reset(seed=0, options={"reset_cell": [2, 3]})
    inner.unwrapped.goal = goal.copy()
    dmp = DiscreteDMP(2, DMPConfig(n_basis=3, weight_scale=25.0 * 6.25))
    reference = dmp.rollout(theta[None, 2:], obs["observation"][:2], theta[:2], 100, 0.01).positions[0]
    total, steps, truncated = 0.0, 0, False
    while not truncated:
        force = 5.0 * (reference[steps] - obs["observation"][:2]) - obs["observation"][2:]
        obs, r, _, truncated, last = inner.step(np.clip(force, -1, 1).astype(np.float32))
        total, steps = total + r, steps + 1
    assert reward == total and info["inner_length"] == 100 == steps
    assert info["inner_info"] == last and info["inner_truncated"]
    np.testing.assert_array_equal(obs["desired_goal"], goal)


@needs_mujoco
def test_reacher_return_equals_a_hand_rolled_loop_and_the_target_is_the_context():
    env = gym.make(REACHER).unwrapped
    target, theta = np.array([0.12, -0.05]), np.linspace(-0.8, 0.8, 8)
    env.reset(options={"context": target})
    _, reward, *_ = env.step(theta)
    inner = gym.make("Reacher-v5", max_episode_steps=50)
    inner.reset(seed=0)
    qpos, qvel = inner.unwrapped.data.qpos.copy(), inner.unwrapped.data.qvel.copy()
    qpos[2:4] = target
    inner.unwrapped.set_state(qpos, qvel)
    dmp = DiscreteDMP(2, DMPConfig(n_basis=4, weight_scale=25.0 * 6.25))
    torques = dmp.rollout(theta[None], [0.0, 0.0], [0.0, 0.0], 50, 0.02).positions[0]
    total = 0.0
    for step in range(50):
        obs, r, *_ = inner.step(np.clip(torques[step], -1, 1).astype(np.float32))
        total += r
    assert reward == total
    np.testing.assert_array_equal(obs[4:6], target)  # Reacher-v5 observes its target at 4:6


@needs_mujoco
@pytest.mark.slow
def test_async_vector_env_runs_converted_episodes_in_subprocesses():
    vec = gym.make_vec(MAZE, num_envs=2, vectorization_mode="async")
    try:
        contexts, _ = vec.reset(seed=5)
        theta = np.random.default_rng(2).uniform(-1, 1, (2, 8))
        _, rewards, terminated, _, info = vec.step(theta)
    finally:
        vec.close()
    serial = gym.make(MAZE).unwrapped
    np.testing.assert_array_equal(rewards, serial.evaluate(contexts, theta)[0])
    assert terminated.all() and (info["inner_length"] == 100).all()


@needs_mujoco
@pytest.mark.slow
def test_the_runner_vector_backend_runs_episodes_in_parallel_with_the_serial_returns():
    from creps_gym.runner import run

    serial, parallel = (
        run("creps-cma-old", MAZE, 2, 16, 0, backend=backend, workers=2) for backend in ("serial", "vector")
    )
    assert parallel.equals(serial)
    assert np.isfinite(serial.column("mean_return")).all()


@needs_mujoco
@pytest.mark.slow
def test_creps_cma_old_learns_goal_dependent_reaching_in_point_maze():
    env = gym.make(MAZE).unwrapped
    test = env.sample_contexts(np.random.default_rng(123), 16)
    opt = CREPSCMA(env.param_dim, env.context_dim, variant="old", epsilon=0.5, initial_cov=0.25, seed=0)

    def success(contexts):
        returns, info = env.evaluate(contexts, opt.recommend(contexts))
        return returns.mean(), np.mean([i["success"] for i in info["inner_info"]])

    start_return, start_success = success(test)
    rng = np.random.default_rng(1)
    for _ in range(10):
        contexts = env.sample_contexts(rng, 30)
        params = opt.ask(contexts)
        opt.tell(contexts, params, env.evaluate(contexts, params)[0])
    end_return, end_success = success(test)
    assert start_success < 0.3 and end_success >= 0.9
    assert end_return > start_return + 20.0
    goals = opt.recommend(test)[:, :2]  # the learned DMP goal follows the context
    assert min(np.corrcoef(goals[:, k], test[:, k])[0, 1] for k in range(2)) > 0.9


class _RewardOf(PointGoal):
    """PointGoal whose step returns a given reward object."""

    def __init__(self, reward) -> None:
        super().__init__()
        self.reward = reward

    def step(self, action):
        observation, _, terminated, truncated, info = super().step(action)
        return observation, self.reward, terminated, truncated, info


@pytest.mark.parametrize(
    "reward",
    ["1.5", True, np.bool_(True), Decimal("1"), np.complex128(1 + 2j), 1 + 0j, np.array([1.0]), None],
    ids=repr,
)
def test_an_inner_reward_that_is_not_a_real_number_is_refused_not_converted(reward):
    controller = {"type": "linear", "indices": [0, 1, 2, 3, 6, 7], "gain_bound": 5.0}
    env = EpisodicEnv(_RewardOf(reward), controller, GoalContext([-1.0, -1.0], [1.0, 1.0]), max_inner_steps=5)
    env.reset(seed=0)
    with pytest.raises(TypeError, match=rf"reward: expected a real number .* got {type(reward).__name__} "):
        env.step(np.zeros(env.param_dim))


@pytest.mark.parametrize("reward", [2, 1.5, np.float32(1.5), np.int64(2), np.array(1.5)], ids=repr)
def test_real_inner_rewards_of_any_numeric_type_are_summed(reward):
    controller = {"type": "linear", "indices": [0, 1, 2, 3, 6, 7], "gain_bound": 5.0}
    env = EpisodicEnv(_RewardOf(reward), controller, GoalContext([-1.0, -1.0], [1.0, 1.0]), max_inner_steps=5)
    env.reset(seed=0)
    assert env.step(np.zeros(env.param_dim))[1] == 5 * float(reward)
