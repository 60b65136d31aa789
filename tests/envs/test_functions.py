"""The 15 contextual test functions: formulas, optima, instances, vector env, autoreset modes, errors."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.base import ContextualEpisodicEnv, SupportsRegret
from creps_gym.envs.evaluation import evaluate_policy, test_contexts
from creps_gym.envs.functions import ENV_CLASSES, REGISTRATIONS, SPECS
from creps_gym.envs.functions import definitions as d
from creps_gym.envs.functions.instance import haar_orthogonal

BOUNDED = [cls for cls, _ in ENV_CLASSES if cls.function.bounded]
UNBOUNDED = [cls for cls, _ in ENV_CLASSES if not cls.function.bounded]
CLASS_IDS = [cls.function.name for cls, _ in ENV_CLASSES]

# Hand-computed values: f(x) for one point per kernel, in canonical coordinates.
HAND_VALUES = {
    # 100 (2 - 1)^2 + 0^2 + 100 (3 - 4)^2 + (1 - 2)^2
    "Rosenbrock": ([1.0, 2.0, 3.0], 201.0),
    "Sphere": ([1.0, 2.0, 3.0], 14.0),
    "ShiftedSphere": ([1.0, -2.0, 3.0], 14.0),
    # cumulative sums 1, 3, 6
    "ShiftedSchwefel": ([1.0, 2.0, 3.0], 1.0 + 9.0 + 36.0),
    # 1 + 1e8 * 9 + 1e4 * 4
    "CigTab": ([1.0, 2.0, 3.0], 900_040_001.0),
    "Tablet": ([1.0, 2.0, 3.0], 1e6 + 4.0 + 9.0),
    # weights 1, 1e3, 1e6
    "ShiftedRotatedElliptic": ([1.0, 2.0, 3.0], 1.0 + 4e3 + 9e6),
    # weights 1, 1e2, 1e4
    "ShiftedRotatedElliptic1e4": ([1.0, 2.0, 3.0], 1.0 + 400.0 + 90_000.0),
    # exponents 2, 7, 12
    "DifferentPowers": ([1.0, -2.0, 3.0], 1.0 + 128.0 + 531_441.0),
    "Plane": ([-7.0, 2.0, 3.0], -7.0),
    # floor(4 / 2) = 2 heavy axes
    "TwoAxes": ([1.0, 2.0, 3.0, 4.0], 1e6 * 5.0 + 25.0),
    "Cigar": ([1.0, 2.0, 3.0], 1.0 + 1e6 * 13.0),
    # 30 + (0.25 + 10) + (0 - 10) + (1 - 10)
    "Rastrigin": ([0.5, 0.0, 1.0], 21.25),
    "ParabolicRidge": ([1.0, 3.0, 4.0], 1.0 + 100.0 * 25.0),
    "SharpRidge": ([1.0, 3.0, 4.0], 1.0 + 100.0 * 5.0),
}


def _contexts(rng, n, z):
    return rng.uniform(0.0, 3.0, size=(n, z))


def test_suite_has_the_15_functions_of_table_1():
    names = [spec.name for spec in SPECS]
    assert sorted(names) == sorted(HAND_VALUES)
    assert len(set(names)) == 15
    assert [cls.function.name for cls in UNBOUNDED] == ["Plane", "ParabolicRidge", "SharpRidge"]


@pytest.mark.parametrize("spec", SPECS, ids=lambda spec: spec.name)
def test_kernel_matches_hand_computed_value(spec):
    point, expected = HAND_VALUES[spec.name]
    x = np.array([point])
    value = spec.kernel(x)
    np.testing.assert_array_equal(x, [point])  # kernels never write to their input
    assert value.shape == (1,)
    np.testing.assert_allclose(value[0], expected, rtol=1e-12, atol=1e-12)


def test_kernels_in_dimension_two():
    x = np.array([[3.0, -2.0]])
    assert d.cigtab(x)[0] == 9.0 + 1e8 * 4.0  # the middle sum is empty
    assert d.two_axes(x)[0] == 1e6 * 9.0 + 4.0
    assert d.different_powers(x)[0] == 9.0 + 2.0**12
    assert d.elliptic(x)[0] == 9.0 + 1e6 * 4.0
    assert d.rosenbrock(np.ones((1, 2)))[0] == 0.0


@pytest.mark.parametrize("env_class", [cls for cls, _ in ENV_CLASSES], ids=CLASS_IDS)
def test_env_objective_is_the_textbook_formula(env_class):
    """f(theta + A s), with the shift and rotation applied by plain numpy, matches the env to rounding."""
    rng = np.random.default_rng(1)
    env = env_class(dim=6, context_dim=3, instance=4)
    contexts, params = _contexts(rng, 20, 3), rng.uniform(-5, 5, size=(20, 6))
    x = params + contexts @ env.problem.matrix.T
    if env.function.shifted:
        x = x - env.problem.shift
    if env.function.rotated:
        x = x @ env.problem.rotation.T
    expected = env.function.kernel(x)
    returns, _ = env.evaluate(contexts, params)
    np.testing.assert_allclose(-returns, expected, rtol=1e-9)
    np.testing.assert_allclose(env.objective(contexts, params), expected, rtol=1e-9)


@pytest.mark.parametrize("env_class", BOUNDED, ids=lambda cls: cls.function.name)
@pytest.mark.parametrize(("dim", "context_dim"), [(2, 1), (15, 1), (9, 3), (64, 5), (4, 0)])
def test_optimum_gives_f_opt_exactly_and_perturbations_do_worse(env_class, dim, context_dim):
    rng = np.random.default_rng(dim * 10 + context_dim)
    env = env_class(dim=dim, context_dim=context_dim, instance=2)
    assert isinstance(env, SupportsRegret)
    contexts = _contexts(rng, 30, context_dim)
    best = env.optimal_params(contexts)
    returns, info = env.evaluate(contexts, best)
    np.testing.assert_array_equal(returns, -env.f_opt)
    np.testing.assert_array_equal(info["regret"], 0.0)
    np.testing.assert_array_equal(info["optimal_params"], best)
    np.testing.assert_array_equal(env.regret(contexts, best), 0.0)
    assert env.solved(contexts, best).all()
    for scale in (1e-3, 1.0):
        worse = best + scale * rng.standard_normal(best.shape)
        assert (env.regret(contexts, worse) > 0.0).all()
        np.testing.assert_array_equal(env.regret(contexts, worse), -env.evaluate(contexts, worse)[0])
    assert not env.solved(contexts, best + 1.0).any()


@pytest.mark.parametrize("env_class", BOUNDED, ids=lambda cls: cls.function.name)
def test_optimum_moves_linearly_with_the_context(env_class):
    env = env_class(dim=5, context_dim=2, instance=3)
    contexts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 3.0]])
    best = env.optimal_params(contexts)
    a = env.problem.matrix
    np.testing.assert_allclose(best[1] - best[0], -a[:, 0], atol=1e-12)
    np.testing.assert_allclose(best[2] - best[0], -a[:, 1], atol=1e-12)
    np.testing.assert_allclose(best[3], best[0] - 2 * a[:, 0] - 3 * a[:, 1], atol=1e-12)
    expected_x = env.problem.shift if env.function.shifted else env.function.canonical_point(5)
    np.testing.assert_allclose(best[0], expected_x, atol=0)


@pytest.mark.parametrize("env_class", UNBOUNDED, ids=lambda cls: cls.function.name)
def test_unbounded_functions_expose_the_target_not_a_regret(env_class):
    env = env_class(dim=4, context_dim=2, instance=1)
    assert not isinstance(env, SupportsRegret)
    assert not hasattr(env, "optimal_params") and not hasattr(env, "regret")
    assert env.target == -1e4
    rng = np.random.default_rng(0)
    contexts = _contexts(rng, 5, 2)
    params = rng.uniform(-5, 5, size=(5, 4))
    values = env.objective(contexts, params)
    returns, info = env.evaluate(contexts, params)
    np.testing.assert_array_equal(returns, -values)
    np.testing.assert_array_equal(info["target_gap"], values + 1e4)
    np.testing.assert_array_equal(env.target_gap(contexts, params), values + 1e4)
    assert not env.solved(contexts, params).any()
    # Walking down -x_1 on the ridge axis (x_i = 0 for i >= 2) reaches the target.
    walk = -(contexts @ env.problem.matrix.T)
    walk[:, 0] -= 2e4
    assert env.solved(contexts, walk).all()
    assert (env.target_gap(contexts, walk) <= 0).all()


@pytest.mark.parametrize("env_class", [cls for cls, _ in ENV_CLASSES], ids=CLASS_IDS)
def test_parameter_box_contains_every_optimum(env_class):
    env = env_class(dim=12, context_dim=3, instance=5)
    low, high = env.action_space.low, env.action_space.high
    assert np.isfinite(low).all() and np.isfinite(high).all()
    assert (low <= -5.0).all() and (high >= 5.0).all()
    corners = np.array(np.meshgrid(*[[0.0, 3.0]] * 3)).reshape(3, -1).T  # theta* is affine: corners suffice
    assert np.array_equal(env.observation_space.low, np.zeros(3))
    assert np.array_equal(env.observation_space.high, np.full(3, 3.0))
    if env.function.bounded:
        best = env.optimal_params(np.vstack([corners, _contexts(np.random.default_rng(0), 100, 3)]))
        assert ((best > low) & (best < high)).all()
        assert (low < -5.0).any() or (high > 5.0).any()  # |A s| reaches 9 for z = 3: the box grew
    else:
        np.testing.assert_array_equal(low, -5.0)
        np.testing.assert_array_equal(high, 5.0)


@pytest.mark.parametrize("env_class", [cls for cls, _ in ENV_CLASSES], ids=CLASS_IDS)
def test_instances_follow_the_documented_recipe(env_class):
    env = env_class(dim=7, context_dim=2, instance=11)
    twin = env_class(dim=7, context_dim=2, instance=11)
    other = env_class(dim=7, context_dim=2, instance=12)
    seeds = np.random.SeedSequence(11).spawn(3)
    matrix = np.random.default_rng(seeds[0]).uniform(-1, 1, size=(7, 2))
    np.testing.assert_array_equal(env.problem.matrix, matrix)
    np.testing.assert_array_equal(twin.problem.matrix, matrix)
    assert not np.array_equal(other.problem.matrix, matrix)
    np.testing.assert_array_equal(env.action_space.low, twin.action_space.low)
    if env.function.shifted:
        shift = np.random.default_rng(seeds[1]).uniform(-4, 4, size=7)
        np.testing.assert_array_equal(env.problem.shift, shift)
    else:
        np.testing.assert_array_equal(env.problem.shift, 0.0)
    if env.function.rotated:
        rotation = env.problem.rotation
        np.testing.assert_array_equal(rotation, twin.problem.rotation)
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(7), atol=1e-14)
        gaussian = np.random.default_rng(seeds[2]).standard_normal((7, 7))
        upper = rotation.T @ gaussian  # Q^T G = R: upper triangular with a positive diagonal
        np.testing.assert_allclose(np.tril(upper, -1), 0.0, atol=1e-12)
        assert (np.diag(upper) > 0).all()
    else:
        assert env.problem.rotation is None
    assert not env.problem.matrix.flags.writeable


def test_haar_orthogonal_is_orthogonal_in_high_dimension():
    rotation = haar_orthogonal(np.random.default_rng(0), 64)
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(64), atol=1e-13)


def test_context_sampling_is_the_uniform_draw_of_the_base_class():
    env = BOUNDED[0](dim=3, context_dim=4)
    mine = env.sample_contexts(np.random.default_rng(3), 50)
    base = ContextualEpisodicEnv.sample_contexts(env, np.random.default_rng(3), 50)
    np.testing.assert_array_equal(mine, base)
    assert mine.shape == (50, 4) and (mine >= 0).all() and (mine <= 3).all()


@pytest.mark.parametrize(("env_class", "vector_class"), ENV_CLASSES, ids=CLASS_IDS)
def test_vector_env_equals_scalar_env_bit_for_bit(env_class, vector_class):
    rng = np.random.default_rng(7)
    kwargs = {"dim": 15, "context_dim": 3, "instance": 1}
    contexts, params = _contexts(rng, 25, 3), rng.uniform(-6, 6, size=(25, 15))
    vector = gym.make_vec(f"creps_gym/{env_class.function.name}-v0", num_envs=25, **kwargs)
    assert type(vector) is vector_class
    obs, reset_info = vector.reset(seed=0, options={"context": contexts})
    np.testing.assert_array_equal(obs, contexts)
    _, rewards, terminated, truncated, info = vector.step(params)
    assert terminated.all() and not truncated.any()
    final = info["final_info"]
    single = env_class(**kwargs)
    bounded = env_class.function.bounded
    reset_keys = {"context", "optimal_params"} if bounded else {"context"}
    step_keys = {"context", "regret", "optimal_params"} if bounded else {"context", "target_gap"}
    assert set(single.reset(seed=0)[1]) == reset_keys
    assert set(single.step(params[0])[4]) == step_keys
    for k in range(25):
        _, info_k = single.reset(options={"context": contexts[k]})
        _, reward, _, _, step_info = single.step(params[k])
        assert reward == rewards[k]
        for key, value in step_info.items():
            np.testing.assert_array_equal(final[key][k], value)
        for key, value in info_k.items():
            np.testing.assert_array_equal(reset_info[key][k], value)


@pytest.mark.parametrize("env_class", [cls for cls, _ in ENV_CLASSES], ids=CLASS_IDS)
@pytest.mark.parametrize(("dim", "context_dim"), [(2, 1), (15, 3), (64, 5)])
def test_each_row_is_independent_of_the_batch(env_class, dim, context_dim):
    """Bigger batches (BLAS kernels change with the batch size): each row equals the row evaluated alone."""
    rng = np.random.default_rng(dim)
    env = env_class(dim=dim, context_dim=context_dim, instance=3)
    contexts, params = _contexts(rng, 300, context_dim), rng.uniform(-6, 6, size=(300, dim))
    returns, batch_info = env.evaluate(contexts, params)
    for k in range(0, 300, 13):
        returns_k, info_k = env.evaluate(contexts[k : k + 1], params[k : k + 1])
        assert returns_k[0] == returns[k]
        for key, value in info_k.items():
            np.testing.assert_array_equal(batch_info[key][k], value[0])


def test_make_vec_same_step_autoreset_draws_new_contexts():
    contexts = np.array([[0.5], [1.5], [2.5], [3.0]])
    vector = gym.make_vec("creps_gym/Sphere-v0", num_envs=4, dim=3)
    assert vector.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    vector.reset(seed=5, options={"context": contexts})
    params = np.zeros((4, 3))
    obs, rewards, terminated, _, info = vector.step(params)
    np.testing.assert_array_equal(info["final_obs"], contexts)
    np.testing.assert_array_equal(info["final_info"]["context"], contexts)
    assert terminated.all() and not np.array_equal(obs, contexts)
    np.testing.assert_array_equal(info["context"], obs)
    np.testing.assert_array_equal(info["optimal_params"], vector.model.optimal_params(obs))
    np.testing.assert_array_equal(rewards, -vector.model.regret(contexts, params))
    _, rewards_next, _, _, info_next = vector.step(params)  # no reset needed
    np.testing.assert_array_equal(rewards_next, -vector.model.regret(obs, params))
    np.testing.assert_array_equal(info_next["final_obs"], obs)


def test_make_vec_disabled_autoreset_and_reset_mask():
    contexts = np.array([[0.5, 1.0], [1.5, 2.0], [2.5, 0.0]])
    vector = gym.make_vec(
        "creps_gym/Rosenbrock-v0", num_envs=3, dim=4, context_dim=2, autoreset_mode="Disabled"
    )
    assert vector.metadata["autoreset_mode"] == AutoresetMode.DISABLED
    vector.reset(seed=1, options={"context": contexts})
    best = vector.model.optimal_params(contexts)
    obs, rewards, terminated, _, info = vector.step(best)
    np.testing.assert_array_equal(obs, contexts)
    np.testing.assert_array_equal(rewards, 0.0)
    np.testing.assert_array_equal(info["regret"], 0.0)
    assert terminated.all() and "final_info" not in info
    with pytest.raises(RuntimeError, match="not reset"):
        vector.step(best)
    mask = np.array([True, False, True])
    obs, _ = vector.reset(options={"context": contexts[mask], "reset_mask": mask})
    with pytest.raises(RuntimeError, match=r"\[1\]"):
        vector.step(best)
    vector.reset(options={"context": contexts[1:2], "reset_mask": ~mask})
    np.testing.assert_array_equal(vector.step(best)[1], 0.0)


def test_scalar_env_protocol_errors_leave_the_episode_usable():
    env = gym.make("creps_gym/CigTab-v0", dim=4).unwrapped
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(np.zeros(4))
    env.reset(seed=0, options={"context": [1.0]})
    with pytest.raises(ValueError, match=r"expected shape \(4,\)"):
        env.step(np.zeros(5))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([0.0, np.inf, 0.0, 0.0]))
    _, reward, terminated, truncated, info = env.step(env.optimal_params(np.array([[1.0]]))[0])
    assert (reward, terminated, truncated, info["regret"]) == (-0.0, True, False, 0.0)
    with pytest.raises(RuntimeError, match="terminated"):
        env.step(np.zeros(4))
    with pytest.raises(ValueError, match="context box"):
        env.reset(options={"context": [3.5]})
    with pytest.raises(ValueError, match="unknown keys"):
        env.reset(options={"contexts": [1.0]})
    with pytest.raises(TypeError, match=r"options: expected a dict such as .* or None, got str"):
        env.reset(options="context")


@pytest.mark.filterwarnings("ignore:.*render_mode")
@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"dim": 1}, ValueError, "dim: expected an integer >= 2, got 1"),
        ({"dim": 2.5}, TypeError, "dim"),
        ({"context_dim": -1}, ValueError, "context_dim: expected an integer >= 0, got -1"),
        ({"instance": -1}, ValueError, "instance: expected an integer >= 0, got -1"),
        ({"instance": "0"}, TypeError, "instance"),
        ({"render_mode": "human"}, ValueError, "render_mode"),
    ],
)
def test_bad_constructor_arguments_are_rejected(kwargs, error, match):
    with pytest.raises(error, match=match):
        gym.make("creps_gym/Sphere-v0", **kwargs)


def test_batch_methods_reject_bad_input():
    env = BOUNDED[0](dim=3, context_dim=2)
    good_c, good_p = np.ones((2, 2)), np.zeros((2, 3))
    with pytest.raises(ValueError, match="as many rows"):
        env.evaluate(good_c, np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"params: expected shape \(n, 3\)"):
        env.regret(good_c, np.zeros((2, 4)))
    with pytest.raises(ValueError, match="contexts: expected finite"):
        env.evaluate(np.array([[1.0, np.nan], [1.0, 1.0]]), good_p)
    with pytest.raises(ValueError, match=r"contexts: expected shape \(n, 2\)"):
        env.optimal_params(np.ones(2))
    with pytest.raises(TypeError, match="params"):
        env.objective(good_c, "theta")


def test_registrations_are_complete_and_json_serialisable():
    ids = [entry["id"] for entry in REGISTRATIONS]
    assert ids == [f"creps_gym/{spec.name}-v0" for spec in SPECS]
    for entry in REGISTRATIONS:
        assert json.loads(json.dumps(entry["kwargs"])) == {"dim": 15, "context_dim": 1, "instance": 0}
        assert "max_episode_steps" not in entry
        spec = gym.spec(entry["id"])
        assert spec.vector_entry_point == entry["vector_entry_point"]
        assert spec.max_episode_steps is None
    env = gym.make("creps_gym/Rastrigin-v0")
    assert env.unwrapped.param_dim == 15 and env.unwrapped.context_dim == 1


@pytest.mark.parametrize("env_class", [cls for cls, _ in ENV_CLASSES], ids=CLASS_IDS)
def test_manual_has_gymnasium_sections_in_order(env_class):
    doc = env_class.__doc__
    sections = ["Description", "Context Space", "Parameter Space", "Return", "Episode End", "Arguments"]
    positions = [doc.index(f"## {name}") for name in [*sections, "Version History"]]
    assert positions == sorted(positions)
    assert env_class.function.formula in doc  # verbatim, in its own indented block
    assert env_class.function.reference in " ".join(doc.split())
    assert f'"creps_gym/{env_class.function.name}-v0"' in doc
    assert ("1e-5" in doc) == env_class.function.bounded and ("-1e4" in doc) != env_class.function.bounded


def test_evaluate_policy_is_the_mean_regret_of_the_mean_policy():
    env = gym.make("creps_gym/ShiftedSphere-v0", dim=4, context_dim=2)
    contexts = test_contexts(env, 64, seed=9)
    np.testing.assert_array_equal(contexts, test_contexts(env, 64, seed=9))
    assert not np.array_equal(contexts, test_contexts(env, 64, seed=10))
    model = env.unwrapped
    exact = evaluate_policy(env, model.optimal_params, contexts)
    assert (exact.metric, exact.value, exact.mean_regret) == ("regret", 0.0, 0.0)
    constant = evaluate_policy(env, np.zeros(4), contexts)
    expected = model.regret(contexts, np.zeros((64, 4))).mean()
    assert constant.value == pytest.approx(expected, rel=1e-12) and constant.value > 0
    assert constant.mean_return == pytest.approx(-expected, rel=1e-12)
    with pytest.raises(ValueError, match=r"policy\(contexts\): expected shape \(64, 4\)"):
        evaluate_policy(env, lambda s: np.zeros((64, 3)), contexts)
    with pytest.raises(ValueError, match="context box"):
        evaluate_policy(env, np.zeros(4), contexts + 3.0)
    with pytest.raises(TypeError, match="ContextualEpisodicEnv"):
        evaluate_policy(gym.make("CartPole-v1"), np.zeros(4), contexts)
    vector = gym.make_vec("creps_gym/ShiftedSphere-v0", num_envs=3, dim=4, context_dim=2)
    np.testing.assert_array_equal(evaluate_policy(vector, np.zeros(4), contexts).regrets, constant.regrets)
    plane = evaluate_policy(gym.make("creps_gym/Plane-v0", dim=4, context_dim=2), np.zeros(4), contexts)
    assert plane.metric == "return" and plane.mean_regret is None
    assert plane.value == plane.mean_return


def test_a_num_envs_whose_arrays_cannot_fit_is_refused_naming_it():
    """Before: ``make_vec(id, num_envs=10**12)`` raised a raw MemoryError."""
    with pytest.raises(
        ValueError, match=r"num_envs: expected a size whose arrays fit in memory .* got 1000000000000"
    ):
        gym.make_vec("creps_gym/Sphere-v0", num_envs=10**12)
    assert gym.make_vec("creps_gym/Sphere-v0", num_envs=3, autoreset_mode="Disabled").num_envs == 3


def test_the_return_at_the_optimum_is_plus_zero_as_the_readme_prints_it():
    """Issue 31: the README's env snippet printed ``-0.0`` for the return at the optimum (``-f`` of 0)."""
    env = gym.make("creps_gym/Rosenbrock-v0", dim=10, context_dim=2)
    context, _ = env.reset(seed=0)
    _, reward, _, _, info = env.step(env.unwrapped.optimal_params(context[None])[0])
    assert f"{reward} {info['regret']}" == "0.0 0.0"


def test_context_dim_zero_is_the_non_contextual_function():
    """z = 0: an empty context, one optimum for every episode, a checked env and a native vector env that
    agrees with it; the runner learns it like any other function."""
    from gymnasium.utils.env_checker import check_env

    from creps_gym.runner import run

    env = gym.make("creps_gym/Rosenbrock-v0", dim=4, context_dim=0)
    context, info = env.reset(seed=0)
    assert context.shape == (0,) and env.observation_space.shape == (0,)
    check_env(env.unwrapped)
    context, info = env.reset(seed=0)  # gymnasium 1.1's check_env leaves the episode stepped
    optimum = info["optimal_params"]
    _, _, terminated, _, step_info = env.step(optimum)
    assert terminated and step_info["regret"] == 0.0
    vector = gym.make_vec("creps_gym/Rosenbrock-v0", num_envs=3, dim=4, context_dim=0)
    vector.reset(seed=1)
    params = np.random.default_rng(0).uniform(-1, 1, (3, 4))
    _, returns, _, _, _ = vector.step(params)
    for k in range(3):
        env.reset(seed=k)
        assert env.step(params[k])[1] == returns[k]
    history = run("c-cma-es", "creps_gym/Sphere-v0", 60, None, 0, env_kwargs={"dim": 4, "context_dim": 0})
    assert history.records[-1].eval_regret < 1e-6 < history.records[0].eval_regret
